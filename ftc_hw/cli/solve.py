"""``ftc solve``: JSON Lines in, one estimate (or error) line out per input line, in order."""
from __future__ import annotations

import json
import math
import sys
from collections.abc import Iterable, Iterator
from typing import IO, Any

import numpy as np

from ftc_hw.compensation import Compensator
from ftc_hw.solver import ContactEstimate, make_solver

from .common import scene_or_exit


class InputError(ValueError):
    pass


def _vector(obj: dict, key: str, n: int, required: bool = True) -> np.ndarray | None:
    if key not in obj:
        if required:
            raise InputError(f"missing {key!r}")
        return None
    v = obj[key]
    if not isinstance(v, list) or len(v) != n:
        raise InputError(f"{key!r} must be a list of {n} numbers")
    for i, x in enumerate(v):
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise InputError(f"{key}[{i}] is not a number: {x!r}")
        if not math.isfinite(x):
            raise InputError(f"{key}[{i}] is {x}: not a finite number")
    return np.array(v, dtype=float)


def _lst(v: np.ndarray) -> list[float]:
    return [float(x) for x in v]


def estimate_record(e: ContactEstimate) -> dict[str, Any]:
    return {
        "contact": e.contact, "link": e.link, "point": _lst(e.point), "force": _lst(e.force),
        "normal": _lst(e.normal), "point_std": _lst(e.point_std), "force_std": _lst(e.force_std),
        "residual": float(e.residual), "chi2": float(e.chi2),
        "conditioning": float(e.conditioning) if math.isfinite(e.conditioning) else None,
        "flags": list(e.flags),
        "candidates": [{"link": c.link, "point": _lst(c.point), "force": _lst(c.force), "score": float(c.score)}
                       for c in e.candidates],
    }


def solve_lines(solver, compensator: Compensator, lines: Iterable[str]) -> Iterator[dict[str, Any]]:
    n_joints = solver.model.n_joints
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            try:
                obj = json.loads(line, parse_constant=lambda c: (_ for _ in ()).throw(InputError(f"{c} is not JSON")))
            except json.JSONDecodeError as exc:
                raise InputError(f"not JSON: {exc.msg} at column {exc.colno}") from None
            if not isinstance(obj, dict):
                raise InputError("expected a JSON object")
            q = _vector(obj, "q", n_joints)
            wrench = _vector(obj, "wrench", 6)
            qd = _vector(obj, "qd", n_joints, required=False)
            qdd = _vector(obj, "qdd", n_joints, required=False)
            tau = _vector(obj, "tau_ext", n_joints, required=False)
            compensated = obj.get("compensated", False)
            if not isinstance(compensated, bool):
                raise InputError("'compensated' must be true or false")
            saturated = bool(np.any(np.abs(wrench) >= solver.scene.sensor.range))
            external = wrench if compensated else compensator.external(wrench, q, qd, qdd)
            yield estimate_record(solver.solve(external, q, tau_ext=tau, saturated=saturated))
        except InputError as exc:
            yield {"error": str(exc), "line": number}


def run_solve(scene_name: str, method: str, input_path: str, output_path: str, bias: str | None) -> None:
    scene = scene_or_exit(scene_name)
    solver = make_solver(scene, method)
    bias_vec = None
    if bias:
        try:
            bias_vec = np.array(json.loads(bias), dtype=float).reshape(6)
        except (ValueError, TypeError) as exc:
            raise SystemExit(f"error: --bias must be a JSON list of 6 numbers ({exc})") from None
    compensator = Compensator(solver.model, bias=bias_vec)
    src: IO[str] = sys.stdin if input_path == "-" else open(input_path, encoding="utf-8")  # noqa: SIM115
    dst: IO[str] = sys.stdout if output_path == "-" else open(output_path, "w", encoding="utf-8")  # noqa: SIM115
    try:
        for record in solve_lines(solver, compensator, src):
            dst.write(json.dumps(record, separators=(",", ":")) + "\n")
            dst.flush()
    finally:
        if src is not sys.stdin:
            src.close()
        if dst is not sys.stdout:
            dst.close()
