"""The contact solver's compiled core (numba): candidates from the force line's crossings and near
misses, Gauss-Newton on the surface, candidate scoring, and a tree forward kinematics for the batch
path. The line/primitive geometry is the engine's (ftc_hw.geometry).

Why numba: the live path must turn one wrench into an estimate in tens of microseconds and the
batch path must do 300k frames/s; numpy pays a microsecond per call on 3-vectors. One compiled
implementation serves both paths, so the batch gives exactly the single-frame answers. numba checks a
cached kernel against its own file only, so this module drops its caches when an engine source
changes (drop_stale_caches).

Everything is in metres, newtons and the base frame unless a name says ``_local`` (a primitive's
frame: MuJoCo geom conventions, capsules and cylinders along local z). Kind codes: ftc_hw.geometry.kinds.
Inside the kernels, arrays travel in tuples (free in compiled code): ``prims`` = (prim_i, sizes, gpos,
gmat), the primitives and their poses at the frame's q; ``prim`` = (kind, size, pos, mat), one of them;
``joints`` = (joint_axis, joint_anchor, link_joint, jnt_i, jnt_ratio); ``torques`` = (tau_ext, tau_var,
use_tau); ``cands`` = (cand_prim, cand_f), with the fitted normals, iterations and convergence from the
scratch once fitted. Scratch lives in one float array ``ws`` at named offsets (WS_*), its views made
once per frame or per fit (a reshape is a C call).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numba import njit, prange

from ..geometry.crossings import crossings_local
from ..geometry.frames import dir_to_base, dir_to_local, to_base, to_base_s, to_local, to_local_s
from ..geometry.jit import ENGINE_SOURCES, JIT, JIT_ALLOC, drop_stale_caches
from ..geometry.kinds import BOX, CAPSULE, CYLINDER, PLANE
from ..geometry.solid import depth_s, inside_s
from ..geometry.surface import normal_local, project_s, surface_normal_local
from ..geometry.vec import cross3, dot3, line_dist2, tangent_basis

drop_stale_caches(Path(__file__).resolve().parent / "__pycache__", ENGINE_SOURCES)

# flag bits (names in ftc_hw.solver.solver.FLAG_NAMES)
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

JNT_SLIDE = 2  # MuJoCo's mjJNT_SLIDE and mjJNT_HINGE
JNT_HINGE = 3

# layout of the packed arguments (one array each: numba's dispatch costs ~0.2 us per argument)
PI_KIND, PI_LINK, PI_TOUCH, PI_PULLS = 0, 1, 2, 3  # prim_i columns
(CFG_LOW_FORCE, CFG_GRAZING_COS, CFG_OFF_CHI2, CFG_AMBIGUITY, CFG_HIDE_TOL, CFG_MAX_ITER, CFG_MISS_TOL, CFG_MISS_T,
 CFG_MISS_F, CFG_MISS_SIGMA) = range(10)
CFG_SIZE = 10
O_POINT, O_FORCE, O_NORMAL, O_SCALARS, O_COV, O_SIZE = 0, 3, 6, 9, 17, 53  # out vector
S_FLAGS, S_BEST, S_NCAND, S_CHI2, S_RESIDUAL, S_COS, S_COND, S_ITER = 0, 1, 2, 3, 4, 5, 6, 7  # scalars
C_POINT, C_FORCE, C_SCORE, C_CHI2, C_SIZE = 0, 3, 6, 7, 8  # cand_f columns

POOR_FIT_CHI2 = 3.841  # chi-square, 1 degree of freedom (6 equations, 5 unknowns), p = 0.05

# solve_frame's scratch: where each view starts in ws (its length in the comments)
WS_U, WS_R0 = 0, 3  # the force line: direction, point nearest the origin (3 each)
WS_O_LOC, WS_D_LOC, WS_S = 6, 9, 12  # the line in a primitive's frame (3 each), its crossings (2)
WS_X_LOC, WS_N_LOC, WS_X, WS_NB = 14, 17, 20, 23  # a point and its normal, local then base frame (3 each)
WS_C, WS_P, WS_NRM = 26, 29, 32  # a candidate's fit: point, force, normal (3 each)
WS_T1, WS_T2, WS_TMP = 35, 38, 41  # a tangent basis, a temporary (3 each)
WS_T = 44  # the best fit's tangent basis as a 3x2 matrix (6)
WS_GROWN = 50  # a primitive's size grown by the line's uncertainty (4)
WS_C2, WS_P2, WS_N2 = 54, 57, 60  # a fit from a box face: point, force, normal (3 each)
WS_REFINE = 64  # refine's and _fit_cov's own scratch (REFINE_WS)
REFINE_WS = 200
WS_RAW = WS_REFINE + REFINE_WS  # then the per-candidate rows (_cand_views)
# refine's scratch (offsets into its own ws)
RW_T1, RW_T2, RW_J, RW_WJ, RW_R = 0, 3, 6, 18, 30  # tangent basis (3, 3), J and W J (6x2 each), residual (6)
RW_TRIAL_C, RW_TRIAL_N, RW_TRIAL_P, RW_TRIAL_R = 36, 39, 42, 45  # a trial step's fit (3, 3, 3, 6)
RW_FAC, RW_TFAC = 51, 66  # _best_force's factors (15), the trial's (15)
# _fit_cov's (in the same scratch, after refine's steps)
FC_T1, FC_T2, FC_J, FC_H, FC_G, FC_R = 0, 3, 6, 36, 61, 66  # basis (3, 3), J (6x5), J^T W J (5x5), J^T W r (5), r (6)
FC_L, FC_WJ, FC_E, FC_COL = 81, 111, 141, 146  # its Cholesky factor (5x5), W J (6x5), a unit vector, a column (5)


@njit(**JIT)
def workspace_size(max_cand):
    """Floats of scratch solve_frame needs for max_cand candidates."""
    return WS_RAW + max_cand * 8 + 25


@njit(inline="always", **JIT)
def _cand_views(ws, max_cand):
    """The per-candidate scratch: raw points and fitted normals (max_cand x 3 each), iterations,
    converged (1.0 or 0.0), and the best fit's covariance (5x5)."""
    at = WS_RAW
    raw_point = ws[at:at + 3 * max_cand].reshape((max_cand, 3))
    at += 3 * max_cand
    normal = ws[at:at + 3 * max_cand].reshape((max_cand, 3))
    at += 3 * max_cand
    iters = ws[at:at + max_cand]
    conv = ws[at + max_cand:at + 2 * max_cand]
    at += 2 * max_cand
    return raw_point, normal, iters, conv, ws[at:at + 25].reshape((5, 5))


@njit(inline="always", **JIT)
def _line(ws):
    """The force line: direction u, point r0 nearest the origin."""
    return ws[WS_U:WS_U + 3], ws[WS_R0:WS_R0 + 3]


@njit(inline="always", **JIT)
def _prim(prims, g):
    """(kind, size, pos, mat) of primitive g."""
    prim_i, sizes, gpos, gmat = prims
    return prim_i[g, PI_KIND], sizes[g], gpos[g], gmat[g]


# -- the arm's outline ----------------------------------------------------------------------------------
@njit(**JIT)
def _hidden(x, n, skip, prims, eps):
    """Not on the arm's outer surface: the point just outside x (x + eps n, n the outward normal of
    primitive ``skip`` at x) lies inside another primitive. This also hides faces glued to another
    primitive (a joint's coincident caps), which a plain inside test at x cannot tell."""
    prim_i, sizes, gpos, gmat = prims
    y0, y1, y2 = x[0] + eps * n[0], x[1] + eps * n[1], x[2] + eps * n[2]
    for g in range(prim_i.shape[0]):
        if g == skip:
            continue
        b = sizes[g, 3]  # bounding radius: most primitives are far away
        dx, dy, dz = y0 - gpos[g, 0], y1 - gpos[g, 1], y2 - gpos[g, 2]
        if dx * dx + dy * dy + dz * dz > b * b:
            continue
        l0, l1, l2 = to_local_s(gpos[g], gmat[g], y0, y1, y2)
        if inside_s(prim_i[g, PI_KIND], sizes[g], l0, l1, l2, 0.0):
            return True
    return False


@njit(**JIT)
def _off_outline(x, n, skip, prims, depth, eps):
    """A fitted point that is not on the arm's outline: more than ``depth`` (m) inside a primitive
    other than ``skip``, or on another primitive's surface (within eps) with its normal n pointing
    into it (a face glued to another part: a joint's coincident caps)."""
    prim_i, sizes, gpos, gmat = prims
    y0, y1, y2 = x[0] + eps * n[0], x[1] + eps * n[1], x[2] + eps * n[2]
    for g in range(prim_i.shape[0]):
        if g == skip:
            continue
        b = sizes[g, 3]
        dx, dy, dz = x[0] - gpos[g, 0], x[1] - gpos[g, 1], x[2] - gpos[g, 2]
        if dx * dx + dy * dy + dz * dz > b * b:
            continue
        kind = prim_i[g, PI_KIND]
        l0, l1, l2 = to_local_s(gpos[g], gmat[g], x[0], x[1], x[2])
        d = depth_s(kind, sizes[g], l0, l1, l2)
        if d > depth:
            return True
        if abs(d) <= eps:
            l0, l1, l2 = to_local_s(gpos[g], gmat[g], y0, y1, y2)
            if depth_s(kind, sizes[g], l0, l1, l2) > 0.0:
                return True
    return False


@njit(inline="always", **JIT)
def _line_sigma(S, x, u, fn, t1, t2):
    """The largest standard deviation (m) of the force line's position across it near the point x,
    from the covariance S of the wrench: the line moves by u x dm_x / |f|, where dm_x = dm - x x df
    is the moment about x, and dm_x . e = (x x e, e) . (df, dm)."""
    tangent_basis(u, t1, t2)
    k11 = k12 = k22 = 0.0
    g1 = (x[1] * t1[2] - x[2] * t1[1], x[2] * t1[0] - x[0] * t1[2], x[0] * t1[1] - x[1] * t1[0], t1[0], t1[1], t1[2])
    g2 = (x[1] * t2[2] - x[2] * t2[1], x[2] * t2[0] - x[0] * t2[2], x[0] * t2[1] - x[1] * t2[0], t2[0], t2[1], t2[2])
    for i in range(6):
        s1 = 0.0
        s2 = 0.0
        for j in range(6):
            s1 += S[i, j] * g1[j]
            s2 += S[i, j] * g2[j]
        k11 += g1[i] * s1
        k12 += g1[i] * s2
        k22 += g2[i] * s2
    half = 0.5 * (k11 + k22)
    lam = half + math.sqrt(max(0.25 * (k11 - k22) ** 2 + k12 * k12, 0.0))
    return math.sqrt(max(lam, 0.0)) / fn


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
def _congruence(A, S, out):
    """out = A S A^T."""
    for i in range(A.shape[0]):
        for j in range(A.shape[0]):
            acc = 0.0
            for k in range(A.shape[1]):
                for m in range(A.shape[1]):
                    acc += A[i, k] * S[k, m] * A[j, m]
            out[i, j] = acc


@njit(**JIT)
def _chol_inverse(L, e, col, inv):
    """inv = (L L^T)^-1, column by column; e, col: scratch of L's size."""
    n = L.shape[0]
    for b in range(n):
        e[:] = 0.0
        e[b] = 1.0
        _chol_solve(L, e, col)
        for a in range(n):
            inv[a, b] = col[a]


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


# -- where a line that misses comes nearest -------------------------------------------------------------
@njit(**JIT)
def _surface_near_line(prim, r0, u, point, normal):
    """The surface point below the line's closest approach to the primitive's centre (and its
    normal): where a line that misses comes nearest, up to the surface's curvature. Returns its
    squared distance from the line."""
    pos = prim[2]
    along = (pos[0] - r0[0]) * u[0] + (pos[1] - r0[1]) * u[1] + (pos[2] - r0[2]) * u[2]
    for i in range(3):
        point[i] = r0[i] + along * u[i]
    _project_base(prim, point, point, normal)
    return line_dist2(point, r0, u)


@njit(**JIT)
def _near_start(prim, grow, pulls, ws):
    """Where the force line would touch the primitive if it passed ``grow`` (m) closer: its entry into
    the primitive grown by ``grow`` (or, where pulls are allowed, its exit, whichever lies nearer the
    line) brought back onto the surface, with the normal of the face it enters there. A line just
    outside a box face and nearly along it thus starts on the face it would enter, not on the face
    it grazes; a line past a sphere starts where it would dip in, not where it runs tangent.
    Fills the point (ws at WS_X) and normal (WS_NB); returns the point's squared distance from the
    line, or -1 when the line passes farther away."""
    kind, size, pos, mat = prim
    if kind == PLANE:
        return -1.0  # an infinite plane is crossed or parallel: nothing to grow into
    u, r0 = ws[WS_U:WS_U + 3], ws[WS_R0:WS_R0 + 3]
    o, d, s = ws[WS_O_LOC:WS_O_LOC + 3], ws[WS_D_LOC:WS_D_LOC + 3], ws[WS_S:WS_S + 2]
    grown, xl = ws[WS_GROWN:WS_GROWN + 4], ws[WS_X_LOC:WS_X_LOC + 3]
    point, normal = ws[WS_X:WS_X + 3], ws[WS_NB:WS_NB + 3]
    to_local(pos, mat, r0, o)
    dir_to_local(mat, u, d)
    for i in range(4):
        grown[i] = size[i]
    grown[0] += grow
    if kind != CAPSULE:  # a capsule grows by its radius only; the others along every semi-axis
        grown[1] += grow
        grown[2] += grow
    if crossings_local(kind, grown, o, d, s) < 2:
        return -1.0
    best = -1.0
    for j in range(2 if pulls else 1):
        x0, x1, x2 = o[0] + s[j] * d[0], o[1] + s[j] * d[1], o[2] + s[j] * d[2]
        p0, p1, p2 = project_s(kind, size, x0, x1, x2)
        if kind == BOX or kind == CYLINDER:  # noqa: SIM109 (numba): the grown face, unambiguous at an edge
            n0, n1, n2 = normal_local(kind, grown, x0, x1, x2)
        else:
            n0, n1, n2 = normal_local(kind, size, p0, p1, p2)
        xl[0], xl[1], xl[2] = to_base_s(pos, mat, p0, p1, p2)
        dist2 = line_dist2(xl, r0, u)
        if best < 0.0 or dist2 < best:
            best = dist2
            point[0], point[1], point[2] = xl[0], xl[1], xl[2]
            for i in range(3):
                normal[i] = mat[3 * i] * n0 + mat[3 * i + 1] * n1 + mat[3 * i + 2] * n2
    return best


# -- Gauss-Newton on one primitive's surface --------------------------------------------------------------
@njit(inline="always", **JIT)
def _project_base(prim, x, out_point, out_normal):
    """x brought onto the surface, with the normal there. For a point outside a box or a cylinder the
    normal points from the surface point to x: a point past an edge takes the face it overhangs, so
    Gauss-Newton can walk around an edge instead of sticking to the first face."""
    kind, size, pos, mat = prim
    l0, l1, l2 = to_local_s(pos, mat, x[0], x[1], x[2])
    p0, p1, p2 = project_s(kind, size, l0, l1, l2)
    n0, n1, n2 = normal_local(kind, size, p0, p1, p2)
    if kind == BOX or kind == CYLINDER:  # noqa: SIM109 (numba); the others' normals are radial already
        e0, e1, e2 = l0 - p0, l1 - p1, l2 - p2
        out2 = e0 * e0 + e1 * e1 + e2 * e2
        if out2 > 1e-24 and not inside_s(kind, size, l0, l1, l2, 0.0):  # outside by more than rounding
            k = math.sqrt(out2)
            n0, n1, n2 = e0 / k, e1 / k, e2 / k
    out_point[0], out_point[1], out_point[2] = to_base_s(pos, mat, p0, p1, p2)
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


@njit(inline="always", **JIT)
def _aw(W, c0, c1, c2):
    """A^T W (3x6, row-major) with A = [I; [c]x]: row a = W[a] + sum_i [c]x[i, a] W[3 + i]."""
    return (W[0, 0] + c2 * W[4, 0] - c1 * W[5, 0], W[0, 1] + c2 * W[4, 1] - c1 * W[5, 1],
            W[0, 2] + c2 * W[4, 2] - c1 * W[5, 2], W[0, 3] + c2 * W[4, 3] - c1 * W[5, 3],
            W[0, 4] + c2 * W[4, 4] - c1 * W[5, 4], W[0, 5] + c2 * W[4, 5] - c1 * W[5, 5],
            W[1, 0] - c2 * W[3, 0] + c0 * W[5, 0], W[1, 1] - c2 * W[3, 1] + c0 * W[5, 1],
            W[1, 2] - c2 * W[3, 2] + c0 * W[5, 2], W[1, 3] - c2 * W[3, 3] + c0 * W[5, 3],
            W[1, 4] - c2 * W[3, 4] + c0 * W[5, 4], W[1, 5] - c2 * W[3, 5] + c0 * W[5, 5],
            W[2, 0] + c1 * W[3, 0] - c0 * W[4, 0], W[2, 1] + c1 * W[3, 1] - c0 * W[4, 1],
            W[2, 2] + c1 * W[3, 2] - c0 * W[4, 2], W[2, 3] + c1 * W[3, 3] - c0 * W[4, 3],
            W[2, 4] + c1 * W[3, 4] - c0 * W[4, 4], W[2, 5] + c1 * W[3, 5] - c0 * W[4, 5])


@njit(inline="always", **JIT)
def _best_force(w, W, c, p, r, fac):
    """The force that best explains w for a contact at c (weighted least squares, closed form):
    h = (p, c x p) = A p with A = [I; [c]x], so p = (A^T W A)^-1 A^T W w. Fills p, the residual
    r = w - A p and ``fac`` (the moment columns of A^T W, 3x3 row-major, then the Cholesky factor
    of A^T W A, 6 entries: what Kaufman's Jacobian needs); returns chi2 (inf if singular).
    Unrolled: it runs at every trial point of every fit."""
    c0, c1, c2 = c[0], c[1], c[2]
    a00, a01, a02, a03, a04, a05, a10, a11, a12, a13, a14, a15, a20, a21, a22, a23, a24, a25 = _aw(W, c0, c1, c2)
    # M = AW A (symmetric): column b of A is e_b over column b of [c]x
    m00 = a00 + c2 * a04 - c1 * a05
    m10 = a10 + c2 * a14 - c1 * a15
    m20 = a20 + c2 * a24 - c1 * a25
    m11 = a11 - c2 * a13 + c0 * a15
    m21 = a21 - c2 * a23 + c0 * a25
    m22 = a22 + c1 * a23 - c0 * a24
    b0 = a00 * w[0] + a01 * w[1] + a02 * w[2] + a03 * w[3] + a04 * w[4] + a05 * w[5]
    b1 = a10 * w[0] + a11 * w[1] + a12 * w[2] + a13 * w[3] + a14 * w[4] + a15 * w[5]
    b2 = a20 * w[0] + a21 * w[1] + a22 * w[2] + a23 * w[3] + a24 * w[4] + a25 * w[5]
    if not m00 > 1e-300:
        return math.inf
    l00 = math.sqrt(m00)
    l10 = m10 / l00
    l20 = m20 / l00
    d = m11 - l10 * l10
    if not d > 1e-300:
        return math.inf
    l11 = math.sqrt(d)
    l21 = (m21 - l20 * l10) / l11
    d = m22 - l20 * l20 - l21 * l21
    if not d > 1e-300:
        return math.inf
    l22 = math.sqrt(d)
    fac[0], fac[1], fac[2] = a03, a04, a05
    fac[3], fac[4], fac[5] = a13, a14, a15
    fac[6], fac[7], fac[8] = a23, a24, a25
    fac[9], fac[10], fac[11], fac[12], fac[13], fac[14] = l00, l10, l20, l11, l21, l22
    p[0], p[1], p[2] = _chol3_solve(fac, b0, b1, b2)
    _residual(w, c, p, r)
    return _chi2(r, W)


@njit(inline="always", **JIT)
def _chol3_solve(fac, b0, b1, b2):
    """(L L^T)^-1 b with the 3x3 Cholesky factor L in fac[9:15] (l00, l10, l20, l11, l21, l22)."""
    l00, l10, l20, l11, l21, l22 = fac[9], fac[10], fac[11], fac[12], fac[13], fac[14]
    y0 = b0 / l00
    y1 = (b1 - l10 * y0) / l11
    y2 = (b2 - l20 * y0 - l21 * y1) / l22
    x2 = y2 / l22
    x1 = (y1 - l21 * x2) / l11
    x0 = (y0 - l10 * x1 - l20 * x2) / l00
    return x0, x1, x2


@njit(inline="always", **JIT)
def _fac_solve(fac, v0, v1, v2):
    """(A^T W A)^-1 (A^T W)[:, 3:6] v with the factors _best_force left in ``fac``."""
    b0 = fac[0] * v0 + fac[1] * v1 + fac[2] * v2
    b1 = fac[3] * v0 + fac[4] * v1 + fac[5] * v2
    b2 = fac[6] * v0 + fac[7] * v1 + fac[8] * v2
    return _chol3_solve(fac, b0, b1, b2)


@njit(**JIT)
def refine(prim, w, W, c0, p0, max_iter, fit, cov, ws, want_cov=True):
    """Weighted least squares on one primitive's surface: minimise (w - h)^T W (w - h) with
    h = (p, c x p), c on the surface. The force is linear given the point, so it is solved in closed
    form at every point (variable projection) and Gauss-Newton runs on the point alone: steps in the
    tangent plane with Kaufman's Jacobian, retraction by projection onto the surface, backtracking.
    A stale force cannot pull a step astray (onto a box edge, where it would stall).
    Returns (chi2, iterations, converged, condition estimate of the full J^T W J); fills ``fit`` =
    (c, p, n: the point, the force, the normal at c) and (``want_cov``) cov (5x5: tangent coordinates
    t1, t2 at c, then p) = (J^T W J)^-1. ``p0`` is the fallback force should the closed form be
    singular. ``ws``: REFINE_WS floats of scratch."""
    c, p, n = fit
    r, fac = ws[RW_R:RW_R + 6], ws[RW_FAC:RW_FAC + 15]
    basis = (ws[RW_T1:RW_T1 + 3], ws[RW_T2:RW_T2 + 3])
    jac = (ws[RW_J:RW_J + 12].reshape((6, 2)), ws[RW_WJ:RW_WJ + 12].reshape((6, 2)))
    trial = (ws[RW_TRIAL_C:RW_TRIAL_C + 3], ws[RW_TRIAL_P:RW_TRIAL_P + 3], ws[RW_TRIAL_N:RW_TRIAL_N + 3],
             ws[RW_TRIAL_R:RW_TRIAL_R + 6], ws[RW_TFAC:RW_TFAC + 15])
    _project_base(prim, c0, c, n)
    chi2 = _best_force(w, W, c, p, r, fac)
    if chi2 == math.inf:
        for i in range(3):
            p[i] = p0[i]
        _residual(w, c, p, r)
        return _chi2(r, W), 0, False, math.inf
    converged = False
    it = 0
    while it < max_iter:
        it += 1
        ok, s0, s1 = _gauss_newton_step(W, c, p, n, r, fac, basis, jac)
        if not ok:  # singular: the force is too small to locate anything
            break
        lam, chi2_new = _backtrack(prim, w, W, c, s0, s1, chi2, basis, trial)
        if lam == 0.0:
            converged = True  # no descent left at rounding level
            break
        step_len = lam * math.sqrt(s0 * s0 + s1 * s1)
        _take_trial(trial, fit, r, fac)
        old = chi2
        chi2 = chi2_new
        if step_len <= 1e-7 * (1.0 + math.sqrt(dot3(c, c))) or old - chi2 <= 1e-14 * (1.0 + old):
            converged = True
            break
    cond = _fit_cov(w, W, c, p, n, cov, ws) if want_cov else math.inf
    return chi2, it, converged, cond


@njit(inline="always", **JIT)
def _gauss_newton_step(W, c, p, n, r, fac, basis, jac):
    """The Gauss-Newton step (s0, s1) in the tangent basis at c (left in ``basis``) with Kaufman's
    Jacobian J_k = -P (0, t_k x p), P = I - A (A^T W A)^-1 A^T W projecting out what a change of force
    absorbs; ``jac``: scratch for J and W J (6x2 each). (False, 0, 0) when the normal equations are
    singular."""
    t1, t2 = basis
    J, WJ = jac
    tangent_basis(n, t1, t2)
    for k in range(2):
        tk = t1 if k == 0 else t2
        v0 = tk[1] * p[2] - tk[2] * p[1]
        v1 = tk[2] * p[0] - tk[0] * p[2]
        v2 = tk[0] * p[1] - tk[1] * p[0]
        x0, x1, x2 = _fac_solve(fac, v0, v1, v2)
        J[0, k] = x0
        J[1, k] = x1
        J[2, k] = x2
        J[3, k] = c[1] * x2 - c[2] * x1 - v0
        J[4, k] = c[2] * x0 - c[0] * x2 - v1
        J[5, k] = c[0] * x1 - c[1] * x0 - v2
    for i in range(6):
        WJ[i, 0] = 0.0
        WJ[i, 1] = 0.0
        for j in range(6):
            WJ[i, 0] += W[i, j] * J[j, 0]
            WJ[i, 1] += W[i, j] * J[j, 1]
    h00 = h01 = h11 = g0 = g1 = 0.0
    for i in range(6):
        h00 += J[i, 0] * WJ[i, 0]
        h01 += J[i, 0] * WJ[i, 1]
        h11 += J[i, 1] * WJ[i, 1]
        g0 += WJ[i, 0] * r[i]
        g1 += WJ[i, 1] * r[i]
    det = h00 * h11 - h01 * h01
    if not det > 1e-14 * (h00 * h11 + 1e-300):
        return False, 0.0, 0.0
    return True, -(h11 * g0 - h01 * g1) / det, -(h00 * g1 - h01 * g0) / det


@njit(inline="always", **JIT)
def _backtrack(prim, w, W, c, s0, s1, chi2, basis, trial):
    """The step (s0, s1) in ``basis`` from c, halved until chi2 does not grow (8 tries): its fit is left
    in ``trial`` (point, force, normal, residual, factors). Returns (the step's fraction, 0 when none
    descends; its chi2)."""
    t1, t2 = basis
    trial_c, trial_p, trial_n, trial_r, tfac = trial
    lam = 1.0
    for _ in range(8):
        for i in range(3):
            trial_c[i] = c[i] + lam * (s0 * t1[i] + s1 * t2[i])
        _project_base(prim, trial_c, trial_c, trial_n)
        chi2_new = _best_force(w, W, trial_c, trial_p, trial_r, tfac)
        if chi2_new <= chi2 * (1.0 + 1e-12) + 1e-300:
            return lam, chi2_new
        lam *= 0.5
    return 0.0, chi2


@njit(inline="always", **JIT)
def _take_trial(trial, fit, r, fac):
    """The trial step's fit becomes the current one."""
    c, p, n = fit
    trial_c, trial_p, trial_n, trial_r, tfac = trial
    for i in range(3):
        c[i] = trial_c[i]
        p[i] = trial_p[i]
        n[i] = trial_n[i]
    for i in range(6):
        r[i] = trial_r[i]
    for i in range(15):
        fac[i] = tfac[i]


@njit(**JIT)
def _fit_cov(w, W, c, p, n, cov, ws):
    """cov = (J^T W J)^-1 at the fit (c, p) with normal n (5x5: tangent coordinates, then p); returns a
    cheap lower bound of the condition number (inf, with infinite variances, when singular)."""
    t1, t2 = ws[FC_T1:FC_T1 + 3], ws[FC_T2:FC_T2 + 3]
    J, WJ = ws[FC_J:FC_J + 30].reshape((6, 5)), ws[FC_WJ:FC_WJ + 30].reshape((6, 5))
    H, Lc = ws[FC_H:FC_H + 25].reshape((5, 5)), ws[FC_L:FC_L + 25].reshape((5, 5))
    g, r = ws[FC_G:FC_G + 5], ws[FC_R:FC_R + 6]
    e, col = ws[FC_E:FC_E + 5], ws[FC_COL:FC_COL + 5]
    _residual(w, c, p, r)
    tangent_basis(n, t1, t2)
    _jacobian(c, p, t1, t2, J)
    _normal_matrix(J, W, r, H, g, WJ)
    if not _cholesky(H, Lc):
        for a in range(5):
            for b in range(5):
                cov[a, b] = np.inf if a == b else 0.0
        return math.inf
    lo, hi = math.inf, 0.0
    for b in range(5):
        lo = min(lo, Lc[b, b])
        hi = max(hi, Lc[b, b])
    _chol_inverse(Lc, e, col, cov)
    return (hi / lo) ** 2  # from the Cholesky pivots: a cheap lower bound of the condition number


# -- the whole frame ----------------------------------------------------------------------------------------
@njit(**JIT)
def solve_frame(w, WS, prims, joints, torques, cfg, out, cands, ws, raw_prim):
    """One frame: external contact wrench w = (p, c x p) about the base origin, base frame. WS stacks
    W, the inverse covariance of w (6 rows), over its covariance S (6 rows).

    ``out`` receives point, force, normal, the scalars (flags, best index, candidate count, chi2,
    residual = moment along the force line (N m), cos of incidence, condition number, iterations)
    and the 6x6 covariance of (point, force). Candidates are sorted best first, their score is the
    log-likelihood (higher is better). Returns the number of candidates.

    Joint torques: ``tau_ext``/``tau_var`` per scene joint; model joint j (``link_joint``'s columns)
    belongs to scene joint ``jnt_i[j, 0]`` (-1: none) at ratio ``jnt_ratio[j]`` and has MuJoCo joint
    type ``jnt_i[j, 1]`` (hinge: torque about its axis; slide: force along it).
    ``ws`` (workspace_size(max_cand) floats) and ``raw_prim`` (max_cand ints) are the caller's
    scratch: numba allocates arrays on the heap, so a frame allocates nothing itself.
    """
    flags, fn = _force_line(w, cfg, out, ws)
    if fn == 0.0:
        return 0  # invalid, or no force: the flags say which
    raw_point, normal, iters, conv, cov = _cand_views(ws, raw_prim.shape[0])
    raw = (raw_prim, raw_point)  # the candidates before their fit: primitive, point
    fitted = (cands[0], cands[1], normal, iters, conv)  # and after it: cand_prim, cand_f and the rest
    miss_tol = cfg[CFG_MISS_TOL] / fn  # the line position's uncertainty (m)
    n_crossed = _crossing_candidates(prims, cfg[CFG_HIDE_TOL], ws, raw)
    n_raw = n_crossed
    if miss_tol > 0.0:
        n_raw = _near_miss_candidates(WS[6:12], fn, prims, cfg, n_crossed, ws, raw)
    near_from = n_crossed  # candidates from here on are near misses
    if n_raw == 0:
        # the line misses (noise, or not a contact on the arm): start from the surface point
        # nearest the line on the closest touchable primitive; kept wherever it lands (off_line)
        flags |= F_OFF_LINE
        if _nearest_surface_candidate(prims, ws, raw):
            n_raw = near_from = 1
    n = _fit_candidates(w, WS[0:6], prims, joints, torques, cfg, miss_tol, n_raw, near_from, raw, fitted, cov, ws)
    if n == 0:
        out[O_SCALARS + S_FLAGS] = flags | F_NO_CANDIDATE
        return 0
    _sort_candidates(n, fitted)
    _report_best(w, WS[0:6], cfg, flags, n, fitted, cov, out, ws)
    return n


@njit(**JIT)
def _force_line(w, cfg, out, ws):
    """Clears the scalars, puts the force line (direction, point nearest the origin) in ws and its
    residual in out. Returns (flags, |f|); |f| = 0 when there is nothing to solve (invalid input or
    no force; the flags are in out)."""
    sc = out[O_SCALARS:O_SCALARS + 8]
    for i in range(8):
        sc[i] = 0.0
    sc[S_BEST] = -1.0
    for i in range(6):
        if not math.isfinite(w[i]):
            sc[S_FLAGS] = F_INVALID
            return 0, 0.0
    f = w[0:3]
    m = w[3:6]
    fn = math.sqrt(dot3(f, f))
    if fn == 0.0:
        sc[S_FLAGS] = F_LOW_FORCE | F_NO_CANDIDATE
        return 0, 0.0
    flags = F_LOW_FORCE if fn < cfg[CFG_LOW_FORCE] else 0
    u = ws[WS_U:WS_U + 3]
    for i in range(3):
        u[i] = f[i] / fn
    r0 = ws[WS_R0:WS_R0 + 3]
    cross3(f, m, r0)
    for i in range(3):
        r0[i] /= fn * fn
    sc[S_RESIDUAL] = dot3(m, u)
    return flags, fn


@njit(**JIT)
def _crossing_candidates(prims, hide_tol, ws, raw):
    """The force line's admissible crossings of the touchable primitives: pushing (or where the link
    allows pulls), on the arm's outline, one per seam point. Fills raw_prim and the raw points;
    returns their count."""
    prim_i, sizes, gpos, gmat = prims
    raw_prim, raw_point = raw
    u, r0 = _line(ws)
    o_loc, d_loc, s = ws[WS_O_LOC:WS_O_LOC + 3], ws[WS_D_LOC:WS_D_LOC + 3], ws[WS_S:WS_S + 2]
    x_loc, n_loc = ws[WS_X_LOC:WS_X_LOC + 3], ws[WS_N_LOC:WS_N_LOC + 3]
    x, nb = ws[WS_X:WS_X + 3], ws[WS_NB:WS_NB + 3]
    n_raw = 0
    for g in range(prim_i.shape[0]):
        if not prim_i[g, PI_TOUCH]:
            continue
        # the line's distance to the primitive's centre against its bounding radius
        if line_dist2(gpos[g], r0, u) > sizes[g, 3] ** 2:
            continue
        kind = prim_i[g, PI_KIND]
        to_local(gpos[g], gmat[g], r0, o_loc)
        dir_to_local(gmat[g], u, d_loc)
        for j in range(crossings_local(kind, sizes[g], o_loc, d_loc, s)):
            for i in range(3):
                x_loc[i] = o_loc[i] + s[j] * d_loc[i]
            surface_normal_local(kind, sizes[g], x_loc, n_loc)
            to_base(gpos[g], gmat[g], x_loc, x)
            dir_to_base(gmat[g], n_loc, nb)
            if dot3(u, nb) > 0.0 and not prim_i[g, PI_PULLS]:
                continue
            if _hidden(x, nb, g, prims, hide_tol) or _seam_twin(x, g, prim_i, raw_prim, raw_point, n_raw):
                continue
            if n_raw < raw_prim.shape[0]:
                raw_prim[n_raw] = g
                for i in range(3):
                    raw_point[n_raw, i] = x[i]
                n_raw += 1
    return n_raw


@njit(inline="always", **JIT)
def _seam_twin(x, g, prim_i, raw_prim, raw_point, n_raw):
    """x is a seam point another primitive of g's link already reported."""
    dup = False
    for kk in range(n_raw):
        if prim_i[raw_prim[kk], PI_LINK] == prim_i[g, PI_LINK]:
            d2 = 0.0
            for i in range(3):
                d2 += (raw_point[kk, i] - x[i]) ** 2
            if d2 <= (1e-9 * (1.0 + math.sqrt(dot3(x, x)))) ** 2:
                dup = True
    return dup


@njit(**JIT)
def _near_miss_candidates(S, fn, prims, cfg, n_crossed, ws, raw):
    """Near misses within the line's own uncertainty are candidates too: noise can push the line off
    the touched link. One per link that has no crossing, the closest; the fit decides. No hidden test
    here: a touch next to a seam moves behind it when noise shifts the line, so the fit decides, and a
    fit deep inside another part is dropped after it (_off_outline). Returns the candidate count."""
    prim_i = prims[0]
    raw_prim, raw_point = raw
    u, r0 = _line(ws)
    x, nb = ws[WS_X:WS_X + 3], ws[WS_NB:WS_NB + 3]
    n_raw = n_crossed
    for g in range(prim_i.shape[0]):
        if not prim_i[g, PI_TOUCH] or _link_crossed(g, prim_i, raw_prim, n_crossed):
            continue
        tol = _miss_tolerance(S, fn, g, prims, cfg, ws)
        if tol < 0.0:
            continue
        miss2 = _near_start(_prim(prims, g), tol, prim_i[g, PI_PULLS] != 0, ws)
        if miss2 < 0.0 or abs(dot3(u, nb)) < cfg[CFG_GRAZING_COS]:
            continue  # too far, or grazing: no evidence of a touch there
        slot = -1
        for kk in range(n_crossed, n_raw):  # one per link: keep the closest
            if prim_i[raw_prim[kk], PI_LINK] == prim_i[g, PI_LINK]:
                slot = kk
        if slot >= 0:
            if line_dist2(raw_point[slot], r0, u) <= miss2:
                continue
        elif n_raw < raw_prim.shape[0]:
            slot = n_raw
            n_raw += 1
        else:
            continue
        raw_prim[slot] = g
        for i in range(3):
            raw_point[slot, i] = x[i]
    return n_raw


@njit(inline="always", **JIT)
def _link_crossed(g, prim_i, raw_prim, n_crossed):
    crossed = False
    for kk in range(n_crossed):
        if prim_i[raw_prim[kk], PI_LINK] == prim_i[g, PI_LINK]:
            crossed = True
    return crossed


@njit(inline="always", **JIT)
def _miss_tolerance(S, fn, g, prims, cfg, ws):
    """How far (m) the force line may pass from primitive g and still be a candidate: the bound
    (miss_t + miss_f d) / |f| of its position's uncertainty at distance d from the origin, or, tighter,
    miss_sigma of the line's own standard deviations where it passes the primitive (plus how much
    that can grow across it). -1 when the line passes farther away."""
    prim_i, sizes, gpos, gmat = prims
    u, r0, tmp = ws[WS_U:WS_U + 3], ws[WS_R0:WS_R0 + 3], ws[WS_TMP:WS_TMP + 3]
    miss_f = cfg[CFG_MISS_F]
    tol = (cfg[CFG_MISS_T] + miss_f * (math.sqrt(dot3(gpos[g], gpos[g])) + sizes[g, 3])) / fn
    b = sizes[g, 3] + tol
    if line_dist2(gpos[g], r0, u) > b * b:
        return -1.0
    along = (gpos[g, 0] - r0[0]) * u[0] + (gpos[g, 1] - r0[1]) * u[1] + (gpos[g, 2] - r0[2]) * u[2]
    for i in range(3):
        tmp[i] = r0[i] + along * u[i]
    sigma = _line_sigma(S, tmp, u, fn, ws[WS_T1:WS_T1 + 3], ws[WS_T2:WS_T2 + 3])
    tol = min(tol, cfg[CFG_MISS_SIGMA] * sigma + miss_f * sizes[g, 3] / fn)
    b = sizes[g, 3] + tol
    if line_dist2(gpos[g], r0, u) > b * b:
        return -1.0
    return tol


@njit(**JIT)
def _nearest_surface_candidate(prims, ws, raw):
    """The surface point nearest the force line on the closest touchable primitive (_surface_near_line)
    as the only candidate; False when there is no touchable primitive."""
    prim_i = prims[0]
    raw_prim, raw_point = raw
    u, r0 = _line(ws)
    point, normal = ws[WS_NB:WS_NB + 3], ws[WS_N_LOC:WS_N_LOC + 3]
    best = 1e300
    for g in range(prim_i.shape[0]):
        if not prim_i[g, PI_TOUCH]:
            continue
        dist2 = _surface_near_line(_prim(prims, g), r0, u, point, normal)
        if dist2 < best:
            best = dist2
            raw_prim[0] = g
            for i in range(3):
                raw_point[0, i] = point[i]
    return best < 1e300


@njit(**JIT)
def _fit_candidates(w, W, prims, joints, torques, cfg, miss_tol, n_raw, near_from, raw, cands, cov, ws):
    """Fits every raw candidate on its surface (refine; across a box's faces after a poor fit from a near
    miss), drops near misses whose fit leaves the arm's outline, scores the rest (log-likelihood, with
    the joint torques when given). Fills the candidates; returns their count."""
    prim_i = prims[0]
    raw_prim, raw_point = raw
    cand_prim, cand_f, cand_normal, cand_iter, cand_conv = cands
    max_iter = int(cfg[CFG_MAX_ITER])
    f = w[0:3]
    u, r0 = _line(ws)
    fit = (ws[WS_C:WS_C + 3], ws[WS_P:WS_P + 3], ws[WS_NRM:WS_NRM + 3])
    c, p, nrm = fit
    tmp, rws = ws[WS_TMP:WS_TMP + 3], ws[WS_REFINE:WS_REFINE + REFINE_WS]
    n_keep = 0
    for k in range(n_raw):
        g = raw_prim[k]
        prim = _prim(prims, g)
        chi2, iters, conv, _ = refine(prim, w, W, raw_point[k], f, max_iter, fit, cov, rws, False)
        if k >= near_from and prim[0] == BOX and chi2 > POOR_FIT_CHI2:
            chi2, conv = _refine_box_faces(prim, w, W, f, max_iter, prim_i[g, PI_PULLS] != 0, chi2, conv, fit, cov, ws)
        if k >= near_from and _off_outline(c, nrm, g, prims, miss_tol, cfg[CFG_HIDE_TOL]):
            continue  # a near miss whose best fit lies deep inside another part, or on a face glued to one
        logl = -0.5 * chi2
        if torques[2]:
            logl = _torque_loglik(logl, prim_i[g, PI_LINK], c, p, joints, torques, ws)
        # a faint preference for the first crossing along the force (the most exposed point):
        # it only orders candidates the data cannot tell apart
        for i in range(3):
            tmp[i] = c[i] - r0[i]
        logl -= 1e-12 * dot3(tmp, u)
        cand_prim[n_keep] = g
        cand_f[n_keep, C_SCORE] = logl
        cand_f[n_keep, C_CHI2] = chi2
        cand_iter[n_keep] = iters
        cand_conv[n_keep] = 1.0 if conv else 0.0
        for i in range(3):
            cand_f[n_keep, C_POINT + i] = c[i]
            cand_f[n_keep, C_FORCE + i] = p[i]
            cand_normal[n_keep, i] = nrm[i]
        n_keep += 1
    return n_keep


@njit(inline="always", **JIT)
def _torque_loglik(logl, link, c, p, joints, torques, ws):
    """logl less each scene joint's torque mismatch: the contact (c, p) on ``link`` predicts J^T p."""
    joint_axis, joint_anchor, link_joint, jnt_i, jnt_ratio = joints
    tau_ext, tau_var = torques[0], torques[1]
    tmp, x = ws[WS_TMP:WS_TMP + 3], ws[WS_X:WS_X + 3]
    for s in range(tau_var.shape[0]):
        pred = 0.0
        for j in range(jnt_i.shape[0]):
            if jnt_i[j, 0] != s or not link_joint[link, j]:
                continue
            if jnt_i[j, 1] == JNT_SLIDE:
                pred += jnt_ratio[j] * dot3(joint_axis[j], p)
            else:
                for i in range(3):
                    tmp[i] = c[i] - joint_anchor[j, i]
                cross3(tmp, p, x)
                pred += jnt_ratio[j] * dot3(joint_axis[j], x)
        e = tau_ext[s] - pred
        logl -= 0.5 * e * e / tau_var[s]
    return logl


@njit(**JIT)
def _refine_box_faces(prim, w, W, f, max_iter, pulls, chi2, conv, fit, cov, ws):
    """A near miss on a box: the fit from the grown box's entry can stop at that face's edge while
    the best fit lies across the face (dxl-arm's finger tips at 1-2 N: chi-square 9-21 where a fit
    of about 1 exists 20 mm away, so the other finger won unflagged). Fits again from where the line
    meets the plane of each face the force enters (clamped into the face) and keeps the best; only
    after a poor first fit (chi2 > POOR_FIT_CHI2), so a good one costs nothing more.
    Returns its (chi2, converged); ``fit`` holds it."""
    _, size, pos, mat = prim
    o, d = ws[WS_O_LOC:WS_O_LOC + 3], ws[WS_D_LOC:WS_D_LOC + 3]
    xl, start = ws[WS_X_LOC:WS_X_LOC + 3], ws[WS_X:WS_X + 3]
    face_fit = (ws[WS_C2:WS_C2 + 3], ws[WS_P2:WS_P2 + 3], ws[WS_N2:WS_N2 + 3])
    to_local(pos, mat, ws[WS_R0:WS_R0 + 3], o)
    dir_to_local(mat, ws[WS_U:WS_U + 3], d)
    for a in range(3):
        if d[a] == 0.0:
            continue
        for sgn in (-1.0, 1.0):
            if d[a] * sgn >= 0.0 and not pulls:
                continue  # the force leaves the box through this face
            t = (sgn * size[a] - o[a]) / d[a]
            for i in range(3):
                xl[i] = min(max(o[i] + t * d[i], -size[i]), size[i])
            xl[a] = sgn * size[a]
            to_base(pos, mat, xl, start)
            chi2b, _, convb, _ = refine(prim, w, W, start, f, max_iter, face_fit, cov,
                                        ws[WS_REFINE:WS_REFINE + REFINE_WS], False)
            if chi2b < chi2:
                chi2 = chi2b
                conv = convb
                for j in range(3):
                    for i in range(3):
                        fit[j][i] = face_fit[j][i]
    return chi2, conv


@njit(**JIT)
def _sort_candidates(n, cands):
    """Candidates by score, best first, in place (a stable insertion sort: a handful of entries, and
    nothing allocated)."""
    cand_prim, cand_f, cand_normal, cand_iter, cand_conv = cands
    for k in range(1, n):
        j = k
        while j > 0 and cand_f[j - 1, C_SCORE] < cand_f[j, C_SCORE]:
            cand_prim[j - 1], cand_prim[j] = cand_prim[j], cand_prim[j - 1]
            for i in range(cand_f.shape[1]):
                cand_f[j - 1, i], cand_f[j, i] = cand_f[j, i], cand_f[j - 1, i]
            for i in range(3):
                cand_normal[j - 1, i], cand_normal[j, i] = cand_normal[j, i], cand_normal[j - 1, i]
            cand_iter[j - 1], cand_iter[j] = cand_iter[j], cand_iter[j - 1]
            cand_conv[j - 1], cand_conv[j] = cand_conv[j], cand_conv[j - 1]
            j -= 1


@njit(**JIT)
def _report_best(w, W, cfg, flags, n, cands, cov, out, ws):
    """The best candidate (the first) into ``out``, with its flags and covariance (``cov``: scratch)."""
    _, cand_f, cand_normal, cand_iter, cand_conv = cands
    out_point, out_force = out[O_POINT:O_POINT + 3], out[O_FORCE:O_FORCE + 3]
    out_normal, sc = out[O_NORMAL:O_NORMAL + 3], out[O_SCALARS:O_SCALARS + 8]
    best = 0
    if n > 1 and cand_f[0, C_SCORE] - cand_f[1, C_SCORE] < cfg[CFG_AMBIGUITY]:
        flags |= F_AMBIGUOUS
    chi2 = cand_f[best, C_CHI2]
    if chi2 > cfg[CFG_OFF_CHI2]:
        flags |= F_OFF_SURFACE
    if cand_conv[best] == 0.0:
        flags |= F_NOT_CONVERGED
    for i in range(3):
        out_point[i] = cand_f[best, C_POINT + i]
        out_force[i] = cand_f[best, C_FORCE + i]
        out_normal[i] = cand_normal[best, i]
    pn = math.sqrt(dot3(out_force, out_force))
    cosi = dot3(out_force, out_normal) / pn if pn > 0 else 0.0
    if cosi > 0.0:
        flags |= F_PULL
    if abs(cosi) < cfg[CFG_GRAZING_COS]:
        flags |= F_GRAZING
    sc[S_COND] = _fit_cov(w, W, out_point, out_force, out_normal, cov, ws[WS_REFINE:WS_REFINE + REFINE_WS])
    _base_cov(cov, out_normal, out[O_COV:O_COV + 36].reshape((6, 6)), ws)
    sc[S_FLAGS] = flags
    sc[S_BEST] = best
    sc[S_NCAND] = n
    sc[S_CHI2] = chi2
    sc[S_COS] = cosi
    sc[S_ITER] = cand_iter[best]


@njit(inline="always", **JIT)
def _base_cov(cov, normal, out_cov, ws):
    """The fit's covariance (tangent coordinates, force) as the 6x6 covariance of (point, force) in the
    base frame: point (3x3, rank 2) from the tangent block."""
    t1, t2 = ws[WS_T1:WS_T1 + 3], ws[WS_T2:WS_T2 + 3]
    T = ws[WS_T:WS_T + 6].reshape((3, 2))
    tangent_basis(normal, t1, t2)
    for i in range(3):
        T[i, 0] = t1[i]
        T[i, 1] = t2[i]
    _congruence(T, cov[0:2, 0:2], out_cov[0:3, 0:3])
    for a in range(3):
        for b in range(3):
            out_cov[3 + a, 3 + b] = cov[2 + a, 2 + b]
            acc = 0.0
            for i in range(2):
                acc += T[a, i] * cov[i, 2 + b]
            out_cov[a, 3 + b] = acc
            out_cov[3 + b, a] = acc


# -- forward kinematics of the geoms (batch path) ---------------------------------------------------------
@njit(**JIT)
def tree_kinematics(q, tree_i, tree_f, geom_i, geom_f, xpos, xquat, gpos, gmat, janchor, jaxis):
    """MuJoCo's forward kinematics for trees of hinge/slide joints (one joint per body at most),
    from the compiled MjModel arrays; checked against mj_kinematics in the tests.

    tree_i columns: parent, joint (-1 none), joint type, joint qpos address;
    tree_f columns: body pos (3), body quat (4), joint axis (3), joint pos (3) (joint of that body).
    geom_i: body; geom_f: geom pos (3), geom quat (4).
    Scalar temporaries only: it runs once per frame of the batch path and allocates nothing.
    """
    xpos[0, 0], xpos[0, 1], xpos[0, 2] = 0.0, 0.0, 0.0
    xquat[0, 0], xquat[0, 1], xquat[0, 2], xquat[0, 3] = 1.0, 0.0, 0.0, 0.0
    for b in range(1, tree_i.shape[0]):
        par = tree_i[b, 0]
        pw, px, py, pz = xquat[par, 0], xquat[par, 1], xquat[par, 2], xquat[par, 3]
        v0, v1, v2 = _quat_rotate(pw, px, py, pz, tree_f[b, 0], tree_f[b, 1], tree_f[b, 2])
        x0, x1, x2 = xpos[par, 0] + v0, xpos[par, 1] + v1, xpos[par, 2] + v2
        qw, qx, qy, qz = _quat_mul_s(pw, px, py, pz, tree_f[b, 3], tree_f[b, 4], tree_f[b, 5], tree_f[b, 6])
        j = tree_i[b, 1]
        if j >= 0:
            x0, x1, x2, qw, qx, qy, qz = _joint_motion(q, tree_i[b], tree_f[b], x0, x1, x2, qw, qx, qy, qz,
                                                       janchor[j], jaxis[j])
        xpos[b, 0], xpos[b, 1], xpos[b, 2] = x0, x1, x2
        xquat[b, 0], xquat[b, 1], xquat[b, 2], xquat[b, 3] = qw, qx, qy, qz
    for g in range(geom_i.shape[0]):
        b = geom_i[g, 0]
        bw, bx, by, bz = xquat[b, 0], xquat[b, 1], xquat[b, 2], xquat[b, 3]
        v0, v1, v2 = _quat_rotate(bw, bx, by, bz, geom_f[g, 0], geom_f[g, 1], geom_f[g, 2])
        gpos[g, 0], gpos[g, 1], gpos[g, 2] = xpos[b, 0] + v0, xpos[b, 1] + v1, xpos[b, 2] + v2
        qw, qx, qy, qz = _quat_mul_s(bw, bx, by, bz, geom_f[g, 3], geom_f[g, 4], geom_f[g, 5], geom_f[g, 6])
        _quat_mat_s(qw, qx, qy, qz, gmat[g])


@njit(inline="always", **JIT)
def _joint_motion(q, body_i, body_f, x0, x1, x2, qw, qx, qy, qz, anchor, axis):
    """A body's pose (position, quaternion) moved by its joint at q, from its pose at q = 0; fills
    the joint's anchor and axis (base frame)."""
    jp0, jp1, jp2 = body_f[10], body_f[11], body_f[12]
    a0, a1, a2 = body_f[7], body_f[8], body_f[9]
    v0, v1, v2 = _quat_rotate(qw, qx, qy, qz, jp0, jp1, jp2)
    an0, an1, an2 = x0 + v0, x1 + v1, x2 + v2
    ax0, ax1, ax2 = _quat_rotate(qw, qx, qy, qz, a0, a1, a2)
    anchor[0], anchor[1], anchor[2] = an0, an1, an2
    axis[0], axis[1], axis[2] = ax0, ax1, ax2
    angle = q[body_i[3]]
    if body_i[2] == JNT_HINGE:  # rotate about the axis through the anchor
        half = 0.5 * angle
        sh = math.sin(half)
        qw, qx, qy, qz = _quat_mul_s(qw, qx, qy, qz, math.cos(half), a0 * sh, a1 * sh, a2 * sh)
        nq = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        qw, qx, qy, qz = qw / nq, qx / nq, qy / nq, qz / nq
        v0, v1, v2 = _quat_rotate(qw, qx, qy, qz, jp0, jp1, jp2)
        return an0 - v0, an1 - v1, an2 - v2, qw, qx, qy, qz
    return x0 + ax0 * angle, x1 + ax1 * angle, x2 + ax2 * angle, qw, qx, qy, qz  # slide


@njit(inline="always", **JIT)
def _quat_mul_s(aw, ax, ay, az, bw, bx, by, bz):
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


@njit(inline="always", **JIT)
def _quat_mat_s(w, x, y, z, m):
    m[0] = 1 - 2 * (y * y + z * z)
    m[1] = 2 * (x * y - w * z)
    m[2] = 2 * (x * z + w * y)
    m[3] = 2 * (x * y + w * z)
    m[4] = 1 - 2 * (x * x + z * z)
    m[5] = 2 * (y * z - w * x)
    m[6] = 2 * (x * z - w * y)
    m[7] = 2 * (y * z + w * x)
    m[8] = 1 - 2 * (x * x + y * y)


@njit(inline="always", **JIT)
def _quat_rotate(w, x, y, z, v0, v1, v2):
    """The unit quaternion's rotation matrix times v."""
    m0, m1, m2 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    m3, m4, m5 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    m6, m7, m8 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return m0 * v0 + m1 * v1 + m2 * v2, m3 * v0 + m4 * v1 + m5 * v2, m6 * v0 + m7 * v1 + m8 * v2


# -- entry points (called from Python: plain arrays, one per argument) -------------------------------------
@njit(**JIT)
def solve_frame_q(w, q, W, prim_i, sizes, link_joint, jnt_i, jnt_ratio, tau_ext, tau_var, use_tau, cfg, tree_i,
                  tree_f, geom_i, geom_f, out, cand_prim, cand_f, ws, raw_prim, xpos, xquat, gpos, gmat, janchor,
                  jaxis):
    """solve_frame at joint angles q (the model's qpos): the same kinematics as the batch path, so a
    frame gets bit-identical answers on either path."""
    tree_kinematics(q, tree_i, tree_f, geom_i, geom_f, xpos, xquat, gpos, gmat, janchor, jaxis)
    return solve_frame(w, W, (prim_i, sizes, gpos, gmat), (jaxis, janchor, link_joint, jnt_i, jnt_ratio),
                       (tau_ext, tau_var, use_tau), cfg, out, (cand_prim, cand_f), ws, raw_prim)


@njit(parallel=True, cache=True, nogil=True)
def solve_batch(wrenches, qs, Ws, prim_i, sizes, link_joint, jnt_i, jnt_ratio, tau_ext, tau_var, use_tau, cfg,
                tree_i, tree_f, geom_i, geom_f, max_cand, out, cand_prim, cand_f, n_cand):
    """solve_frame over N frames, each with its own joint angles; kinematics inside. Frames go in
    chunks over the threads, each chunk with its own scratch; the best cand_prim.shape[1] candidates
    of each frame are kept (n_cand counts them all)."""
    n = wrenches.shape[0]
    nb = tree_i.shape[0]
    ng = geom_i.shape[0]
    nj = link_joint.shape[1]
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
        prims, joints, cands = (prim_i, sizes, gpos, gmat), (jaxis, janchor, link_joint, jnt_i, jnt_ratio), (cp, cf)
        for i in range(ch * n // n_chunks, (ch + 1) * n // n_chunks):
            tree_kinematics(qs[i], tree_i, tree_f, geom_i, geom_f, xpos, xquat, gpos, gmat, janchor, jaxis)
            W = Ws[i] if Ws.shape[0] > 1 else Ws[0]
            k = solve_frame(wrenches[i], W, prims, joints, (tau_ext[i], tau_var, use_tau[i]), cfg, out[i], cands, ws,
                            raw_prim)
            n_cand[i] = k
            for j in range(min(k, keep)):
                cand_prim[i, j] = cp[j]
                for c in range(C_SIZE):
                    cand_f[i, j, c] = cf[j, c]


@njit(**JIT_ALLOC)
def weight_stack(a, sigma_sensor, out):
    """out[6:] = a sigma_sensor a^T (the wrench covariance in the base frame), out[:6] its inverse
    (the solver's weight; no LAPACK call for a 6x6). False when the covariance is not positive
    definite."""
    sigma = out[6:]
    _congruence(a, sigma_sensor, sigma)
    low = np.empty((6, 6))
    if not _cholesky(sigma, low):
        return False
    _chol_inverse(low, np.empty(6), np.empty(6), out[:6])
    return True


@njit(**JIT_ALLOC)
def frame_inputs(w, q, a, sigma_sensor, extra, use_extra, tau_ext, use_tau, tau_std, use_std, wmat, tau, tau_var):
    """A frame's inputs to ``solve_frame_q`` checked and laid out in one call (a dozen numpy calls
    before). False when w, q, ``extra`` (``use_extra``) or ``tau_ext`` (``use_tau``) hold NaN or Inf (a
    sum that is not finite, as ``ContactSolver.solve`` judged them) or when sigma_sensor + extra is
    not positive definite; nothing is written then. Else: with ``use_extra``, wmat = ``weight_stack``
    of sigma_sensor + extra; with ``use_tau``, tau = tau_ext and, with ``use_std``, tau_var = tau_std^2."""
    if not (math.isfinite(_sum(w)) and math.isfinite(_sum(q))):
        return False
    if use_extra:
        if not math.isfinite(_sum(extra.ravel())):
            return False
        sigma = np.empty((6, 6))
        for i in range(6):
            for j in range(6):
                sigma[i, j] = sigma_sensor[i, j] + extra[i, j]
        if not weight_stack(a, sigma, wmat):
            return False
    if use_tau:
        if not math.isfinite(_sum(tau_ext)):
            return False
        for j in range(tau.shape[0]):
            tau[j] = tau_ext[j]
        if use_std:
            for j in range(tau.shape[0]):
                tau_var[j] = tau_std[j] * tau_std[j]
    return True


@njit(**JIT)
def _sum(x):
    """The sum of a C-ordered array's entries, in order."""
    s = 0.0
    for v in x:
        s += v
    return s
