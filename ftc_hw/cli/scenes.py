"""``ftc scenes``."""
from __future__ import annotations

import typer

from ftc_hw.scene import builtin_names, load_scene


def list_scenes() -> None:
    for name in builtin_names():
        s = load_scene(name)
        kinds = ", ".join(f"{d.kind}/{d.transport}" for d in s.devices) or "no devices"
        typer.echo(f"{name:10s} {s.n_joints} joints, sensor {s.sensor.rate_hz:g} Hz ({s.sensor.reports}), "
                   f"compensation {s.compensation}, devices: {kinds} - {s.description}")
