"""The point of the quadric ``|k * x| = 1`` (an ellipsoid; k >= 0 the inverse semi-axes, 0 for an
infinite axis) nearest to a point, local frame, by Eberly's robust bisection.

The nearest point is ``x_i = y_i / f_i`` with ``f_i = 1 + lam k_i^2`` and the Lagrange multiplier
lam the root of ``F = sum (k_i y_i / f_i)^2 - 1`` (decreasing in lam), taken in the first octant
(|y|) and signed back. The bisection is geometric, on ``w = 1 + lam kmax^2``: ``f_i = (1 - rho_i)
+ w rho_i`` with ``rho_i = (k_i / kmax)^2`` is a sum of non-negative terms, so every f_i keeps full
relative precision; ``w`` lies in ``[kmax |y_top|, 1]`` inside, ``[1, 1 + kmax^2 lam_hi]`` outside.
Inside, with y = 0 on every largest-k axis, the nearest point may lie off-axis (closed form).
"""
from __future__ import annotations

import math

from numba import njit

from .jit import JIT

_BISECT_ITERS = 66  # relative width of the bracket -> eps over 2^-1075 .. 2^180
_TINY = 1e-100  # points this close to the centre (in semi-axes) move out radially to it


@njit(inline="always", **JIT)
def _bracket(k, ay, kmax, outside):
    """The bisection's bracket of w, and |y| on the largest-k axes (the largest of them)."""
    ytop = 0.0
    for i in range(3):
        if k[i] == kmax:
            ytop = max(ytop, ay[i])
    if not outside:
        return max(kmax * ytop, 5e-324), 1.0, ytop  # F(kmax |y_top|) >= 0: its top term alone is 1
    yy = ay[0] * ay[0] + ay[1] * ay[1] + ay[2] * ay[2]
    q = 0.0
    for i in range(3):
        if k[i] > 0.0:
            q += (ay[i] / k[i]) ** 2
    lam_hi = min(yy / 4.0, math.sqrt(q))
    return 1.0, max(1.0 + kmax * kmax * lam_hi, 1.0), ytop


@njit(inline="always", **JIT)
def _root_w(ky, rho, omr, lo, hi):
    for _ in range(_BISECT_ITERS):
        mid = math.sqrt(lo) * math.sqrt(hi)
        q0, q1, q2 = ky[0] / (omr[0] + mid * rho[0]), ky[1] / (omr[1] + mid * rho[1]), ky[2] / (omr[2] + mid * rho[2])
        if q0 * q0 + q1 * q1 + q2 * q2 - 1.0 > 0.0:
            lo = mid
        else:
            hi = mid
    return math.sqrt(lo) * math.sqrt(hi)


@njit(inline="always", **JIT)
def _off_axis(k, ay, ky, omr, kmax, x):
    """Inside on the mid-plane(s) of the largest k: the off-axis nearest point when there is one
    (fills x, returns True), else False (the bisection's root is right)."""
    g = 0.0
    first = -1
    for i in range(3):
        if k[i] == kmax:
            if first < 0 or ay[i] > ay[first]:
                first = i
        else:
            g += (ky[i] / omr[i]) ** 2
    g -= 1.0
    if g > 0.0:
        return False
    for i in range(3):
        if k[i] != kmax:
            x[i] = ay[i] / omr[i]
        else:
            x[i] = math.sqrt(max(-g, 0.0)) / kmax if i == first else 0.0
    return True


@njit(**JIT)
def quadric_closest_local(k, y, x):
    """Fills x with the point of ``|k * x| = 1`` nearest to y; returns the signed distance (m,
    negative inside)."""
    kmax = max(k[0], max(k[1], k[2]))
    m = max(abs(y[0]), max(abs(y[1]), abs(y[2]))) * kmax
    sc = _TINY / m if 0.0 < m < _TINY else 1.0
    ay = (abs(y[0]) * sc, abs(y[1]) * sc, abs(y[2]) * sc)
    rho = ((k[0] / kmax) ** 2, (k[1] / kmax) ** 2, (k[2] / kmax) ** 2)
    # 1 - rho without cancellation
    omr = ((kmax - k[0]) * (kmax + k[0]) / kmax**2, (kmax - k[1]) * (kmax + k[1]) / kmax**2,
           (kmax - k[2]) * (kmax + k[2]) / kmax**2)
    ky = (k[0] * ay[0], k[1] * ay[1], k[2] * ay[2])
    kyn = math.sqrt(ky[0] * ky[0] + ky[1] * ky[1] + ky[2] * ky[2])
    g = (kyn - 1.0) * (kyn + 1.0)
    if not (g > 0.0 or g < 0.0):  # on the surface (or NaN)
        for i in range(3):
            x[i] = y[i]
        return 0.0
    lo, hi, ytop = _bracket(k, ay, kmax, g > 0.0)
    w = _root_w(ky, rho, omr, lo, max(hi, lo))
    special = g < 0.0 and kmax * ytop <= _TINY and _off_axis(k, ay, ky, omr, kmax, x)
    d2 = 0.0
    for i in range(3):
        if special:
            diff = ay[i] - x[i]
        else:
            f = omr[i] + w * rho[i]
            x[i] = ay[i] / f
            diff = ay[i] * ((w - 1.0) * rho[i]) / f
        d2 += diff * diff
        if y[i] < 0.0:
            x[i] = -x[i]
    return math.sqrt(d2) if g > 0.0 else -math.sqrt(d2)
