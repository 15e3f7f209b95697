"""``ftc sim``: run a scene's physics world and its device emulators, optionally writing ground truth.

Ctrl-C (SIGINT) or SIGTERM stops it cleanly: the world and its emulators are shut down, one line on
stderr says so, and the exit code is the shell's for the signal (130 for SIGINT, 143 for SIGTERM)."""
from __future__ import annotations

import contextlib
import json
import signal
import sys
from pathlib import Path

import typer

from ftc_hw.scene import SceneError
from ftc_hw.sim_devices.addresses import parse_addresses
from ftc_hw.sim_devices.host import WorldHost, WorldHostError
from ftc_hw.sim_devices.world import SCENARIOS

from .common import scene_or_exit


def list_scenarios() -> None:
    for info in SCENARIOS.values():
        typer.echo(f"{info.name:22s} {info.description}")


def run_sim(scene_name: str, scenario: str, duration: float, seed: int, truth: Path | None,
            realtime: bool, noise: bool, devices: bool = True, addresses: list[str] | None = None,
            reality: str = "ideal", device_overrides: list[str] | None = None, ahead: bool = False) -> None:
    scene = scene_or_exit(scene_name, device_overrides or ())
    if scenario not in SCENARIOS:
        typer.echo(f"error: unknown scenario {scenario!r} (known: {', '.join(SCENARIOS)})", err=True)
        raise typer.Exit(2)
    try:
        options = parse_addresses(addresses or [], scene)
    except ValueError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    # Ctrl-C and SIGTERM stop the run: the world and its emulators are shut down, never orphaned (the
    # world's process ignores the terminal's SIGINT: its host, this process, closes it)
    stopped_by: list[int] = []

    def stop(signum: int, _frame: object) -> None:
        stopped_by.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    try:
        world = WorldHost(scene, scenario, devices=None if devices else [], options=options, duration=duration,
                          seed=seed, noise=noise, realtime=realtime, truth=truth, reality=reality, ahead=ahead)
    except SceneError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    if ahead:
        world.on_progress = lambda done, of: print(f"computing ahead: {done:.1f} of {of:.1f} simulated s",
                                                   file=sys.stderr, flush=True)
    started, ran_s = False, None
    try:
        endpoints = world.start()
        started = True
        # The first stdout line tells clients what to connect to.
        print(json.dumps({"scene": scene.name, "scenario": scenario, "reality": reality, "seed": seed,
                          "devices": list(endpoints.values())}),
              flush=True)
        while not world.wait_done(1.0):
            pass
    except WorldHostError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    except KeyboardInterrupt:
        stopped_by = stopped_by or [signal.SIGINT]
        if started:
            with contextlib.suppress(WorldHostError):
                ran_s = world.scenario_time()
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):  # a second Ctrl-C does not cut the shutdown short
            signal.signal(sig, signal.SIG_IGN)
        world.close()
    if stopped_by:
        ran = f" after {ran_s:.3f} simulated s" if ran_s is not None else ""
        print(f"interrupted ({signal.Signals(stopped_by[0]).name}){ran} of {scene.name}/{scenario}: the world and "
              "its emulators are stopped" + (f", truth so far -> {truth}" if truth and started else ""),
              file=sys.stderr)
        raise typer.Exit(128 + stopped_by[0])
    report = world.result or {}
    if "error" in report:
        print(f"error: {report['error']}", file=sys.stderr)
        raise typer.Exit(1)
    print(f"simulated {report.get('t', 0.0):.3f} s of {scene.name}/{scenario}: {report.get('samples', 0)} sensor "
          f"samples, {report.get('contact', 0)} in contact" + (f", truth -> {truth}" if truth else ""), file=sys.stderr)
