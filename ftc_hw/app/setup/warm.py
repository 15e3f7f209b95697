"""Compile, once, every numba kernel that ``ftc demo`` and ``ftc monitor --sim`` call in any of their
processes (the world's and the monitor's; the emulators call none) into numba's on-disk cache
(``cache=True``). ``scripts/bootstrap.sh`` runs it after installing (``ftc warm``), so a first demo
loads each kernel in milliseconds instead of compiling it for minutes while the world runs in real
time. numba's cache index tells a kernel whose file changed, and
:func:`ftc_hw.geometry.jit.drop_stale_caches` drops those whose engine files changed (it runs when
the kernels' modules are imported, before any is called here), so a second run only loads: seconds.
"""
from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import TextIO

import numpy as np
from numba.core.dispatcher import Dispatcher

from ftc_hw.bus import ClockAligner
from ftc_hw.detection.kernels import mahalanobis2, quad_sum
from ftc_hw.model import ArmModel, Contact
from ftc_hw.pipeline import ContactPipeline, PipelineSettings, pipeline_for
from ftc_hw.scene import Scene, builtin_names, load_scene
from ftc_hw.sim_devices.world import SCENARIOS, World, build_scenario
from ftc_hw.sim_devices.world.scenarios import sample_contacts
from ftc_hw.solver import ContactSolver
from ftc_hw.solver.bound import crlb_point_cov


@dataclass(frozen=True)
class WarmStep:
    what: str  # what it compiles, as the progress line says it
    run: Callable[[Scene], None]  # on one scene


def _world(scene: Scene) -> None:
    """The world process: every scenario's set-up (surface sampling calls the inside test), then a
    world, whose constructor loads its ray kernel."""
    arm = ArmModel(scene)
    setups = [build_scenario(name, scene, arm, seed=0, duration=2.0) for name in SCENARIOS]
    World(scene, setups[-1], seed=0)


def _pipeline(scene: Scene) -> None:
    """The monitor process: a pipeline calls each of its kernels once when it is built; then the
    detector's kernels with the model error the pipeline passes once the arm moves, whose rows are
    a transposed array (Fortran order: another signature, MotionStage._model_error), and the
    solver's tree kinematics, which a contact's track asks for at a q the last solve was not at."""
    pipe = pipeline_for(scene, PipelineSettings().with_level("dynamics"))  # the joint pipeline warms itself
    ClockAligner()  # the monitor's and the readers' clock alignment: its fit's kernels load with the first one
    if not isinstance(pipe, ContactPipeline):
        return
    rows = np.zeros((6, 2)).T
    mahalanobis2(np.zeros(6), pipe.detector.cov, rows)
    quad_sum(rows, pipe.detector.inv)
    pipe.localization.solver.body_poses(np.asarray(scene.robot.home, dtype=float) + 0.01)


def _evaluation(scene: Scene) -> None:
    """The end of a simulated run (``ftc_hw.app.monitor.evaluate``): at a contact on the surface, the
    Cramer-Rao bound and the solver's batch (a base F/T sensor's: the same kernels serve a flange one)."""
    if scene.sensing.ft != "base":
        return
    arm = ArmModel(scene)
    solver = ContactSolver(arm)
    q = np.asarray(scene.robot.home, dtype=float)
    (point, force), = sample_contacts(arm, q, 1, np.random.default_rng(0), 45.0, (20.0, 40.0))
    clean = arm.predicted_wrench(q, level="bias", contacts=[Contact(point.link, point.point, force)])
    e = solver.solve(clean, q)
    crlb_point_cov(solver, e.point, e.normal, e.force)
    solver.solve_batch(np.repeat(clean[None], 2, axis=0), np.repeat(q[None], 2, axis=0))


STEPS = (
    WarmStep("the world's kernels (surface sampling, ray entry)", _world),
    WarmStep("the pipeline's kernels (compensation, detection, localization, tracking)", _pipeline),
    WarmStep("the evaluation's kernels (solver batch, Cramer-Rao bound)", _evaluation),
)


def kernels() -> Iterator[tuple[str, Dispatcher]]:
    """Every compiled kernel (numba dispatcher) of the ftc_hw modules imported so far, by qualified name."""
    for name, module in list(sys.modules.items()):
        if name.startswith("ftc_hw.") and module is not None:
            for attr, obj in list(vars(module).items()):
                if isinstance(obj, Dispatcher) and obj.__module__ == name:
                    yield f"{name}.{attr}", obj


def compiled_count() -> int:
    """Signatures compiled in this process (not found in the on-disk cache) over all kernels."""
    return sum(len(d.stats.cache_misses) for _, d in kernels())


def warm(scenes: Sequence[Scene] | None = None, out: TextIO | None = None) -> dict[str, float]:
    """Run every step on every scene (default: the built-in ones), one progress line per step on
    ``out`` (default stderr); returns each step's seconds."""
    out = out or sys.stderr
    loaded = list(scenes) if scenes else [load_scene(name) for name in builtin_names()]
    times = {}
    for step in STEPS:
        print(f"[warm] {step.what}: {', '.join(s.name for s in loaded)} ...", end="", file=out, flush=True)
        t0, before = time.perf_counter(), compiled_count()
        for scene in loaded:
            step.run(scene)
        times[step.what] = dt = time.perf_counter() - t0
        made = compiled_count() - before
        print(f" {dt:.1f} s, " + (f"{made} compiled" if made else "all from the cache"), file=out, flush=True)
    return times


def missing_signatures(before: dict[str, set], after: dict[str, set]) -> dict[str, set]:
    """Signatures in ``after`` (a :func:`signatures` snapshot) that ``before`` lacks, by kernel."""
    return {k: sigs - before.get(k, set()) for k, sigs in after.items() if sigs - before.get(k, set())}


def signatures() -> dict[str, set]:
    """Each kernel's loaded signatures now, by qualified name."""
    return {name: {str(s) for s in d.signatures} for name, d in kernels()}


__all__ = ["STEPS", "WarmStep", "compiled_count", "kernels", "missing_signatures", "signatures", "warm"]
