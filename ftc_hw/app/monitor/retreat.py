"""The retreat's joint path: the touched point moved back along the contact normal, within the joints' limits
and the time limit.

The direction (:func:`retreat_direction`) is the contact normal as it can be told at the onset: where the
arm ran into something (its touched point moving), the reverse of that motion -- the force on it opposes the
motion, the way it came is free of obstacles, and the onset's force estimate, a few newtons against the
compensation's error while the arm moves, is not needed; where the arm was still, the estimated force's
direction (the force the environment applies points into the arm, ``force . normal < 0``: moving the point
with it moves the arm's surface away from what touched it).

Where the point is, the onset can tell only roughly (centimetres, :mod:`.retreat_region`): the path moves
back every point the contact may be at (``region``), not the estimate alone. The joints come from damped
least squares on those points' stacked Jacobians (:mod:`.retreat_fit`), waypoint by waypoint along their
straight lines, each waypoint kept inside the model's joint ranges; the motion is the straight joint-space
line from the start towards the last waypoint (a short path: the points stay within millimetres of their
lines, and no corner between waypoints asks a joint for a step in acceleration), as far along it as the
point that gains least needs (at most ``settings.max_scale`` times the fitted line), timed by one
rest-to-rest trapezoid whose speed and acceleration keep every joint within the scene's ``max_speed`` and
``max_acceleration``. A path that would end after ``settings.time_limit_s`` is cut to the longest that ends
in time (the points then move back less: said by the path, ``time_cut``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ftc_hw.model import ArmModel

from .config import RetreatSettings
from .retreat_fit import (
    along,
    cover_scale,
    joint_line,
    profile_time,
    reach_in,
    region_jacobian,
    rest_to_rest,
    trapezoid,
)
from .retreat_region import Region, frozen_joints


class RetreatError(ValueError):
    """No retreat can be planned: the scene gives no joint limits, or the contact's direction is undefined."""


@dataclass(frozen=True)
class RetreatPath:
    """Joint setpoints ``q`` (k, n, rad) at times ``t`` (k, s from the start, the last at ``duration_s``);
    ``direction`` (3, base); ``moved_m``: how far the model says the estimated point ends up along it from
    where it was touched (or from where it was when the retreat began, if pushed back meanwhile); ``least_m``:
    the same for the point of the region (the estimate and the points the contact may be at) that moves least;
    ``points``: how many points the region held; ``clipped``: a waypoint met a joint range (the points may then
    move less than asked); ``needed_s``: how long the path that moves every point back would take;
    ``time_cut``: it was cut to end within the time limit."""

    t: np.ndarray
    q: np.ndarray
    direction: np.ndarray
    moved_m: float
    duration_s: float
    clipped: bool
    least_m: float = math.nan
    points: int = 1
    needed_s: float = math.nan
    time_cut: bool = False

    def within(self, time_limit_s: float) -> bool:
        return self.duration_s <= time_limit_s + 1e-9


def in_link(model: ArmModel, q: np.ndarray, *, link: str, point: np.ndarray) -> np.ndarray:
    """``point`` (base) at q in ``link``'s frame."""
    b_T_l = model.kinematics(q)[link]
    return b_T_l[:3, :3].T @ (point - b_T_l[:3, 3])


def point_at(model: ArmModel, q0: np.ndarray, q: np.ndarray, *, link: str, point: np.ndarray) -> np.ndarray:
    """Where the point of ``link`` that is at ``point`` (base) at q0 is at q."""
    b_T_l = model.kinematics(q)[link]
    return b_T_l[:3, :3] @ in_link(model, q0, link=link, point=point) + b_T_l[:3, 3]


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
                 period_s: float, q_touch=None, region=None, qd_touch=None) -> RetreatPath:
    """The retreat from a contact at ``point`` (base, m) on ``link`` along ``direction`` (base, normalized
    here; :func:`retreat_direction`), the arm now at ``q0`` (rad), as setpoints every ``period_s``.
    ``q_touch``: the joints when the point was there (the onset's; default q0): every point ends
    ``distance_m`` back from where it was touched (however far the arm went on before the retreat took
    over) and from where it is now. ``region``: the points the contact may be at, the estimate first
    (:meth:`.retreat_region.SurfaceSamples.region`; default: the estimate alone). ``qd_touch`` (n, rad/s):
    where the arm ran into the contact (``direction`` from its motion), its joints' velocity then: the joints
    go straight back along ``-qd_touch`` and every point of the arm retraces its way (free a moment ago),
    wherever the contact is, the estimate wrong or not; each point's motion is judged along its own way back."""
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
    if region is None:
        region = Region.of_point(link, in_link(model, q_touch, link=link, point=point))
    touched = region.at(model, q_touch)
    retrace = qd_touch is not None
    if retrace:  # each point back the way it came
        direction, speed = _ways_back(model, q_touch, np.asarray(qd_touch, dtype=float), region, touched, direction)
    # from where each point was touched, or from where it is now if it was pushed back meanwhile: it ends at
    # least distance_m from both (one that went on deeper before the retreat began comes back further)
    now = region.at(model, q0)
    ahead = along(now - touched, direction)
    need = settings.distance_m + np.maximum(0.0, -ahead)
    # the joints go straight from q0 through the fit's end (a short path: the points stay near their lines,
    # and no corner between waypoints asks a joint for an acceleration step), as far as the least point needs
    if retrace:
        delta, clipped = _reversed_joints(np.asarray(qd_touch, dtype=float), float(speed[0]), need[0]), False
    else:
        delta, clipped = _joint_motion(model, q0, region=region, now=now, need=need, direction=direction,
                                       settings=settings)
    try:
        v, a = rest_to_rest(delta, robot.max_speed, robot.max_acceleration)
    except ValueError:
        raise RetreatError(f"no joint moves the point on {link!r} back (a link fixed to the base, or at a limit)"
                           ) from None
    # retracing goes back over free space: as far as the region needs, within the joints' ranges (and the time
    # limit below); a fitted line only max_scale times its fit (beyond, it may move points into something)
    most = _in_range(model, q0, delta) if retrace else min(settings.max_scale, _in_range(model, q0, delta))
    scale, moved = cover_scale(model, q0, delta, region=region, need=need, direction=direction, most=most)
    needed_s = profile_time(scale, v, a)
    time_cut = needed_s > settings.time_limit_s
    if time_cut:  # at the joints' limits already: only a shorter path ends in time
        scale = reach_in(settings.time_limit_s, v, a)
        moved = along(region.at(model, q0 + scale * delta) - now, direction)
    total = profile_time(scale, v, a)
    t = np.append(np.arange(0.0, total, period_s), total)
    q = q0 + trapezoid(scale, v, a, t)[:, None] * delta
    back = moved - np.maximum(0.0, -ahead)  # from where each was touched, or pushed back to
    return RetreatPath(t, q, direction if direction.ndim == 1 else direction[0], float(back[0]), total, clipped,
                       least_m=float(back.min()), points=len(region),
                       needed_s=needed_s, time_cut=time_cut)


def _ways_back(model: ArmModel, q_touch: np.ndarray, qd: np.ndarray, region: Region, touched: np.ndarray,
               fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each region point's way back (k, 3, unit, base): the reverse of its velocity at the touch (``fallback``
    for a point that was not moving, e.g. on the axis of the only moving joint); and each one's speed (k, m/s)."""
    v = region_jacobian(model, q_touch, region, touched) @ qd
    speed = np.linalg.norm(v, axis=1)
    return np.where(speed[:, None] > 1e-6, -v / np.maximum(speed, 1e-12)[:, None], fallback), speed


def _reversed_joints(qd: np.ndarray, speed: float, need: float) -> np.ndarray:
    """The joints' motion (n, rad) along ``-qd`` that moves the estimate (moving at ``speed`` m/s at the touch)
    ``need`` back along its way to first order (:func:`~.retreat_fit.cover_scale` then finds how far every
    point needs)."""
    norm = float(np.linalg.norm(qd))
    rate = speed / norm  # m per rad along the reversed joints
    if not rate > 1e-9:
        raise RetreatError("the touched point does not move with the joints' motion: no way back to retrace")
    return -qd / norm * (need / rate)


def _joint_motion(model: ArmModel, q0: np.ndarray, *, region: Region, now: np.ndarray, need: np.ndarray,
                  direction: np.ndarray, settings: RetreatSettings) -> tuple[np.ndarray, bool]:
    """The joints' motion (n, rad) fitted to the estimate and the region's extremes; whether a joint range
    clipped the fit. (A second fit with the points the first moved least shortened dxl-arm's path by ~5 %
    for twice the planning time: not done.)"""
    fit = _representatives(now)
    way, clipped = joint_line(model, q0, region=region.take(fit), targets=now[fit] + np.outer(need[fit], direction),
                              along=direction, frozen=frozen_joints(model), damping_m=settings.damping_m,
                              waypoints=settings.waypoints)
    return way[-1] - q0, clipped


def _representatives(points: np.ndarray) -> np.ndarray:
    """The points the joints are fitted to (indices): the estimate (first) and the region's extremes along
    each base axis (a body that translates moves these and all between alike)."""
    ext = [0, *np.argmin(points, axis=0), *np.argmax(points, axis=0)]
    return np.array(sorted(set(int(i) for i in ext)))


def _in_range(model: ArmModel, q0: np.ndarray, delta: np.ndarray) -> float:
    """The largest s with ``q0 + s delta`` inside the model's joint ranges (at least 1: the fit's end is)."""
    lo, hi = model.joint_limits(unlimited=np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(delta > 0, (hi - q0) / delta, np.where(delta < 0, (lo - q0) / delta, np.inf))
    return max(1.0, float(np.min(room)))
