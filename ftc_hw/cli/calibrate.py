"""``ftc calibrate``: arguments to the bench wizard (:mod:`ftc_hw.app.calibration.calibrate`)."""
from __future__ import annotations

from pathlib import Path

import typer

from ftc_hw.app.calibration.calibrate import run_calibrate
from ftc_hw.model import Payload

from .common import scene_or_exit


def parse_sim_payload(text: str) -> Payload:
    """``mass=KG,com=X,Y,Z`` (m, flange frame)."""
    try:
        head, _, com = text.partition(",com=")
        key, _, mass = head.partition("=")
        if key.strip() != "mass" or not com:
            raise ValueError
        c = [float(x) for x in com.split(",")]
        if len(c) != 3:
            raise ValueError
        return Payload(float(mass), (c[0], c[1], c[2]))
    except ValueError as exc:
        raise typer.BadParameter(f"expected mass=KG,com=X,Y,Z (a positive mass, 3 numbers in m), got {text!r}"
                                 + (f": {exc}" if str(exc) else ""), param_hint="--sim-payload") from None


def run_calibrate_command(scene_name: str, device_overrides: tuple[str, ...] = (), rig: Path | None = None, *,
                          sim: bool, sim_payload: str | None, **options) -> int:
    scene = scene_or_exit(scene_name, device_overrides, rig)
    payload = parse_sim_payload(sim_payload) if sim_payload else None
    if payload is not None and not sim:
        raise typer.BadParameter("--sim-payload needs --sim", param_hint="--sim-payload")
    return run_calibrate(scene, sim=sim, sim_payload=payload, **options)
