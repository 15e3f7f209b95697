"""Inside a primitive's solid (local frame): a strict test with a margin, and the depth."""
from __future__ import annotations

import math

from numba import njit

from .jit import JIT
from .kinds import BOX, CAPSULE, CYLINDER, ELLIPSOID, SPHERE


@njit(inline="always", **JIT)
def inside_s(kind, size, x0, x1, x2, tol):
    """(x0, x1, x2) strictly inside the solid by more than tol (m)."""
    r = size[0]
    if kind == SPHERE:
        return math.sqrt(x0 * x0 + x1 * x1 + x2 * x2) < r - tol
    if kind == CAPSULE:
        z = min(max(x2, -size[1]), size[1])
        return math.sqrt(x0 * x0 + x1 * x1 + (x2 - z) ** 2) < r - tol
    if kind == CYLINDER:
        return math.sqrt(x0 * x0 + x1 * x1) < r - tol and abs(x2) < size[1] - tol
    if kind == ELLIPSOID:
        q = math.sqrt((x0 / size[0]) ** 2 + (x1 / size[1]) ** 2 + (x2 / size[2]) ** 2)
        return q < 1.0 - tol / max(size[0], max(size[1], size[2]))
    if kind == BOX:
        return abs(x0) < size[0] - tol and abs(x1) < size[1] - tol and abs(x2) < size[2] - tol
    return x2 < -tol


@njit(**JIT)
def inside_local(kind, size, x, tol):
    return inside_s(kind, size, x[0], x[1], x[2], tol)


@njit(inline="always", **JIT)
def depth_s(kind, size, x0, x1, x2):
    """How far (m) the point lies inside the solid (negative outside; ellipsoids approximately)."""
    r = size[0]
    if kind == SPHERE:
        return r - math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    if kind == CAPSULE:
        z = min(max(x2, -size[1]), size[1])
        return r - math.sqrt(x0 * x0 + x1 * x1 + (x2 - z) ** 2)
    if kind == CYLINDER:
        return min(r - math.sqrt(x0 * x0 + x1 * x1), size[1] - abs(x2))
    if kind == ELLIPSOID:
        q = math.sqrt((x0 / size[0]) ** 2 + (x1 / size[1]) ** 2 + (x2 / size[2]) ** 2)
        return (1.0 - q) * min(size[0], min(size[1], size[2]))
    if kind == BOX:
        return min(size[0] - abs(x0), min(size[1] - abs(x1), size[2] - abs(x2)))
    return -x2
