"""The retreat's joint path: the touched point moved back along the contact normal, within the joints' limits.

The direction (:func:`retreat_direction`) is the contact normal as it can be told at the onset: where the
arm ran into something (its touched point moving), the reverse of that motion -- the force on it opposes the
motion, the way it came is free of obstacles, and the onset's force estimate, a few newtons against the
compensation's error while the arm moves, is not needed; where the arm was still, the estimated force's
direction (the force the environment applies points into the arm, ``force . normal < 0``: moving the point
with it moves the arm's surface away from what touched it). The joints that move the point along the
straight line to ``distance_m`` in that direction come from damped least squares on the point's positional
Jacobian (``dq = J^T (J J^T + lambda^2 I)^-1 e``, Nakamura & Hanafusa 1986 / Wampler 1986: well behaved near
singularities), waypoint by waypoint, each kept inside the model's joint ranges. The motion is then the
straight joint-space line from the start to the last waypoint (a short path: the point stays within
millimetres of its Cartesian line, and no corner between waypoints asks a joint for a step in acceleration),
timed by one rest-to-rest trapezoid whose speed and acceleration keep every joint within the scene's
``max_speed`` and ``max_acceleration``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ftc_hw.model import ArmModel

from .config import RetreatSettings


class RetreatError(ValueError):
    """No retreat can be planned: the scene gives no joint limits, or the contact's direction is undefined."""


@dataclass(frozen=True)
class RetreatPath:
    """Joint setpoints ``q`` (k, n, rad) at times ``t`` (k, s from the start, the last at ``duration_s``);
    ``direction`` (3, base); ``moved_m``: how far the model says the point ends up along it from where it
    was touched (or from where it was when the retreat began, if pushed back meanwhile);
    ``clipped``: a waypoint met a joint range (the point may then move less than asked)."""

    t: np.ndarray
    q: np.ndarray
    direction: np.ndarray
    moved_m: float
    duration_s: float
    clipped: bool

    def within(self, time_limit_s: float) -> bool:
        return self.duration_s <= time_limit_s + 1e-9


def joint_line(model: ArmModel, q0: np.ndarray, *, link: str, point_link: np.ndarray, target: np.ndarray,
               settings: RetreatSettings) -> tuple[np.ndarray, bool]:
    """Waypoints (k+1, n) from q0 that move the point ``point_link`` (the link's frame) of ``link`` on the
    straight line to ``target`` (base); whether a joint range clipped one."""
    lo, hi = model.joint_limits(unlimited=np.inf)
    start = link_point(model, q0, link, point_link)
    lam2 = settings.damping_m ** 2
    # a coupling (a gripper's fingers) is no part of the arm's motion: the retreat leaves it where it is
    frozen = np.array([j in {c.joint for c in model.scene.robot.couplings} for j in model.scene.robot.joints])
    q, out, clipped = q0.copy(), [q0.copy()], False
    for i in range(1, settings.waypoints + 1):
        goal = start + (target - start) * i / settings.waypoints
        # two Gauss-Newton steps per waypoint (the steps are small, the error carries on), up to ten at the
        # last, until it is within 0.1 mm
        for k in range(2 if i < settings.waypoints else 10):
            p = link_point(model, q, link, point_link)
            if k >= 2 and np.linalg.norm(goal - p) < 1e-4:
                break
            jac = model.jacobian(q, link, p)
            jac[:, frozen] = 0.0
            dq = jac.T @ np.linalg.solve(jac @ jac.T + lam2 * np.eye(3), goal - p)
            q_new = np.clip(q + dq, lo, hi)
            clipped |= bool(np.any(q_new != q + dq))
            q = q_new
        out.append(q.copy())
    return np.array(out), clipped


def link_point(model: ArmModel, q: np.ndarray, link: str, point_link: np.ndarray) -> np.ndarray:
    """``point_link`` (``link``'s frame) in the base frame at q: one body's pose, not every link's."""
    xpos, xquat = model.body_poses(q)
    bid = model.model.body(link).id
    w, x, y, z = xquat[bid]
    rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                    [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                    [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    return rot @ point_link + xpos[bid]


def in_link(model: ArmModel, q: np.ndarray, *, link: str, point: np.ndarray) -> np.ndarray:
    """``point`` (base) at q in ``link``'s frame."""
    b_T_l = model.kinematics(q)[link]
    return b_T_l[:3, :3].T @ (point - b_T_l[:3, 3])


def point_at(model: ArmModel, q0: np.ndarray, q: np.ndarray, *, link: str, point: np.ndarray) -> np.ndarray:
    """Where the point of ``link`` that is at ``point`` (base) at q0 is at q."""
    b_T_l = model.kinematics(q)[link]
    return b_T_l[:3, :3] @ in_link(model, q0, link=link, point=point) + b_T_l[:3, 3]


def trapezoid(length: float, v: float, a: float, t: np.ndarray) -> np.ndarray:
    """Position along a rest-to-rest trapezoidal (or triangular) profile of ``length`` at times ``t``."""
    t_acc = v / a
    if a * t_acc * t_acc >= length:  # never reaches v: a triangle
        t_acc = math.sqrt(length / a)
        v = a * t_acc
    total = 2 * t_acc + (length - a * t_acc * t_acc) / v
    t = np.clip(t, 0.0, total)
    s = np.where(t < t_acc, 0.5 * a * t * t, a * t_acc * t_acc / 2 + v * (t - t_acc))
    dec = total - t
    return np.where(t > total - t_acc, length - 0.5 * a * dec * dec, s)


def profile_time(length: float, v: float, a: float) -> float:
    t_acc = v / a
    if a * t_acc * t_acc >= length:
        return 2 * math.sqrt(length / a)
    return 2 * t_acc + (length - a * t_acc * t_acc) / v


def retreat_direction(model: ArmModel, q, qd, *, link: str, point, force, settings: RetreatSettings
                      ) -> tuple[np.ndarray, str]:
    """Which way the touched point goes back (unit, base) and why: ``"motion"``, the reverse of the point's
    own velocity when the arm was moving faster than ``settings.moving_above_m_s`` at the touch (it ran into
    something: the force on it opposes that motion, and the way it came is free), else ``"force"``, the
    estimated contact force's direction (a still arm pushed by something). ``q``, ``qd``: the joints at the
    touch (rad, rad/s). Raises RetreatError when neither gives a direction."""
    point = np.asarray(point, dtype=float)
    v = model.jacobian(np.asarray(q, dtype=float), link, point) @ np.asarray(qd, dtype=float)
    speed = float(np.linalg.norm(v))
    if math.isfinite(speed) and speed > settings.moving_above_m_s:
        return -v / speed, "motion"
    f = np.asarray(force, dtype=float)
    norm = float(np.linalg.norm(f))
    if not norm > 1e-9 or not np.all(np.isfinite(f)):
        raise RetreatError(f"contact force {f.tolist()} on a still arm: no direction to retreat along")
    return f / norm, "force"


def plan_retreat(model: ArmModel, q0, *, link: str, point, direction, settings: RetreatSettings,
                 period_s: float, q_touch=None) -> RetreatPath:
    """The retreat from a contact at ``point`` (base, m) on ``link`` along ``direction`` (base, normalized
    here; :func:`retreat_direction`), the arm now at ``q0`` (rad), as setpoints every ``period_s``.
    ``q_touch``: the joints when the point was there (the onset's; default q0): the point ends
    ``distance_m`` back from where it was touched (however far the arm went on before the retreat took
    over) and from where it is now."""
    robot = model.scene.robot
    if robot.max_speed is None or robot.max_acceleration is None:
        raise RetreatError(f"scene {model.scene.name!r} gives no [robot] max_speed / max_acceleration")
    d = np.asarray(direction, dtype=float)
    norm = float(np.linalg.norm(d))
    if not norm > 1e-9 or not np.all(np.isfinite(d)):
        raise RetreatError(f"direction {d.tolist()}: none to retreat along")
    direction = d / norm
    q0, point = np.asarray(q0, dtype=float), np.asarray(point, dtype=float)
    q_touch = q0 if q_touch is None else np.asarray(q_touch, dtype=float)
    point_link = in_link(model, q_touch, link=link, point=point)
    # from the point where it was touched, or from where it is now if it was pushed back meanwhile: the arm
    # ends at least distance_m from both (one that went on deeper before the retreat began comes back further)
    ahead = max(0.0, float((point_at(model, q_touch, q0, link=link, point=point) - point) @ direction))
    way, clipped = joint_line(model, q0, link=link, point_link=point_link,
                              target=point + direction * (ahead + settings.distance_m), settings=settings)
    # the joints go straight from q0 to the line's end (a short path: the point stays near its line, and no
    # corner between waypoints asks a joint for an acceleration step), timed by one rest-to-rest trapezoid
    delta = way[-1] - q0
    reach = np.abs(delta)
    moving = reach > 1e-12
    if not moving.any():
        raise RetreatError(f"no joint moves the point on {link!r} back (a link fixed to the base, or at a limit)")
    v = float(np.min(robot.max_speed[moving] / reach[moving]))
    a = float(np.min(robot.max_acceleration[moving] / reach[moving]))
    total = profile_time(1.0, v, a)
    t = np.append(np.arange(0.0, total, period_s), total)
    q = q0 + trapezoid(1.0, v, a, t)[:, None] * delta
    moved = float((point_at(model, q_touch, q[-1], link=link, point=point) - point) @ direction) - ahead
    return RetreatPath(t, q, direction, moved, total, clipped)
