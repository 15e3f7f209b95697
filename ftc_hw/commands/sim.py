"""``ftc sim``: run a scene's physics world, optionally writing ground truth."""
from __future__ import annotations

import json
import sys
import time
from contextlib import ExitStack
from pathlib import Path

import typer

from .common import scene_or_exit


def list_scenarios() -> None:
    from sim_devices.world import SCENARIOS

    for info in SCENARIOS.values():
        typer.echo(f"{info.name:22s} {info.description}")


def run_sim(scene_name: str, scenario: str, duration: float, seed: int, truth: Path | None,
            realtime: bool, noise: bool) -> None:
    from sim_devices.world import SCENARIOS, TruthWriter, World, build_scenario

    from ..model import ArmModel

    scene = scene_or_exit(scene_name)
    if scenario not in SCENARIOS:
        typer.echo(f"error: unknown scenario {scenario!r} (known: {', '.join(SCENARIOS)})", err=True)
        raise typer.Exit(2)
    setup = build_scenario(scenario, scene, ArmModel(scene), seed, duration)
    world = World(scene, setup, seed=seed, noise=noise)
    # The first stdout line tells clients what to connect to (the emulators attach here).
    print(json.dumps({"scene": scene.name, "scenario": scenario, "devices": []}), flush=True)
    samples = contacts = 0
    wall0 = time.monotonic()
    with ExitStack() as stack:
        writer = None
        if truth is not None:
            writer = TruthWriter(stack.enter_context(truth.open("w", encoding="utf-8")))
        try:
            for state, _reading in world.run(duration):
                samples += 1
                contacts += bool(state.contacts)
                if writer:
                    writer.write(state)
                if realtime:
                    ahead = state.t - (time.monotonic() - wall0)
                    if ahead > 0:
                        time.sleep(ahead)
        except KeyboardInterrupt:
            print("interrupted", file=sys.stderr)
    print(f"simulated {world.t:.3f} s of {scene.name}/{scenario}: {samples} sensor samples, "
          f"{contacts} in contact" + (f", truth -> {truth}" if truth else ""), file=sys.stderr)
