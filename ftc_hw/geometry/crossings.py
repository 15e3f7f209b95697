"""Where a line ``o + s d`` (local frame, d unit, s in metres) enters and leaves a primitive or the
unbounded quadric ``|k * x| = 1``. Roots are taken about the line's closest approach, so their
offset never suffers cancellation. Scalar helpers return tuples: numba keeps them on the stack."""
from __future__ import annotations

import math

from numba import njit

from .jit import JIT
from .kinds import BOX, CAPSULE, CYLINDER, ELLIPSOID, PLANE, SPHERE

# Squared speed across the finite axes below which a line counts as parallel to the infinite ones
# (its crossings would lie beyond ~1e125 semi-axes anyway).
_PARALLEL = 1e-250


@njit(inline="always", **JIT)
def _ball(cz, r, o, d):
    """Crossings of the line with the sphere of radius r at (0, 0, cz): (hit, s_lo, s_hi)."""
    s0 = -(o[0] * d[0] + o[1] * d[1] + (o[2] - cz) * d[2])
    mx = o[0] + s0 * d[0]
    my = o[1] + s0 * d[1]
    mz = o[2] - cz + s0 * d[2]
    m = math.sqrt(mx * mx + my * my + mz * mz)
    disc = (r - m) * (r + m)
    if disc < 0.0:
        if disc < -1e-14 * r * r:
            return False, 0.0, 0.0
        disc = 0.0
    h = math.sqrt(disc)
    return True, s0 - h, s0 + h


@njit(inline="always", **JIT)
def _side(r, o, d):
    """Crossings with the infinite cylinder x^2 + y^2 = r^2 (about the xy closest approach)."""
    a = d[0] * d[0] + d[1] * d[1]
    if a < 1e-300:
        return False, 0.0, 0.0
    s0 = -(o[0] * d[0] + o[1] * d[1]) / a
    mx = o[0] + s0 * d[0]
    my = o[1] + s0 * d[1]
    m = math.sqrt(mx * mx + my * my)
    disc = (r - m) * (r + m)
    if disc < 0.0:
        if disc < -1e-14 * r * r:
            return False, 0.0, 0.0
        disc = 0.0
    h = math.sqrt(disc / a)
    return True, s0 - h, s0 + h


@njit(inline="always", **JIT)
def _unit_ball(o0, o1, o2, d0, d1, d2):
    """Crossings of the line o + s d (d not unit: s keeps the caller's metric) with the unit sphere;
    a miss by less than 1e-14 is a double root."""
    a = d0 * d0 + d1 * d1 + d2 * d2
    s0 = -(o0 * d0 + o1 * d1 + o2 * d2) / a
    m0, m1, m2 = o0 + s0 * d0, o1 + s0 * d1, o2 + s0 * d2
    m = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    disc = (1.0 - m) * (1.0 + m)
    if disc >= -1e-14:
        hh = math.sqrt(max(disc, 0.0) / a)
        return True, s0 - hh, s0 + hh
    return False, 0.0, 0.0


@njit(inline="always", **JIT)
def _rounded(kind, size, o, d):
    """(hit, s_lo, s_hi) for the primitives bounded by spheres and cylinder sides."""
    r = size[0]
    h = size[1]
    lo, hi = math.inf, -math.inf
    if kind == SPHERE:
        ok, a, b = _ball(0.0, r, o, d)
        if ok:
            lo, hi = a, b
        return lo, hi
    ok, a, b = _side(r, o, d)
    if ok:
        for t in (a, b):
            if abs(o[2] + t * d[2]) <= h * (1.0 + 1e-15) + 1e-15:
                lo, hi = min(lo, t), max(hi, t)
    if kind == CAPSULE:
        for sign in (-1.0, 1.0):
            ok, a, b = _ball(sign * h, r, o, d)
            if ok:
                for t in (a, b):
                    if sign * (o[2] + t * d[2]) >= h * (1.0 - 1e-15) - 1e-15:
                        lo, hi = min(lo, t), max(hi, t)
    elif abs(d[2]) > 1e-300:
        for sign in (-1.0, 1.0):
            t = (sign * h - o[2]) / d[2]
            x = o[0] + t * d[0]
            y = o[1] + t * d[1]
            if x * x + y * y <= r * r * (1.0 + 1e-14):
                lo, hi = min(lo, t), max(hi, t)
    return lo, hi


@njit(inline="always", **JIT)
def _box(size, o, d):
    """(hit, s_lo, s_hi) by the slab method; a line lying in a face plane hits."""
    lo, hi = -1e300, 1e300
    for i in range(3):
        if abs(d[i]) < 1e-300:
            if abs(o[i]) > size[i]:
                return False, lo, hi
            continue
        t1 = (-size[i] - o[i]) / d[i]
        t2 = (size[i] - o[i]) / d[i]
        if t1 > t2:
            t1, t2 = t2, t1
        lo = max(lo, t1)
        hi = min(hi, t2)
    if lo > hi + 1e-15 * (abs(lo) + abs(hi)):
        return False, lo, hi
    return True, lo, max(lo, hi)


@njit(**JIT)
def crossings_local(kind, size, o, d, s_out):
    """Entry and exit of the line o + s d (d unit) through a closed primitive: returns the count
    (0, 1 for a plane, 2 otherwise; a tangent line gives a double root) and the s values, sorted."""
    lo, hi = math.inf, -math.inf
    if kind == ELLIPSOID:
        # the unit sphere in coordinates scaled by the semi-axes; s keeps its metric meaning
        ok, a, b = _unit_ball(o[0] / size[0], o[1] / size[1], o[2] / size[2],
                              d[0] / size[0], d[1] / size[1], d[2] / size[2])
        if ok:
            lo, hi = a, b
    elif kind == SPHERE or kind == CAPSULE or kind == CYLINDER:  # noqa: SIM109 (numba)
        lo, hi = _rounded(kind, size, o, d)
    elif kind == BOX:
        ok, lo, hi = _box(size, o, d)
        if not ok:
            return 0
    elif kind == PLANE:
        if abs(d[2]) < 1e-300:
            return 0
        s_out[0] = -o[2] / d[2]
        return 1
    if lo > hi:
        return 0
    s_out[0] = lo
    s_out[1] = hi
    return 2


@njit(**JIT)
def quadric_crossings_local(k, o, d, s_out):
    """Crossings of the line o + s d (d unit) with the quadric ``|k * x| = 1``, k >= 0 the inverse
    semi-axes (0: an infinite axis, so (1/r, 1/r, 0) is an infinite cylinder along z): the count
    (0 or 2; a tangent line gives a double root) and the s values, sorted. A line parallel to every
    infinite axis misses."""
    d0, d1, d2 = k[0] * d[0], k[1] * d[1], k[2] * d[2]
    if d0 * d0 + d1 * d1 + d2 * d2 < _PARALLEL:
        return 0
    ok, lo, hi = _unit_ball(k[0] * o[0], k[1] * o[1], k[2] * o[2], d0, d1, d2)
    if not ok:
        return 0
    s_out[0] = lo
    s_out[1] = hi
    return 2
