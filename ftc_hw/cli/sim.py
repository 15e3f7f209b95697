"""``ftc sim``: run a scene's physics world and its device emulators, optionally writing ground truth."""
from __future__ import annotations

import json
import signal
import sys
from contextlib import ExitStack
from pathlib import Path

import typer

from ftc_hw.cli.common import scene_or_exit


def list_scenarios() -> None:
    from ftc_hw.sim_devices.world import SCENARIOS

    for info in SCENARIOS.values():
        typer.echo(f"{info.name:22s} {info.description}")


def run_sim(scene_name: str, scenario: str, duration: float, seed: int, truth: Path | None,
            realtime: bool, noise: bool, devices: bool = True) -> None:
    from ftc_hw.sim_devices.runner import EmulatorStartError, SimRunner
    from ftc_hw.sim_devices.world import SCENARIOS, TruthWriter

    scene = scene_or_exit(scene_name)
    if scenario not in SCENARIOS:
        typer.echo(f"error: unknown scenario {scenario!r} (known: {', '.join(SCENARIOS)})", err=True)
        raise typer.Exit(2)
    # SIGTERM stops like Ctrl-C: the emulators are shut down, never orphaned
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt()))
    runner = SimRunner(scene, scenario, duration=duration, seed=seed, noise=noise, devices=devices)
    try:
        endpoints = runner.start()
    except EmulatorStartError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    # The first stdout line tells clients what to connect to.
    print(json.dumps({"scene": scene.name, "scenario": scenario, "devices": endpoints}), flush=True)
    counts = {"samples": 0, "contact": 0}
    try:
        with ExitStack() as stack:
            writer = TruthWriter(stack.enter_context(truth.open("w", encoding="utf-8"))) if truth else None

            def on_sample(state) -> None:
                counts["samples"] += 1
                counts["contact"] += bool(state.contacts)
                if writer:
                    writer.write(state)

            runner.run(realtime=realtime, on_sample=on_sample)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
    finally:
        runner.stop()
    print(f"simulated {runner.world.t:.3f} s of {scene.name}/{scenario}: {counts['samples']} sensor samples, "
          f"{counts['contact']} in contact" + (f", truth -> {truth}" if truth else ""), file=sys.stderr)
