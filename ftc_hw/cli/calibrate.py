"""``ftc calibrate``: its ``--sim-payload`` parsed for the bench wizard (:mod:`ftc_hw.app.calibration.calibrate`)."""
from __future__ import annotations

import typer

from ftc_hw.model import Payload


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


def sim_payload_or_exit(text: str | None, sim: bool) -> Payload | None:
    """``--sim-payload``, which needs ``--sim``."""
    payload = parse_sim_payload(text) if text else None
    if payload is not None and not sim:
        raise typer.BadParameter("--sim-payload needs --sim", param_hint="--sim-payload")
    return payload
