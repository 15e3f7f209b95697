"""``ftc devices probe``: arguments to the probe (:mod:`ftc_hw.app.setup.probe`)."""
from __future__ import annotations

from pathlib import Path

import typer

from ftc_hw.app.monitor.view import make_console
from ftc_hw.app.setup.probe import plan_probe, run_probe

from .common import scene_or_exit


def run_probe_command(scene_name: str | None, device_overrides: tuple[str, ...], rig: Path | None, *,
                      ports: list[str], can: list[str], addresses: list[str], bauds: list[int],
                      timeout: float) -> int:
    if (device_overrides or rig) and not scene_name:
        typer.echo("error: --device and --rig change a scene's devices: give --scene too", err=True)
        return 2
    scene = scene_or_exit(scene_name, device_overrides, rig) if scene_name else None
    plan = plan_probe(scene, ports=ports, can=can, addresses=addresses, bauds=bauds)
    return run_probe(plan, timeout, make_console())
