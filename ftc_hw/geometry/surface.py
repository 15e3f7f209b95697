"""Points of a primitive's surface (local frame): the outward normal at a surface point, and a
surface point near any point (the closest one except for ellipsoids: see quadric.py for those)."""
from __future__ import annotations

import math

from numba import njit

from .jit import JIT
from .kinds import BOX, CAPSULE, CYLINDER, ELLIPSOID, SPHERE


@njit(inline="always", **JIT)
def normal_local(kind, size, x0, x1, x2):
    """Outward unit normal at the surface point (x0, x1, x2) of a primitive (local frame)."""
    r = size[0]
    if kind == SPHERE:
        n0, n1, n2 = x0, x1, x2
    elif kind == CAPSULE:
        z = min(max(x2, -size[1]), size[1])
        n0, n1, n2 = x0, x1, x2 - z
    elif kind == CYLINDER:
        rho = math.sqrt(x0 * x0 + x1 * x1)
        # the nearest face decides: the side when |rho - r| < | |z| - h |
        if abs(rho - r) <= abs(abs(x2) - size[1]) and rho > 0.0:
            n0, n1, n2 = x0, x1, 0.0
        else:
            n0, n1, n2 = 0.0, 0.0, 1.0 if x2 >= 0 else -1.0
    elif kind == ELLIPSOID:
        n0, n1, n2 = x0 / (size[0] * size[0]), x1 / (size[1] * size[1]), x2 / (size[2] * size[2])
    elif kind == BOX:
        g0, g1, g2 = abs(abs(x0) - size[0]), abs(abs(x1) - size[1]), abs(abs(x2) - size[2])
        if g0 <= g1 and g0 <= g2:
            n0, n1, n2 = 1.0 if x0 >= 0 else -1.0, 0.0, 0.0
        elif g1 <= g2:
            n0, n1, n2 = 0.0, 1.0 if x1 >= 0 else -1.0, 0.0
        else:
            n0, n1, n2 = 0.0, 0.0, 1.0 if x2 >= 0 else -1.0
    else:
        n0, n1, n2 = 0.0, 0.0, 1.0
    k = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if k == 0.0:
        return 0.0, 0.0, 1.0
    return n0 / k, n1 / k, n2 / k


@njit(**JIT)
def surface_normal_local(kind, size, x, n):
    n[0], n[1], n[2] = normal_local(kind, size, x[0], x[1], x[2])


@njit(inline="always", **JIT)
def _project_cylinder(r, h, x0, x1, x2):
    rho = math.sqrt(x0 * x0 + x1 * x1)
    ux, uy = (x0 / rho, x1 / rho) if rho > 0.0 else (1.0, 0.0)
    sz = min(max(x2, -h), h)
    d_side = (rho - r) ** 2 + (x2 - sz) ** 2
    cz = h if x2 >= 0 else -h
    cr = min(rho, r)
    d_cap = (rho - cr) ** 2 + (x2 - cz) ** 2
    if d_side <= d_cap:
        return r * ux, r * uy, sz
    return cr * ux, cr * uy, cz


@njit(inline="always", **JIT)
def _project_box(size, x0, x1, x2):
    c0 = min(max(x0, -size[0]), size[0])
    c1 = min(max(x1, -size[1]), size[1])
    c2 = min(max(x2, -size[2]), size[2])
    if abs(x0) > size[0] or abs(x1) > size[1] or abs(x2) > size[2]:
        return c0, c1, c2
    g0, g1, g2 = size[0] - abs(x0), size[1] - abs(x1), size[2] - abs(x2)  # inside: nearest face
    if g0 <= g1 and g0 <= g2:
        return (size[0] if x0 >= 0 else -size[0]), c1, c2
    if g1 <= g2:
        return c0, (size[1] if x1 >= 0 else -size[1]), c2
    return c0, c1, (size[2] if x2 >= 0 else -size[2])


@njit(inline="always", **JIT)
def project_s(kind, size, x0, x1, x2):
    """A point of the primitive's surface near (x0, x1, x2) (the closest one except for ellipsoids,
    where it is the radial retraction): the solver's retraction and its miss initialisation."""
    r = size[0]
    if kind == SPHERE or kind == CAPSULE:  # noqa: SIM109 (numba)
        cz = min(max(x2, -size[1]), size[1]) if kind == CAPSULE else 0.0
        vx, vy, vz = x0, x1, x2 - cz
        k = math.sqrt(vx * vx + vy * vy + vz * vz)
        if k == 0.0:
            vx, vy, vz, k = 1.0, 0.0, 0.0, 1.0
        return r * vx / k, r * vy / k, cz + r * vz / k
    if kind == CYLINDER:
        return _project_cylinder(r, size[1], x0, x1, x2)
    if kind == ELLIPSOID:
        q = math.sqrt((x0 / size[0]) ** 2 + (x1 / size[1]) ** 2 + (x2 / size[2]) ** 2)
        if q == 0.0:
            return size[0], 0.0, 0.0
        return x0 / q, x1 / q, x2 / q
    if kind == BOX:
        return _project_box(size, x0, x1, x2)
    return x0, x1, 0.0
