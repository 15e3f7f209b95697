"""The retreat's joint motion for a set of points of the arm: the joints that move them all along one
direction (damped least squares on their stacked Jacobians), how far along that joint line every point has
gone back its distance (a max-min over the points), and the rest-to-rest trapezoid that times it.

The points may lie on several links (each point's Jacobian from its body's twist). The stacked fit keeps the
estimate on its straight line and asks every other point for its distance along the direction (sideways it
may go): where the arm has the joints for it (ur5e's six) the wrist then translates, every point moves alike
and the estimate's error costs nothing; where it has not (dxl-arm's four), the hand turns, and the max-min
lengthens the path until the point that gains least has its distance. Damped least squares: Nakamura &
Hanafusa 1986 / Wampler 1986 (well behaved near singularities): ``dq = (J^T J / k + lambda^2 I)^-1 J^T e / k``
for k stacked rows' points (the usual ``J^T (J J^T + lambda^2 I)^-1 e`` for one).
"""
from __future__ import annotations

import math

import numpy as np

from ftc_hw.model import ArmModel

from .retreat_region import Region


def stacked_jacobian(model: ArmModel, q: np.ndarray, link: str, points: np.ndarray) -> np.ndarray:
    """The positional Jacobians (k, 3, n) of ``link``'s points at ``points`` (k, 3, base) at q: the body's
    twist at the first, then each point's (a point ``r`` away moves at ``v_0 + w x r``)."""
    j0, (wx, wy, wz) = model.twist_jacobian(q, link, points[0])
    rx, ry, rz = (points - points[0]).T[:, :, None]
    out = np.empty((len(points), 3, len(wx)))
    out[:, 0], out[:, 1], out[:, 2] = wy * rz - wz * ry, wz * rx - wx * rz, wx * ry - wy * rx
    return out + j0


def along(displacement: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Each displacement (k, 3) along ``direction``: one (3,) for all, or each its own (k, 3) -> (k,)."""
    if direction.ndim == 1:
        return displacement @ direction
    return np.einsum("ij,ij->i", displacement, direction)


def region_jacobian(model: ArmModel, q: np.ndarray, region: Region, points: np.ndarray) -> np.ndarray:
    """The positional Jacobians (k, 3, n) of the region's points, at ``points`` (k, 3, base) at q."""
    out = np.empty((len(region), 3, model.n_joints))
    for i, link in enumerate(region.links):
        mine = np.flatnonzero(region.link_of == i)
        if mine.size:
            out[mine] = stacked_jacobian(model, q, link, points[mine])
    return out


def joint_line(model: ArmModel, q0: np.ndarray, *, region: Region, targets: np.ndarray, along: np.ndarray,
               frozen: np.ndarray, damping_m: float, waypoints: int) -> tuple[np.ndarray, bool]:
    """Waypoints (waypoints + 1, n) from q0 that move the first point of ``region`` on its straight line to
    its target (``targets``: k, 3, base), and the others as near their targets as they can along ``along``
    (unit, base: how far sideways they go does not matter), the ``frozen`` joints (bool, n) left alone,
    every waypoint inside the model's joint ranges; whether a range clipped one."""
    lo, hi = model.joint_limits(unlimited=np.inf)
    start = region.at(model, q0)
    k = len(region)
    damp = damping_m ** 2 * np.eye(model.n_joints)
    q, out, clipped = q0.copy(), [q0.copy()], False
    for i in range(1, waypoints + 1):
        goal = start + (targets - start) * i / waypoints
        # two Gauss-Newton steps per waypoint (the steps are small, the error carries on), up to ten at the
        # last, until within 0.1 mm; four for several points (a body that cannot translate stays off by what
        # the max-min then covers)
        for it in range(2 if i < waypoints else 10 if k == 1 else 4):
            p = region.at(model, q)
            err = goal - p
            if it >= 2 and max(np.abs(err[0]).max(), np.abs(err[1:] @ along).max(initial=0.0)) < 1e-4:
                break
            jacs = region_jacobian(model, q, region, p)
            jac = np.vstack([jacs[0], along @ jacs[1:]])  # (3 + k - 1, n): the first's three rows, one per other
            jac[:, frozen] = 0.0
            e = np.concatenate([err[0], err[1:] @ along])
            dq = np.linalg.solve(jac.T @ jac / k + damp, jac.T @ e / k)
            q_new = np.clip(q + dq, lo, hi)
            clipped |= bool(np.any(q_new != q + dq))
            q = q_new
        out.append(q.copy())
    return np.array(out), clipped


COVER_STEPS = 30  # fixed-point steps at most (each one forward kinematics of the region)


def cover_scale(model: ArmModel, q0: np.ndarray, delta: np.ndarray, *, region: Region, need: np.ndarray,
                direction: np.ndarray, most: float) -> tuple[float, np.ndarray]:
    """The least s (at most ``most``) at which every point of ``region`` moves at least its ``need`` (k, m)
    along ``direction`` (3: one for all; k, 3: each point's own) from q0 to ``q0 + s delta``, and each one's
    motion there (k, m). The motions are
    nearly linear in s (a few cm on an arm's links): fixed-point steps until the least-covered point has its
    need (a point on an arc comes back less than linearly: five steps left one 0.8 mm short of 30, dxl-arm)."""
    start = region.at(model, q0)

    def motion(s: float) -> np.ndarray:
        return along(region.at(model, q0 + s * delta) - start, direction)

    s = 1.0
    for _ in range(COVER_STEPS):
        moved = motion(s)
        ratio = float(np.where(moved > 1e-9, need / np.maximum(moved, 1e-9), np.inf).max())
        if ratio <= 1.0 + 1e-6 and s <= most:  # every point covered
            break
        s_next = min(most, s * ratio * (1.0 + 1e-4))  # a hair over: converges from above, not towards
        if s_next == s:  # capped at ``most``
            break
        s = s_next
    return s, motion(s)


def rest_to_rest(delta: np.ndarray, max_speed: np.ndarray, max_acceleration: np.ndarray) -> tuple[float, float]:
    """The speed (1/s) and acceleration (1/s^2) along the joint line ``q0 + s delta`` (in units of s) that
    keep every joint within its limits (the joint nearest its limit sets them). Raises ValueError when no
    joint moves."""
    reach = np.abs(delta)
    moving = reach > 1e-12
    if not moving.any():
        raise ValueError("no joint moves")
    return float(np.min(max_speed[moving] / reach[moving])), float(np.min(max_acceleration[moving] / reach[moving]))


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
    """How long the rest-to-rest profile of ``length`` takes at speed v and acceleration a."""
    t_acc = v / a
    if a * t_acc * t_acc >= length:
        return 2 * math.sqrt(length / a)
    return 2 * t_acc + (length - a * t_acc * t_acc) / v


def reach_in(time_s: float, v: float, a: float) -> float:
    """The longest rest-to-rest profile that takes at most ``time_s`` at speed v and acceleration a."""
    if time_s <= 2 * v / a:  # a triangle: accelerate half the time, brake the other half
        return a * time_s * time_s / 4
    return v * (time_s - v / a)
