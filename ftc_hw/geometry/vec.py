"""Small 3-vector helpers of the compiled engine (no allocation; frame-free)."""
from __future__ import annotations

import math

from numba import njit

from .jit import JIT


@njit(inline="always", **JIT)
def cross3(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(inline="always", **JIT)
def dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(inline="always", **JIT)
def tangent_basis(n, t1, t2):
    """Orthonormal t1, t2 with t1 x t2 = n (n unit)."""
    ax, ay, az = abs(n[0]), abs(n[1]), abs(n[2])
    if ax <= ay and ax <= az:
        e0, e1, e2 = 1.0, 0.0, 0.0
    elif ay <= az:
        e0, e1, e2 = 0.0, 1.0, 0.0
    else:
        e0, e1, e2 = 0.0, 0.0, 1.0
    t1[0] = n[1] * e2 - n[2] * e1
    t1[1] = n[2] * e0 - n[0] * e2
    t1[2] = n[0] * e1 - n[1] * e0
    k = 1.0 / math.sqrt(dot3(t1, t1))
    t1[0] *= k
    t1[1] *= k
    t1[2] *= k
    t2[0] = n[1] * t1[2] - n[2] * t1[1]
    t2[1] = n[2] * t1[0] - n[0] * t1[2]
    t2[2] = n[0] * t1[1] - n[1] * t1[0]


@njit(inline="always", **JIT)
def line_dist2(x, r0, u):
    """Squared distance of x from the line r0 + s u (u unit)."""
    d0, d1, d2 = x[0] - r0[0], x[1] - r0[1], x[2] - r0[2]
    along = d0 * u[0] + d1 * u[1] + d2 * u[2]
    return d0 * d0 + d1 * d1 + d2 * d2 - along * along
