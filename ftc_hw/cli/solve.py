"""``ftc solve``: JSON Lines in, one estimate (or error) line out per input line, blank ones included,
in order. Every output line is standard JSON (no NaN or Infinity): a wrench beyond the sensor's range
or a joint angle outside its joint's range is an error line, and an estimate holding a non-finite
number goes out as no contact with ``null`` there and the ``non_finite`` flag.

A scene sensed through its joints (no base F/T sensor in its sensing) takes the external joint torques
instead of a wrench: ``{"q": [...], "tau_ext": [...], "tau_ext_std": [...]}`` (N m, the torque the contact
exerts about each joint, ``J_c^T p``; its 1 sigma per joint, default 0.1 N m), and, where the scene uses
a flange sensor, ``"wrench"``: the contact's wrench on the arm at that sensor (compensated, its frame)."""
from __future__ import annotations

import json
import math
import sys
from collections.abc import Iterable, Iterator
from typing import IO, Any

import numpy as np

from ftc_hw.compensation import Compensator
from ftc_hw.model import ArmModel
from ftc_hw.solver import ContactEstimate, JointContactSolver, make_solver

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


# a joint without limits in the model still turns only so far: beyond this many radians a reading is
# not an angle (a wrapped encoder or a unit slip)
UNLIMITED_JOINT_RAD = 8 * math.pi
# a reading this far past the model's limits is not the arm's (calibration offsets stay below it)
LIMIT_SLACK_RAD = 0.05


def _lst(v: np.ndarray) -> list[float]:
    return [float(x) for x in v]


def _check_range(wrench: np.ndarray, sensor_range: np.ndarray) -> None:
    names = ("fx", "fy", "fz", "tx", "ty", "tz")
    over = np.flatnonzero(np.abs(wrench) > sensor_range)
    if over.size:
        i = int(over[0])
        unit = "N" if i < 3 else "N m"
        raise InputError(f"wrench {names[i]} = {wrench[i]:g} {unit} is beyond the sensor's range "
                         f"(+-{sensor_range[i]:g} {unit}): not a reading of this sensor")


def joint_bounds(model) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's accepted angles: the model's limits widened by LIMIT_SLACK_RAD; +-UNLIMITED_JOINT_RAD
    for a joint the model leaves unlimited."""
    lo, hi = model.joint_limits(unlimited=UNLIMITED_JOINT_RAD)
    return lo - LIMIT_SLACK_RAD, hi + LIMIT_SLACK_RAD


def _check_q(q: np.ndarray, bounds: tuple[np.ndarray, np.ndarray]) -> None:
    lo, hi = bounds
    out = np.flatnonzero((q < lo) | (q > hi))
    if out.size:
        i = int(out[0])
        raise InputError(f"q[{i}] = {q[i]:g} rad is outside joint {i}'s range [{lo[i]:g}, {hi[i]:g}] rad")


def estimate_record(e: ContactEstimate) -> dict[str, Any]:
    """The estimate as standard JSON: a non-finite number becomes null, and an estimate holding one
    is no contact, flagged ``non_finite``."""
    record, replaced = _finite(_record(e))
    if replaced:
        record["contact"] = False
        record["flags"] = [*record["flags"], "non_finite"]
    return record


def _finite(obj: Any) -> tuple[Any, bool]:
    if isinstance(obj, float):
        return (obj, False) if math.isfinite(obj) else (None, True)
    if isinstance(obj, dict):
        pairs = {k: _finite(v) for k, v in obj.items()}
        return {k: v for k, (v, _) in pairs.items()}, any(r for _, r in pairs.values())
    if isinstance(obj, list):
        items = [_finite(v) for v in obj]
        return [v for v, _ in items], any(r for _, r in items)
    return obj, False


def _record(e: ContactEstimate) -> dict[str, Any]:
    return {
        "contact": e.contact, "link": e.link, "point": _lst(e.point), "force": _lst(e.force),
        "normal": _lst(e.normal), "point_std": _lst(e.point_std), "force_std": _lst(e.force_std),
        "residual": float(e.residual), "chi2": float(e.chi2),
        "conditioning": float(e.conditioning),
        "flags": list(e.flags),
        "candidates": [{"link": c.link, "point": _lst(c.point), "force": _lst(c.force), "score": float(c.score)}
                       for c in e.candidates],
    }


def solve_lines(solver, compensator: Compensator, lines: Iterable[str]) -> Iterator[dict[str, Any]]:
    n_joints = solver.model.n_joints
    bounds = joint_bounds(solver.model)
    sensor_range = np.asarray(solver.scene.sensor.range, dtype=float)
    for number, line in enumerate(lines, start=1):
        try:
            obj = _object(line)
            q = _vector(obj, "q", n_joints)
            wrench = _vector(obj, "wrench", 6)
            qd = _vector(obj, "qd", n_joints, required=False)
            qdd = _vector(obj, "qdd", n_joints, required=False)
            tau = _vector(obj, "tau_ext", n_joints, required=False)
            compensated = obj.get("compensated", False)
            if not isinstance(compensated, bool):
                raise InputError("'compensated' must be true or false")
            _check_q(q, bounds)
            if not compensated:
                _check_range(wrench, sensor_range)
            saturated = bool(np.any(np.abs(wrench) >= solver.scene.sensor.range))
            with np.errstate(over="ignore", invalid="ignore"):  # a non-finite result is flagged instead
                external = wrench if compensated else compensator.external(wrench, q, qd, qdd)
                record = estimate_record(solver.solve(external, q, tau_ext=tau, saturated=saturated))
            yield record
        except InputError as exc:
            yield {"error": str(exc), "line": number}


TAU_EXT_STD = 0.1  # N m: the external joint torques' 1 sigma where a line gives none


def solve_joint_lines(solver: JointContactSolver, lines: Iterable[str], *,
                      flange: bool) -> Iterator[dict[str, Any]]:
    """As :func:`solve_lines`, from the external joint torques (and a flange sensor's wrench)."""
    n_joints = solver.model.n_joints
    bounds = joint_bounds(solver.model)
    for number, line in enumerate(lines, start=1):
        try:
            obj = _object(line)
            q = _vector(obj, "q", n_joints)
            tau = _vector(obj, "tau_ext", n_joints)
            std = _vector(obj, "tau_ext_std", n_joints, required=False)
            std = np.full(n_joints, TAU_EXT_STD) if std is None else std
            if np.any(std <= 0):
                raise InputError("'tau_ext_std' must be > 0")
            wrench = _vector(obj, "wrench", 6, required=False) if flange else None
            _check_q(q, bounds)
            wrench_cov = None if wrench is None else solver.model.scene.sensor.noise_cov
            with np.errstate(over="ignore", invalid="ignore"):
                yield estimate_record(solver.solve(tau, np.diag(std**2), q, wrench=wrench, wrench_cov=wrench_cov))
        except InputError as exc:
            yield {"error": str(exc), "line": number}


def _object(line: str) -> dict:
    if not line.strip():
        raise InputError("blank line")
    try:
        obj = json.loads(line, parse_constant=lambda c: (_ for _ in ()).throw(InputError(f"{c} is not JSON")))
    except json.JSONDecodeError as exc:
        raise InputError(f"not JSON: {exc.msg} at column {exc.colno}") from None
    if not isinstance(obj, dict):
        raise InputError("expected a JSON object")
    return obj


def run_solve(scene_name: str, method: str, input_path: str, output_path: str, bias: str | None,
              sensing: str | None = None) -> None:
    scene = scene_or_exit(scene_name, sensing=sensing)
    if scene.sensing.ft != "base":
        if method != "ours" or bias:
            raise SystemExit(f"error: scene {scene.name!r} is sensed through its joints ({scene.sensing.label()}): "
                             "--method leng2016 and --bias are for a base F/T sensor's wrench")
        solver = JointContactSolver(ArmModel(scene))
        _write(input_path, output_path,
               lambda lines: solve_joint_lines(solver, lines, flange=scene.sensing.ft == "flange"))
        return
    solver = make_solver(scene, method)
    bias_vec = None
    if bias:
        try:
            bias_vec = np.array(json.loads(bias), dtype=float).reshape(6)
        except (ValueError, TypeError) as exc:
            raise SystemExit(f"error: --bias must be a JSON list of 6 numbers ({exc})") from None
    compensator = Compensator(solver.model, bias=bias_vec)
    _write(input_path, output_path, lambda lines: solve_lines(solver, compensator, lines))


def _write(input_path: str, output_path: str, solve) -> None:
    """``solve(lines)``'s records, one JSON line each, from the input to the output (``-``: stdin, stdout)."""
    src: IO[str] = sys.stdin if input_path == "-" else _open(input_path, "r", "input")
    try:
        dst: IO[str] = sys.stdout if output_path == "-" else _open(output_path, "w", "output")
        try:
            for record in solve(_lines(src, input_path)):
                dst.write(json.dumps(record, separators=(",", ":"), allow_nan=False) + "\n")
                dst.flush()
        finally:
            if dst is not sys.stdout:
                dst.close()
    finally:
        if src is not sys.stdin:
            src.close()


def _open(path: str, mode: str, what: str) -> IO[str]:
    try:
        return open(path, mode, encoding="utf-8")  # noqa: SIM115
    except OSError as exc:
        raise SystemExit(f"error: cannot open {what} file {path!r}: {exc.strerror}") from None


def _lines(src: IO[str], path: str) -> Iterator[str]:
    try:
        yield from src
    except (OSError, UnicodeDecodeError) as exc:
        raise SystemExit(f"error: cannot read input {path!r}: {exc}") from None
