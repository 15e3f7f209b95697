"""``ftc serve`` and ``ftc record --remote``: arguments to :mod:`ftc_hw.app.serving.serve` and
:mod:`ftc_hw.app.serving.remote_record`."""
from __future__ import annotations

from pathlib import Path

import typer

from ftc_hw.app.serving.serve import DEFAULT_LISTEN, ServeConfig, ServeError, run_serve
from ftc_hw.bus.remote import RemoteError


def run_serve_command(scene: str, devices: tuple[str, ...], rig: Path | None, listen: tuple[str, ...],
                      name: str | None, sim: bool, scenario: str, seed: int, reality: str, hold: float,
                      duration: float | None, zenoh_config: Path | None = None) -> int:
    names = tuple(d for d in devices if "=" not in d)  # a device to serve; NAME.KEY=VALUE: an override
    overrides = tuple(d for d in devices if "=" in d)
    cfg = ServeConfig(scene, devices=names, rig=name, listen=listen or (DEFAULT_LISTEN,), device_overrides=overrides,
                      rig_file=rig, sim=sim, scenario=scenario, seed=seed, reality=reality, hold_s=hold,
                      duration=duration, zenoh_config=zenoh_config)
    try:
        return run_serve(cfg, say=lambda line: typer.echo(line))
    except (ServeError, RemoteError) as exc:
        typer.echo(f"error: {exc}", err=True)
        return 1


def run_record_command(remote: str, name: str, out: Path, duration: float | None, zenoh_config: Path | None) -> int:
    from ftc_hw.app.serving.remote_record import record_remote  # lazy: only this command records

    try:
        result = record_remote(remote, name, out, duration, zenoh_config, say=lambda line: typer.echo(line))
    except (RemoteError, OSError) as exc:
        typer.echo(f"error: {exc}", err=True)
        return 1
    return 0 if not result.drops and not any(result.seq_missing.values()) else 3
