"""The contact solver's compiled core (numba): line/primitive crossings, surface projection,
Gauss-Newton on the surface, candidate scoring, and a tree forward kinematics for the batch path.

Why numba: the live path must turn one wrench into an estimate in tens of microseconds and the
batch path must do 300k frames/s; numpy pays a microsecond per call on 3-vectors. One compiled
implementation serves both paths, so the batch gives exactly the single-frame answers.

Everything is in metres, newtons and the base frame unless a name says ``_local`` (a primitive's
frame: MuJoCo geom conventions, capsules and cylinders along local z). Kind codes: KINDS below.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

SPHERE, CAPSULE, CYLINDER, ELLIPSOID, BOX, PLANE = 0, 1, 2, 3, 4, 5
KINDS = {"sphere": SPHERE, "capsule": CAPSULE, "cylinder": CYLINDER, "ellipsoid": ELLIPSOID, "box": BOX,
         "plane": PLANE}

# flag bits (names in ftc_hw.solver.types.FLAG_NAMES)
F_INVALID = 1
F_LOW_FORCE = 2
F_NO_CANDIDATE = 4
F_AMBIGUOUS = 8
F_GRAZING = 16
F_OFF_SURFACE = 32
F_SATURATED = 64
F_PULL = 128
F_OFF_LINE = 256
F_NOT_CONVERGED = 512

MAX_CROSS = 6  # crossings collected per primitive before reduction to entry/exit
JIT = {"cache": True, "nogil": True, "fastmath": False}


# -- small vector helpers ------------------------------------------------------------------------------
@njit(inline="always", **JIT)
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(inline="always", **JIT)
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(inline="always", **JIT)
def _tangent_basis(n, t1, t2):
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
    k = 1.0 / math.sqrt(_dot3(t1, t1))
    t1[0] *= k
    t1[1] *= k
    t1[2] *= k
    t2[0] = n[1] * t1[2] - n[2] * t1[1]
    t2[1] = n[2] * t1[0] - n[0] * t1[2]
    t2[2] = n[0] * t1[1] - n[1] * t1[0]


# -- line / primitive crossings (local frame) -----------------------------------------------------------
# Scalar helpers return tuples: numba keeps them on the stack (no heap allocation per call).
@njit(inline="always", **JIT)
def _ball(cz, r, o, d):
    """Crossings of the line o + s d (|d| = 1) with the sphere of radius r at (0, 0, cz), solved about
    the closest approach s0 so the root offset never suffers cancellation: (hit, s_lo, s_hi)."""
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


@njit(**JIT)
def crossings_local(kind, size, o, d, s_out):
    """Entry and exit of the line o + s d (d unit) through a closed primitive: returns the count
    (0, 1 for a plane, 2 otherwise; a tangent line gives a double root) and the s values, sorted."""
    r = size[0]
    h = size[1]
    lo, hi = math.inf, -math.inf
    if kind == SPHERE:
        ok, a, b = _ball(0.0, r, o, d)
        if ok:
            lo, hi = a, b
    elif kind == ELLIPSOID:
        # the unit sphere in coordinates scaled by the semi-axes; s keeps its metric meaning
        o0, o1, o2 = o[0] / size[0], o[1] / size[1], o[2] / size[2]
        d0, d1, d2 = d[0] / size[0], d[1] / size[1], d[2] / size[2]
        a = d0 * d0 + d1 * d1 + d2 * d2
        s0 = -(o0 * d0 + o1 * d1 + o2 * d2) / a
        m0, m1, m2 = o0 + s0 * d0, o1 + s0 * d1, o2 + s0 * d2
        m = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
        disc = (1.0 - m) * (1.0 + m)
        if disc >= -1e-14:
            hh = math.sqrt(max(disc, 0.0) / a)
            lo, hi = s0 - hh, s0 + hh
    elif kind == CAPSULE or kind == CYLINDER:  # noqa: SIM109 (numba)
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
    elif kind == BOX:
        lo, hi = -1e300, 1e300
        for i in range(3):
            if abs(d[i]) < 1e-300:
                if abs(o[i]) > size[i]:
                    return 0
                continue
            t1 = (-size[i] - o[i]) / d[i]
            t2 = (size[i] - o[i]) / d[i]
            if t1 > t2:
                t1, t2 = t2, t1
            lo = max(lo, t1)
            hi = min(hi, t2)
        if lo > hi + 1e-15 * (abs(lo) + abs(hi)):
            return 0
        hi = max(lo, hi)
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


@njit(inline="always", **JIT)
def inside_s(kind, size, x0, x1, x2, tol):
    """(x0, x1, x2) strictly inside the solid by more than tol (m), local frame."""
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
def project_s(kind, size, x0, x1, x2):
    """A point of the primitive's surface near (x0, x1, x2) (the closest one except for ellipsoids,
    where it is the radial retraction): the Gauss-Newton retraction and the miss initialisation."""
    r = size[0]
    if kind == SPHERE or kind == CAPSULE:  # noqa: SIM109 (numba)
        cz = min(max(x2, -size[1]), size[1]) if kind == CAPSULE else 0.0
        vx, vy, vz = x0, x1, x2 - cz
        k = math.sqrt(vx * vx + vy * vy + vz * vz)
        if k == 0.0:
            vx, vy, vz, k = 1.0, 0.0, 0.0, 1.0
        return r * vx / k, r * vy / k, cz + r * vz / k
    if kind == CYLINDER:
        h = size[1]
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
    if kind == ELLIPSOID:
        q = math.sqrt((x0 / size[0]) ** 2 + (x1 / size[1]) ** 2 + (x2 / size[2]) ** 2)
        if q == 0.0:
            return size[0], 0.0, 0.0
        return x0 / q, x1 / q, x2 / q
    if kind == BOX:
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
    return x0, x1, 0.0


@njit(inline="always", **JIT)
def _local_s(pos, mat, x0, x1, x2):
    """mat^T (x - pos) with mat row-major 3x3 as MuJoCo stores geom_xmat."""
    dx, dy, dz = x0 - pos[0], x1 - pos[1], x2 - pos[2]
    return (mat[0] * dx + mat[3] * dy + mat[6] * dz, mat[1] * dx + mat[4] * dy + mat[7] * dz,
            mat[2] * dx + mat[5] * dy + mat[8] * dz)


@njit(**JIT)
def _to_local(pos, mat, x, out):
    out[0], out[1], out[2] = _local_s(pos, mat, x[0], x[1], x[2])


@njit(**JIT)
def _dir_local(mat, v, out):
    out[0] = mat[0] * v[0] + mat[3] * v[1] + mat[6] * v[2]
    out[1] = mat[1] * v[0] + mat[4] * v[1] + mat[7] * v[2]
    out[2] = mat[2] * v[0] + mat[5] * v[1] + mat[8] * v[2]


@njit(inline="always", **JIT)
def _base_s(pos, mat, x0, x1, x2):
    return (pos[0] + mat[0] * x0 + mat[1] * x1 + mat[2] * x2, pos[1] + mat[3] * x0 + mat[4] * x1 + mat[5] * x2,
            pos[2] + mat[6] * x0 + mat[7] * x1 + mat[8] * x2)


@njit(**JIT)
def _to_base(pos, mat, x, out):
    out[0], out[1], out[2] = _base_s(pos, mat, x[0], x[1], x[2])


@njit(**JIT)
def _dir_base(mat, v, out):
    for i in range(3):
        out[i] = mat[3 * i] * v[0] + mat[3 * i + 1] * v[1] + mat[3 * i + 2] * v[2]


@njit(**JIT)
def _hidden(x, n, skip, kinds, sizes, gpos, gmat, eps):
    """Not on the arm's outer surface: the point just outside x (x + eps n, n the outward normal of
    primitive ``skip`` at x) lies inside another primitive. This also hides faces glued to another
    primitive (a joint's coincident caps), which a plain inside test at x cannot tell."""
    y0, y1, y2 = x[0] + eps * n[0], x[1] + eps * n[1], x[2] + eps * n[2]
    for g in range(kinds.shape[0]):
        if g == skip:
            continue
        b = sizes[g, 3]  # bounding radius: most primitives are far away
        dx, dy, dz = y0 - gpos[g, 0], y1 - gpos[g, 1], y2 - gpos[g, 2]
        if dx * dx + dy * dy + dz * dz > b * b:
            continue
        l0, l1, l2 = _local_s(gpos[g], gmat[g], y0, y1, y2)
        if inside_s(kinds[g], sizes[g], l0, l1, l2, 0.0):
            return True
    return False


# -- small dense linear algebra (numba's np.linalg would need scipy's BLAS) ------------------------------
@njit(**JIT)
def _cholesky(A, L):
    """L L^T = A for a symmetric positive definite A; False when A is not (numerically) SPD."""
    n = A.shape[0]
    for i in range(n):
        for j in range(i + 1):
            acc = A[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            if i == j:
                if not acc > 1e-300:
                    return False
                L[i, i] = math.sqrt(acc)
            else:
                L[i, j] = acc / L[j, j]
        for j in range(i + 1, n):
            L[i, j] = 0.0
    return True


@njit(**JIT)
def _chol_solve(L, b, x):
    n = L.shape[0]
    for i in range(n):
        acc = b[i]
        for k in range(i):
            acc -= L[i, k] * x[k]
        x[i] = acc / L[i, i]
    for i in range(n - 1, -1, -1):
        acc = x[i]
        for k in range(i + 1, n):
            acc -= L[k, i] * x[k]
        x[i] = acc / L[i, i]


@njit(inline="always", **JIT)
def _line_dist2(x, r0, u):
    """Squared distance of x from the line r0 + s u (u unit)."""
    d0, d1, d2 = x[0] - r0[0], x[1] - r0[1], x[2] - r0[2]
    along = d0 * u[0] + d1 * u[1] + d2 * u[2]
    return d0 * d0 + d1 * d1 + d2 * d2 - along * along


@njit(**JIT)
def _surface_near_line(kind, size, pos, mat, r0, u, point, normal):
    """The surface point below the line's closest approach to the primitive's centre (and its
    normal): where a line that misses comes nearest, up to the surface's curvature. Returns its
    squared distance from the line."""
    along = (pos[0] - r0[0]) * u[0] + (pos[1] - r0[1]) * u[1] + (pos[2] - r0[2]) * u[2]
    for i in range(3):
        point[i] = r0[i] + along * u[i]
    _project_base(kind, size, pos, mat, point, point, normal)
    return _line_dist2(point, r0, u)


# -- Gauss-Newton on one primitive's surface --------------------------------------------------------------
@njit(inline="always", **JIT)
def _project_base(kind, size, pos, mat, x, out_point, out_normal):
    l0, l1, l2 = _local_s(pos, mat, x[0], x[1], x[2])
    p0, p1, p2 = project_s(kind, size, l0, l1, l2)
    n0, n1, n2 = normal_local(kind, size, p0, p1, p2)
    out_point[0], out_point[1], out_point[2] = _base_s(pos, mat, p0, p1, p2)
    for i in range(3):
        out_normal[i] = mat[3 * i] * n0 + mat[3 * i + 1] * n1 + mat[3 * i + 2] * n2


@njit(inline="always", **JIT)
def _jacobian(c, p, t1, t2, J):
    """d(residual)/d(u1, u2, p) with residual = w - (p, c x p); rows: force then moment."""
    for i in range(6):
        for j in range(5):
            J[i, j] = 0.0
    J[0, 2] = -1.0
    J[1, 3] = -1.0
    J[2, 4] = -1.0
    # d(-(c x p))/dc = [p]x ; along t: p x t
    J[3, 0] = p[1] * t1[2] - p[2] * t1[1]
    J[4, 0] = p[2] * t1[0] - p[0] * t1[2]
    J[5, 0] = p[0] * t1[1] - p[1] * t1[0]
    J[3, 1] = p[1] * t2[2] - p[2] * t2[1]
    J[4, 1] = p[2] * t2[0] - p[0] * t2[2]
    J[5, 1] = p[0] * t2[1] - p[1] * t2[0]
    # d(-(c x p))/dp = -[c]x
    J[3, 2], J[3, 3], J[3, 4] = 0.0, c[2], -c[1]
    J[4, 2], J[4, 3], J[4, 4] = -c[2], 0.0, c[0]
    J[5, 2], J[5, 3], J[5, 4] = c[1], -c[0], 0.0


@njit(inline="always", **JIT)
def _residual(w, c, p, r):
    r[0] = w[0] - p[0]
    r[1] = w[1] - p[1]
    r[2] = w[2] - p[2]
    r[3] = w[3] - (c[1] * p[2] - c[2] * p[1])
    r[4] = w[4] - (c[2] * p[0] - c[0] * p[2])
    r[5] = w[5] - (c[0] * p[1] - c[1] * p[0])


@njit(inline="always", **JIT)
def _chi2(r, W):
    s = 0.0
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += W[i, j] * r[j]
        s += r[i] * acc
    return s


@njit(**JIT)
def _normal_matrix(J, W, r, H, g, WJ):
    for i in range(6):
        for a in range(5):
            acc = 0.0
            for k in range(6):
                acc += W[i, k] * J[k, a]
            WJ[i, a] = acc
    for a in range(5):
        for b in range(5):
            acc = 0.0
            for i in range(6):
                acc += J[i, a] * WJ[i, b]
            H[a, b] = acc
        acc = 0.0
        for i in range(6):
            acc += WJ[i, a] * r[i]
        g[a] = acc


REFINE_WS = 160  # workspace (float64 entries) refine needs
WS_RAW = 64 + REFINE_WS


@njit(**JIT)
def workspace_size(max_cand):
    """Floats of scratch solve_frame needs for max_cand candidates."""
    return WS_RAW + max_cand * 40


@njit(**JIT)
def refine(kind, size, pos, mat, w, W, c0, p0, max_iter, c, p, n, cov, ws):
    """Weighted least squares on one primitive's surface: minimise (w - h)^T W (w - h) with
    h = (p, c x p), c on the surface. Manifold Gauss-Newton from (c0, p0): tangent-plane steps,
    retraction by projection onto the surface. Returns (chi2, iterations, converged, condition
    estimate of J^T W J); fills c, p, the normal n at c, and cov (5x5: tangent coordinates t1, t2 at c,
    then p) = (J^T W J)^-1."""
    t1 = ws[0:3]
    t2 = ws[3:6]
    J = ws[6:36].reshape((6, 5))
    H = ws[36:61].reshape((5, 5))
    g = ws[61:66]
    r = ws[66:72]
    trial_c = ws[72:75]
    trial_n = ws[75:78]
    trial_p = ws[78:81]
    Lc = ws[81:106].reshape((5, 5))
    step = ws[106:111]
    WJ = ws[111:141].reshape((6, 5))
    e = ws[141:146]
    col = ws[146:151]
    _project_base(kind, size, pos, mat, c0, c, n)
    for i in range(3):
        p[i] = p0[i]
    _residual(w, c, p, r)
    chi2 = _chi2(r, W)
    converged = False
    it = 0
    while it < max_iter:
        it += 1
        _tangent_basis(n, t1, t2)
        _jacobian(c, p, t1, t2, J)
        _normal_matrix(J, W, r, H, g, WJ)
        if not _cholesky(H, Lc):  # singular: the force is too small to locate anything
            break
        _chol_solve(Lc, g, step)
        for i in range(5):
            step[i] = -step[i]
        lam = 1.0
        improved = False
        for _ in range(8):  # backtracking keeps every accepted step a descent
            for i in range(3):
                trial_c[i] = c[i] + lam * (step[0] * t1[i] + step[1] * t2[i])
                trial_p[i] = p[i] + lam * step[2 + i]
            _project_base(kind, size, pos, mat, trial_c, trial_c, trial_n)
            _residual(w, trial_c, trial_p, r)
            chi2_new = _chi2(r, W)
            if chi2_new <= chi2 * (1.0 + 1e-12) + 1e-300:
                improved = True
                break
            lam *= 0.5
        if not improved:
            _residual(w, c, p, r)
            converged = True  # no descent left at rounding level
            break
        step_len = lam * math.sqrt(step[0] ** 2 + step[1] ** 2)
        for i in range(3):
            c[i] = trial_c[i]
            p[i] = trial_p[i]
            n[i] = trial_n[i]
        old = chi2
        chi2 = chi2_new
        if step_len <= 1e-13 * (1.0 + math.sqrt(_dot3(c, c))) or old - chi2 <= 1e-14 * (1.0 + old):
            converged = True
            break
    _tangent_basis(n, t1, t2)
    _jacobian(c, p, t1, t2, J)
    _normal_matrix(J, W, r, H, g, WJ)
    cond = math.inf
    if _cholesky(H, Lc):
        lo, hi = math.inf, 0.0
        for b in range(5):
            lo = min(lo, Lc[b, b])
            hi = max(hi, Lc[b, b])
        cond = (hi / lo) ** 2  # from the Cholesky pivots: a cheap lower bound of the condition number
        for b in range(5):
            e[:] = 0.0
            e[b] = 1.0
            _chol_solve(Lc, e, col)
            for a in range(5):
                cov[a, b] = col[a]
    else:
        for a in range(5):
            for b in range(5):
                cov[a, b] = np.inf if a == b else 0.0
    return chi2, it, converged, cond


# -- the whole frame ----------------------------------------------------------------------------------------
# layout of the packed arguments (one array each: numba's dispatch costs ~0.2 us per argument)
PI_KIND, PI_LINK, PI_TOUCH, PI_PULLS = 0, 1, 2, 3  # prim_i columns
CFG_LOW_FORCE, CFG_GRAZING_COS, CFG_OFF_CHI2, CFG_AMBIGUITY, CFG_HIDE_TOL, CFG_MAX_ITER, CFG_MISS_TOL = range(7)
O_POINT, O_FORCE, O_NORMAL, O_SCALARS, O_COV, O_SIZE = 0, 3, 6, 9, 17, 53  # out vector
S_FLAGS, S_BEST, S_NCAND, S_CHI2, S_RESIDUAL, S_COS, S_COND, S_ITER = 0, 1, 2, 3, 4, 5, 6, 7  # scalars
C_POINT, C_FORCE, C_SCORE, C_CHI2, C_SIZE = 0, 3, 6, 7, 8  # cand_f columns


@njit(**JIT)
def solve_frame(w, W, prim_i, sizes, gpos, gmat, joint_axis, joint_anchor, link_joint, tau_ext, tau_var, use_tau,
                cfg, out, cand_prim, cand_f, ws, raw_prim):
    """One frame: external contact wrench w = (p, c x p) about the base origin, base frame.

    ``out`` receives point, force, normal, the scalars (flags, best index, candidate count, chi2,
    residual = moment along the force line (N m), cos of incidence, condition number, iterations)
    and the 6x6 covariance of (point, force). Candidates are sorted best first, their score is the
    log-likelihood (higher is better). Returns the number of candidates.
    """
    kinds = prim_i[:, PI_KIND]
    prim_link = prim_i[:, PI_LINK]
    prim_touch = prim_i[:, PI_TOUCH]
    prim_pulls = prim_i[:, PI_PULLS]
    low_force = cfg[CFG_LOW_FORCE]
    grazing_cos = cfg[CFG_GRAZING_COS]
    off_chi2 = cfg[CFG_OFF_CHI2]
    ambiguity_dlogl = cfg[CFG_AMBIGUITY]
    hide_tol = cfg[CFG_HIDE_TOL]
    max_iter = int(cfg[CFG_MAX_ITER])
    miss_num = cfg[CFG_MISS_TOL]  # N m: divided by |f| below, the line position's uncertainty (m)
    out_point = out[O_POINT:O_POINT + 3]
    out_force = out[O_FORCE:O_FORCE + 3]
    out_normal = out[O_NORMAL:O_NORMAL + 3]
    out_scalars = out[O_SCALARS:O_SCALARS + 8]
    out_cov = out[O_COV:O_COV + 36].reshape((6, 6))
    cand_point = cand_f[:, C_POINT:C_POINT + 3]
    cand_force = cand_f[:, C_FORCE:C_FORCE + 3]
    cand_score = cand_f[:, C_SCORE]
    cand_chi2 = cand_f[:, C_CHI2]
    n_prim = kinds.shape[0]
    max_cand = cand_prim.shape[0]
    flags = 0
    for i in range(8):
        out_scalars[i] = 0.0
    out_scalars[1] = -1.0
    for i in range(6):
        if not math.isfinite(w[i]):
            out_scalars[0] = F_INVALID
            return 0
    f = w[0:3]
    m = w[3:6]
    fn = math.sqrt(_dot3(f, f))
    if fn == 0.0:
        out_scalars[0] = F_LOW_FORCE | F_NO_CANDIDATE
        return 0
    if fn < low_force:
        flags |= F_LOW_FORCE
    miss_tol = miss_num / fn
    # ws (workspace_size(max_cand) floats) and raw_prim (max_cand ints) are the caller's scratch:
    # numba allocates arrays on the heap, so a frame allocates nothing itself
    u = ws[0:3]
    for i in range(3):
        u[i] = f[i] / fn
    r0 = ws[3:6]
    _cross(f, m, r0)
    for i in range(3):
        r0[i] /= fn * fn
    out_scalars[4] = _dot3(m, u)

    o_loc = ws[6:9]
    d_loc = ws[9:12]
    s = ws[12:14]
    x_loc = ws[14:17]
    n_loc = ws[17:20]
    x = ws[20:23]
    nb = ws[23:26]
    tmp = ws[41:44]
    # raw candidates: (primitive, s) of admissible crossings
    raw_point = ws[WS_RAW:WS_RAW + 3 * max_cand].reshape((max_cand, 3))
    n_raw = 0
    for g in range(n_prim):
        if not prim_touch[g]:
            continue
        # the line's distance to the primitive's centre against its bounding radius
        if _line_dist2(gpos[g], r0, u) > sizes[g, 3] ** 2:
            continue
        _to_local(gpos[g], gmat[g], r0, o_loc)
        _dir_local(gmat[g], u, d_loc)
        k = crossings_local(kinds[g], sizes[g], o_loc, d_loc, s)
        for j in range(k):
            for i in range(3):
                x_loc[i] = o_loc[i] + s[j] * d_loc[i]
            surface_normal_local(kinds[g], sizes[g], x_loc, n_loc)
            _to_base(gpos[g], gmat[g], x_loc, x)
            _dir_base(gmat[g], n_loc, nb)
            cosi = _dot3(u, nb)
            if cosi > 0.0 and not prim_pulls[g]:
                continue
            if _hidden(x, nb, g, kinds, sizes, gpos, gmat, hide_tol):
                continue
            dup = False
            for kk in range(n_raw):  # a seam point reported by both primitives of one link
                if prim_link[raw_prim[kk]] == prim_link[g]:
                    d2 = 0.0
                    for i in range(3):
                        d2 += (raw_point[kk, i] - x[i]) ** 2
                    if d2 <= (1e-9 * (1.0 + math.sqrt(_dot3(x, x)))) ** 2:
                        dup = True
            if not dup and n_raw < max_cand:
                raw_prim[n_raw] = g
                for i in range(3):
                    raw_point[n_raw, i] = x[i]
                n_raw += 1
    n_crossed = n_raw
    if miss_tol > 0.0:
        # Near misses within the line's own uncertainty are candidates too: noise can push the line
        # off the touched link. One per link that has no crossing, the closest; the fit decides.
        for g in range(n_prim):
            if not prim_touch[g]:
                continue
            crossed = False
            for kk in range(n_crossed):
                if prim_link[raw_prim[kk]] == prim_link[g]:
                    crossed = True
            if crossed:
                continue
            b = sizes[g, 3] + miss_tol
            if _line_dist2(gpos[g], r0, u) > b * b:
                continue
            miss2 = _surface_near_line(kinds[g], sizes[g], gpos[g], gmat[g], r0, u, x, nb)
            cosn = _dot3(u, nb)
            # a clear push (or pull where allowed): a grazing near miss is no evidence of a touch there
            if miss2 >= miss_tol * miss_tol or abs(cosn) < grazing_cos or (cosn > 0.0 and not prim_pulls[g]):
                continue
            if _hidden(x, nb, g, kinds, sizes, gpos, gmat, hide_tol):
                continue
            slot = -1
            for kk in range(n_crossed, n_raw):  # one per link: keep the closest
                if prim_link[raw_prim[kk]] == prim_link[g]:
                    slot = kk
            if slot >= 0:
                if _line_dist2(raw_point[slot], r0, u) <= miss2:
                    continue
            elif n_raw < max_cand:
                slot = n_raw
                n_raw += 1
            else:
                continue
            raw_prim[slot] = g
            for i in range(3):
                raw_point[slot, i] = x[i]
    if n_raw == 0:
        # the line misses (noise, or not a contact on the arm): start from the surface point
        # nearest the line on the closest touchable primitive(s)
        flags |= F_OFF_LINE
        best = 1e300
        for g in range(n_prim):
            if not prim_touch[g]:
                continue
            dist2 = _surface_near_line(kinds[g], sizes[g], gpos[g], gmat[g], r0, u, nb, n_loc)
            if dist2 < best:
                best = dist2
                raw_prim[0] = g
                for i in range(3):
                    raw_point[0, i] = nb[i]
        if best < 1e300:
            n_raw = 1

    c = ws[26:29]
    p = ws[29:32]
    nrm = ws[32:35]
    t1 = ws[35:38]
    t2 = ws[38:41]
    T = ws[44:50].reshape((3, 2))
    rws = ws[64:64 + REFINE_WS]
    base = WS_RAW + 3 * max_cand
    cand_cov = ws[base:base + max_cand * 25].reshape((max_cand, 5, 5))
    base += max_cand * 25
    cand_normal = ws[base:base + max_cand * 3].reshape((max_cand, 3))
    base += max_cand * 3
    cand_iter = ws[base:base + max_cand]
    base += max_cand
    cand_conv = ws[base:base + max_cand]  # 1.0 converged, 0.0 not
    base += max_cand
    cand_cond = ws[base:base + max_cand]
    cov = cand_cov[0]
    n_joints = joint_axis.shape[0]
    for k in range(n_raw):
        g = raw_prim[k]
        cov = cand_cov[k]
        chi2, iters, conv, cond = refine(kinds[g], sizes[g], gpos[g], gmat[g], w, W, raw_point[k], f, max_iter,
                                   c, p, nrm, cov, rws)
        logl = -0.5 * chi2
        if use_tau:
            link = prim_link[g]
            for j in range(n_joints):
                pred = 0.0
                if link_joint[link, j]:
                    for i in range(3):
                        tmp[i] = c[i] - joint_anchor[j, i]
                    _cross(tmp, p, x)
                    pred = _dot3(joint_axis[j], x)
                e = tau_ext[j] - pred
                logl -= 0.5 * e * e / tau_var[j]
        # a faint preference for the first crossing along the force (the most exposed point):
        # it only orders candidates the data cannot tell apart
        for i in range(3):
            tmp[i] = c[i] - r0[i]
        logl -= 1e-12 * _dot3(tmp, u)
        cand_prim[k] = g
        cand_score[k] = logl
        cand_chi2[k] = chi2
        cand_iter[k] = iters
        cand_conv[k] = 1.0 if conv else 0.0
        cand_cond[k] = cond
        for i in range(3):
            cand_point[k, i] = c[i]
            cand_force[k, i] = p[i]
            cand_normal[k, i] = nrm[i]
    if n_raw == 0:
        out_scalars[0] = flags | F_NO_CANDIDATE
        return 0
    # sort candidates by score, best first (insertion sort: a handful of entries)
    order = np.argsort(-cand_score[:n_raw], kind="mergesort")
    best = order[0]
    if n_raw > 1 and cand_score[best] - cand_score[order[1]] < ambiguity_dlogl:
        flags |= F_AMBIGUOUS
    chi2 = cand_chi2[best]
    if chi2 > off_chi2:
        flags |= F_OFF_SURFACE
    if cand_conv[best] == 0.0:
        flags |= F_NOT_CONVERGED
    for i in range(3):
        out_point[i] = cand_point[best, i]
        out_force[i] = cand_force[best, i]
        out_normal[i] = cand_normal[best, i]
    pn = math.sqrt(_dot3(out_force, out_force))
    cosi = _dot3(out_force, out_normal) / pn if pn > 0 else 0.0
    if cosi > 0.0:
        flags |= F_PULL
    if abs(cosi) < grazing_cos:
        flags |= F_GRAZING
    # covariance in the base frame: point (3x3) from the tangent block, force (3x3)
    _tangent_basis(out_normal, t1, t2)
    cb = cand_cov[best]
    for i in range(3):
        T[i, 0] = t1[i]
        T[i, 1] = t2[i]
    for a in range(3):
        for b in range(3):
            acc = 0.0
            for i in range(2):
                for j in range(2):
                    acc += T[a, i] * cb[i, j] * T[b, j]
            out_cov[a, b] = acc
            out_cov[3 + a, 3 + b] = cb[2 + a, 2 + b]
            acc = 0.0
            for i in range(2):
                acc += T[a, i] * cb[i, 2 + b]
            out_cov[a, 3 + b] = acc
            out_cov[3 + b, a] = acc
    out_scalars[6] = cand_cond[best]
    out_scalars[0] = flags
    out_scalars[1] = best
    out_scalars[2] = n_raw
    out_scalars[3] = chi2
    out_scalars[5] = cosi
    out_scalars[7] = cand_iter[best]
    # reorder candidates in place, best first
    identity = True
    for k in range(n_raw):
        if order[k] != k:
            identity = False
    if identity:
        out_scalars[1] = 0
        return n_raw
    tp = cand_prim[:n_raw].copy()
    tpt = cand_point[:n_raw].copy()
    tf = cand_force[:n_raw].copy()
    ts = cand_score[:n_raw].copy()
    tc = cand_chi2[:n_raw].copy()
    for k in range(n_raw):
        o = order[k]
        cand_prim[k] = tp[o]
        cand_score[k] = ts[o]
        cand_chi2[k] = tc[o]
        for i in range(3):
            cand_point[k, i] = tpt[o, i]
            cand_force[k, i] = tf[o, i]
    out_scalars[1] = 0
    return n_raw


# -- forward kinematics of the geoms (batch path) ---------------------------------------------------------
@njit(**JIT)
def _quat_mul(a, b, out):
    out[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3]
    out[1] = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2]
    out[2] = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1]
    out[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]


@njit(**JIT)
def _quat_mat(q, m):
    w, x, y, z = q[0], q[1], q[2], q[3]
    m[0] = 1 - 2 * (y * y + z * z)
    m[1] = 2 * (x * y - w * z)
    m[2] = 2 * (x * z + w * y)
    m[3] = 2 * (x * y + w * z)
    m[4] = 1 - 2 * (x * x + z * z)
    m[5] = 2 * (y * z - w * x)
    m[6] = 2 * (x * z - w * y)
    m[7] = 2 * (y * z + w * x)
    m[8] = 1 - 2 * (x * x + y * y)


@njit(**JIT)
def tree_kinematics(q, tree_i, tree_f, geom_i, geom_f, xpos, xquat, gpos, gmat, janchor, jaxis):
    """MuJoCo's forward kinematics for trees of hinge/slide joints (one joint per body at most),
    from the compiled MjModel arrays; checked against mj_kinematics in the tests.

    tree_i columns: parent, joint (-1 none), joint type, joint qpos address;
    tree_f columns: body pos (3), body quat (4), joint axis (3), joint pos (3) (joint of that body).
    geom_i: body; geom_f: geom pos (3), geom quat (4).
    """
    body_parent = tree_i[:, 0]
    body_pos = tree_f[:, 0:3]
    body_quat = tree_f[:, 3:7]
    body_jnt = tree_i[:, 1]
    geom_body = geom_i[:, 0]
    geom_pos = geom_f[:, 0:3]
    geom_quat = geom_f[:, 3:7]
    nb = body_parent.shape[0]
    qtmp = np.empty(4)
    rot = np.empty(9)
    jq = np.empty(4)
    v = np.empty(3)
    xpos[0, :] = 0.0
    xquat[0, 0], xquat[0, 1], xquat[0, 2], xquat[0, 3] = 1.0, 0.0, 0.0, 0.0
    for b in range(1, nb):
        par = body_parent[b]
        _quat_mat(xquat[par], rot)
        _dir_base(rot, body_pos[b], v)
        for i in range(3):
            xpos[b, i] = xpos[par, i] + v[i]
        _quat_mul(xquat[par], body_quat[b], qtmp)
        for i in range(4):
            xquat[b, i] = qtmp[i]
        j = body_jnt[b]
        if j >= 0:
            _quat_mat(xquat[b], rot)
            jpos = tree_f[b, 10:13]
            jax = tree_f[b, 7:10]
            _dir_base(rot, jpos, v)
            for i in range(3):
                janchor[j, i] = xpos[b, i] + v[i]
            _dir_base(rot, jax, v)
            for i in range(3):
                jaxis[j, i] = v[i]
            angle = q[tree_i[b, 3]]
            if tree_i[b, 2] == 3:  # hinge: rotate about the axis through the anchor
                half = 0.5 * angle
                sh = math.sin(half)
                jq[0] = math.cos(half)
                jq[1] = jax[0] * sh
                jq[2] = jax[1] * sh
                jq[3] = jax[2] * sh
                _quat_mul(xquat[b], jq, qtmp)
                nq = math.sqrt(qtmp[0] ** 2 + qtmp[1] ** 2 + qtmp[2] ** 2 + qtmp[3] ** 2)
                for i in range(4):
                    xquat[b, i] = qtmp[i] / nq
                _quat_mat(xquat[b], rot)
                _dir_base(rot, jpos, v)
                for i in range(3):
                    xpos[b, i] = janchor[j, i] - v[i]
            else:  # slide
                for i in range(3):
                    xpos[b, i] += jaxis[j, i] * angle
    for g in range(geom_body.shape[0]):
        b = geom_body[g]
        _quat_mat(xquat[b], rot)
        _dir_base(rot, geom_pos[g], v)
        for i in range(3):
            gpos[g, i] = xpos[b, i] + v[i]
        _quat_mul(xquat[b], geom_quat[g], qtmp)
        _quat_mat(qtmp, gmat[g])


@njit(**JIT)
def solve_frame_q(w, q, W, prim_i, sizes, link_joint, tau_ext, tau_var, use_tau, cfg, tree_i, tree_f, geom_i, geom_f,
                  out, cand_prim, cand_f, ws, raw_prim, xpos, xquat, gpos, gmat, janchor, jaxis):
    """solve_frame at joint angles q (the model's qpos): the same kinematics as the batch path, so a
    frame gets bit-identical answers on either path."""
    tree_kinematics(q, tree_i, tree_f, geom_i, geom_f, xpos, xquat, gpos, gmat, janchor, jaxis)
    return solve_frame(w, W, prim_i, sizes, gpos, gmat, jaxis, janchor, link_joint, tau_ext, tau_var, use_tau, cfg,
                       out, cand_prim, cand_f, ws, raw_prim)


@njit(parallel=True, cache=True, nogil=True)
def solve_batch(wrenches, qs, Ws, prim_i, sizes, link_joint, tau_ext, tau_var, use_tau, cfg, tree_i, tree_f,
                geom_i, geom_f, max_cand, out, cand_prim, cand_f, n_cand):
    """solve_frame over N frames, each with its own joint angles; kinematics inside. Frames go in
    chunks over the threads, each chunk with its own scratch; the best cand_prim.shape[1] candidates
    of each frame are kept (n_cand counts them all)."""
    n = wrenches.shape[0]
    nb = tree_i.shape[0]
    ng = geom_i.shape[0]
    nj = tau_var.shape[0]
    keep = cand_prim.shape[1]
    n_chunks = min(n, 64)
    for ch in prange(n_chunks):
        xpos = np.empty((nb, 3))
        xquat = np.empty((nb, 4))
        gpos = np.empty((ng, 3))
        gmat = np.empty((ng, 9))
        janchor = np.zeros((nj, 3))
        jaxis = np.zeros((nj, 3))
        ws = np.empty(workspace_size(max_cand))
        raw_prim = np.empty(max_cand, dtype=np.int64)
        cp = np.empty(max_cand, dtype=np.int64)
        cf = np.empty((max_cand, C_SIZE))
        for i in range(ch * n // n_chunks, (ch + 1) * n // n_chunks):
            tree_kinematics(qs[i], tree_i, tree_f, geom_i, geom_f, xpos, xquat, gpos, gmat, janchor, jaxis)
            W = Ws[i] if Ws.shape[0] > 1 else Ws[0]
            k = solve_frame(wrenches[i], W, prim_i, sizes, gpos, gmat, jaxis, janchor, link_joint, tau_ext[i],
                            tau_var, use_tau[i], cfg, out[i], cp, cf, ws, raw_prim)
            n_cand[i] = k
            for j in range(min(k, keep)):
                cand_prim[i, j] = cp[j]
                for c in range(C_SIZE):
                    cand_f[i, j, c] = cf[j, c]
