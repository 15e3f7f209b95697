"""``ftc scenes``."""
from __future__ import annotations

import typer

from ftc_hw.app.setup.vendor_meshes import VendorFetchError, fetch_vendor_shell
from ftc_hw.scene import builtin_names, load_scene, variant_names
from ftc_hw.scene.vendor import shell_fetched, shell_model


def list_scenes() -> None:
    for name in builtin_names() + variant_names():
        s = load_scene(name)
        kinds = ", ".join(f"{d.kind}/{d.transport}" for d in s.devices) or "no devices"
        ft = f", F/T {s.sensor.rate_hz:g} Hz at the {s.sensor.mount} ({s.sensor.reports})" if s.sensor else ""
        typer.echo(f"{name:10s} {s.n_joints} joints, sensing {s.sensing.label()}{ft}, "
                   f"compensation {s.compensation}, devices: {kinds} - {s.description}")
        shell = s.robot.vendor_shell
        if shell is not None:
            where = shell_model(shell).parent if shell_fetched(shell) else "not fetched: ftc scenes --fetch-meshes"
            typer.echo(f"{'':10s} vendor shell {shell} ({where})")


def fetch_all_meshes() -> None:
    names = sorted({s.robot.vendor_shell for s in map(load_scene, builtin_names()) if s.robot.vendor_shell})
    for name in names:
        try:
            fetch_vendor_shell(name, log=typer.echo)
        except VendorFetchError as exc:
            typer.echo(f"error: {exc}", err=True)
            raise typer.Exit(1) from exc
