"""``ftc warm`` (run by scripts/bootstrap.sh) holds every kernel the demo path calls: in a fresh
process the warm step loads everything from numba's cache (compiles nothing: every kernel it warms
is cacheable), and the demo's path in miniature (the world through the sweep's first collision, the
monitor's pipeline with its tare, the evaluation against the truth) then needs no kernel, nor any
signature of one, that the warm step did not load."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ftc_hw.app.monitor.evaluate import crlb_of_truth, evaluate, solver_rms_of_truth
from ftc_hw.bus import Bus
from ftc_hw.model import ArmModel
from ftc_hw.monitor import LiveMonitor, PipelineInput
from ftc_hw.pipeline import PipelineSettings
from ftc_hw.record.events import event_record
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world import World, build_scenario, truth_record

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

ROOT = Path(__file__).resolve().parents[2]
PROBE = """
import json
from ftc_hw.app.setup import warm as W
from ftc_hw.scene import load_scene
from tests.app.test_warm import demo_path
W.warm([load_scene('ur5e')])
compiled, loaded = W.compiled_count(), W.signatures()
events = demo_path()
late = W.missing_signatures(loaded, W.signatures())
print(json.dumps({"compiled": compiled, "events": events, "late": {k: sorted(v) for k, v in late.items()}}))
"""


def demo_path(scene_name: str = "ur5e", scenario: str = "sweep-with-collision", seconds: float = 2.0) -> int:
    """What ``ftc demo``'s processes compute, in one process and faster than real time: the world
    poked once, each sample through the live monitor's pipeline (tare first), then the evaluation.
    Returns the number of contact events."""
    scene = load_scene(scene_name)
    world = World(scene, build_scenario(scenario, scene, ArmModel(scene), seed=1, duration=seconds), seed=1)
    monitor = LiveMonitor(Bus(), scene, settings=PipelineSettings().with_level("dynamics"))
    events, truth = [], []
    for seq, (state, reading) in enumerate(world.run(seconds)):
        t_ns = int(round(state.t * 1e9))
        inp = PipelineInput(t_ns, t_ns, seq, "ft", reading.wrench, state.q, state.qd, world.read_current(state),
                            bool(np.any(reading.saturated)), tare=not monitor.tared)
        frame = monitor.consume(inp)
        if frame is not None:
            events += [event_record(e) for e in frame.result.events]
        truth.append({**truth_record(state), "t_host_ns": t_ns})
    evaluate(events, truth, 1.0 / scene.sensor.rate_hz, crlb=crlb_of_truth(scene),
             solver_rms=solver_rms_of_truth(scene))
    return len(events)


def _probe() -> dict:
    probe = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=900, cwd=ROOT)
    assert probe.returncode == 0, probe.stderr
    return {**json.loads(probe.stdout.strip().splitlines()[-1]), "stderr": probe.stderr}


def test_after_the_warm_step_the_demo_path_compiles_and_loads_nothing_more():
    out = _probe()
    if out["compiled"]:  # the cache was stale (a kernel's source changed since the last warm-up): now it is not
        out = _probe()
    assert out["compiled"] == 0, f"the warm step's kernels are not all in numba's cache: {out['stderr']}"
    assert out["events"] > 0, "the collision made no contact event: the path did not run the solver"
    assert out["late"] == {}, f"kernels the demo path loads that the warm step does not: {out['late']}"
