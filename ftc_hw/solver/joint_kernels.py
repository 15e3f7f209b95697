"""Compiled core of the joint-torque localizer: every candidate point's best force and its chi-square.

A point p of link L has the contact Jacobian ``J_p = Jv - [p - x]x Jw`` (Jv, Jw: the link origin x's
linear and angular Jacobians, 3 x n), so with W the residual's information matrix every quantity of the
weighted least squares is a 3 x 3 expression in ``d = p - x`` over per-link blocks computed once a frame:

    A(d) = J_p W J_p^T = Avv + Avw S - S Avw^T - S Aww S,   b(d) = J_p W r = bv - S bw,   S = [d]x

A wrench measured by a flange sensor (for a link beyond it) adds the same structure about the sensor's
origin. The force: ``argmin f^T (A + I/s_f^2) f - 2 b^T f`` (s_f the force prior), pushing into the
surface within the friction cone ``|f_t| <= mu f_n`` (Manuelli & Tedrake, IROS 2016, use a polyhedral
cone and a QP); when the unconstrained minimum lies outside, the minimum is on the cone's surface (or its
apex): the best force along each edge is closed-form, so the best of 16 edges and a parabola through it
and its neighbours find it.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _skew_apply(d, v, out):
    out[0] = d[1] * v[2] - d[2] * v[1]
    out[1] = d[2] * v[0] - d[0] * v[2]
    out[2] = d[0] * v[1] - d[1] * v[0]


@njit(cache=True, nogil=True)
def _assemble(blocks, bvec, d, a, b, s):
    """a += A(d), b += b(d) of one block set: blocks (3, 3, 3) = Avv, Avw, Aww; bvec (2, 3) = bv, bw
    (``s``: scratch 3 x 3)."""
    avv, avw, aww = blocks[0], blocks[1], blocks[2]
    d0, d1, d2 = d[0], d[1], d[2]
    # s = Aww [d]x (column j of [d]x is e_j x d ... written out: ([d]x)_kj)
    for i in range(3):
        w0, w1, w2 = aww[i, 0], aww[i, 1], aww[i, 2]
        s[i, 0] = w1 * d2 - w2 * d1
        s[i, 1] = w2 * d0 - w0 * d2
        s[i, 2] = w0 * d1 - w1 * d0
    for j in range(3):
        # column j of [d]x Aww [d]x = d x (column j of s); of Avw [d]x: as s; of [d]x Avw^T: d x (row j of Avw)
        c0, c1, c2 = s[0, j], s[1, j], s[2, j]
        x0, x1, x2 = d1 * c2 - d2 * c1, d2 * c0 - d0 * c2, d0 * c1 - d1 * c0
        v0, v1, v2 = avw[j, 0], avw[j, 1], avw[j, 2]
        y0, y1, y2 = d1 * v2 - d2 * v1, d2 * v0 - d0 * v2, d0 * v1 - d1 * v0
        for i in range(3):
            u0, u1, u2 = avw[i, 0], avw[i, 1], avw[i, 2]
            if j == 0:
                avw_s = u1 * d2 - u2 * d1
            elif j == 1:
                avw_s = u2 * d0 - u0 * d2
            else:
                avw_s = u0 * d1 - u1 * d0
            xi = x0 if i == 0 else (x1 if i == 1 else x2)
            yi = y0 if i == 0 else (y1 if i == 1 else y2)
            a[i, j] += avv[i, j] + avw_s - yi - xi
    bw0, bw1, bw2 = bvec[1, 0], bvec[1, 1], bvec[1, 2]
    b[0] += bvec[0, 0] - (d1 * bw2 - d2 * bw1)
    b[1] += bvec[0, 1] - (d2 * bw0 - d0 * bw2)
    b[2] += bvec[0, 2] - (d0 * bw1 - d1 * bw0)


@njit(cache=True, nogil=True)
def _solve3(a, b, out) -> bool:
    """out = a^-1 b for a positive definite 3 x 3 by its adjugate (False: not positive definite)."""
    i00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    i01 = a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]
    i02 = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]
    i10 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    i11 = a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]
    i12 = a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]
    i20 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    i21 = a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]
    i22 = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    det = a[0, 0] * i00 + a[0, 1] * i10 + a[0, 2] * i20
    if not (det > 0.0 and math.isfinite(det)):
        return False
    out[0] = (i00 * b[0] + i01 * b[1] + i02 * b[2]) / det
    out[1] = (i10 * b[0] + i11 * b[1] + i12 * b[2]) / det
    out[2] = (i20 * b[0] + i21 * b[1] + i22 * b[2]) / det
    return True


@njit(cache=True, nogil=True)
def _in_cone(f, nrm, mu) -> bool:
    fn = -(f[0] * nrm[0] + f[1] * nrm[1] + f[2] * nrm[2])
    if fn <= 0.0:
        return False
    t2 = 0.0
    for i in range(3):
        ti = f[i] + fn * nrm[i]
        t2 += ti * ti
    return t2 <= mu * mu * fn * fn


@njit(cache=True, nogil=True)
def _edge_fit(a, b, nrm, t1, t2, mu, c, s, f) -> float:
    """The best force along the cone's edge at angle (cos c, sin s), into f; its cost f^T a f - 2 b^T f."""
    e0 = -nrm[0] + mu * (c * t1[0] + s * t2[0])
    e1 = -nrm[1] + mu * (c * t1[1] + s * t2[1])
    e2 = -nrm[2] + mu * (c * t1[2] + s * t2[2])
    eae = (e0 * (a[0, 0] * e0 + a[0, 1] * e1 + a[0, 2] * e2) + e1 * (a[1, 0] * e0 + a[1, 1] * e1 + a[1, 2] * e2)
           + e2 * (a[2, 0] * e0 + a[2, 1] * e1 + a[2, 2] * e2))
    eb = e0 * b[0] + e1 * b[1] + e2 * b[2]
    k = eb / eae if eb > 0.0 and eae > 0.0 else 0.0
    f[0], f[1], f[2] = k * e0, k * e1, k * e2
    return -k * eb


@njit(cache=True, nogil=True)
def _cone_fit(a, b, nrm, mu, f, t1, t2, g, edges, costs):
    """argmin f^T a f - 2 b^T f over the friction cone about -nrm, when the unconstrained minimum lies
    outside it (the minimum is then on the cone's surface, or its apex): the best of the edges at the
    angles ``edges`` (k, 2: cos, sin), then the vertex of the parabola through it and its neighbours
    (``t1``, ``t2``, ``g``: scratch 3-vectors, ``costs``: scratch (k,))."""
    if abs(nrm[0]) < 0.9:
        t1[0], t1[1], t1[2] = 0.0, nrm[2], -nrm[1]
    else:
        t1[0], t1[1], t1[2] = -nrm[2], 0.0, nrm[0]
    nt = math.sqrt(t1[0] ** 2 + t1[1] ** 2 + t1[2] ** 2)
    for i in range(3):
        t1[i] /= nt
    _skew_apply(nrm, t1, t2)
    k_edges = edges.shape[0]
    best, kb = 0.0, -1
    for k in range(k_edges):
        costs[k] = _edge_fit(a, b, nrm, t1, t2, mu, edges[k, 0], edges[k, 1], g)
        if costs[k] < best:
            best, kb = costs[k], k
    if kb < 0:
        f[0] = f[1] = f[2] = 0.0  # the apex: no push explains anything
        return
    lo, hi = costs[(kb - 1) % k_edges], costs[(kb + 1) % k_edges]
    den = lo - 2.0 * best + hi
    shift = 0.5 * (lo - hi) / den if den > 0.0 else 0.0
    step = 2.0 * math.pi / k_edges
    th = math.atan2(edges[kb, 1], edges[kb, 0]) + shift * step
    cost = _edge_fit(a, b, nrm, t1, t2, mu, math.cos(th), math.sin(th), f)
    if cost > best:
        _edge_fit(a, b, nrm, t1, t2, mu, edges[kb, 0], edges[kb, 1], f)


def cone_edges(k: int = 16) -> np.ndarray:
    """(k, 2): cos and sin of k angles evenly around the cone."""
    th = 2.0 * np.pi * np.arange(k) / k
    return np.ascontiguousarray(np.stack([np.cos(th), np.sin(th)], axis=1))


@njit(cache=True, nogil=True)
def fit_candidates(loc, nrm_loc, link_of, poses, joint_blocks, joint_b, flange_blocks, flange_b, flange_on,
                   sensor_pos, const, ridge, mu, edges, idx, chi2, force, point, normal, info):
    """For the candidates ``idx`` (m,) of the tables ``loc``/``nrm_loc`` (N, 3, link frame) on links
    ``link_of`` (N,): point, outward normal (base frame), best force and chi-square into rows 0..m-1 of
    ``point``/``normal``/``force``/``chi2``, and the fit's 3 x 3 information into ``info`` (m, 3, 3).
    ``poses`` (L, 3, 4): each link's rotation and origin; ``joint_blocks`` (L, 3, 3, 3), ``joint_b``
    (L, 2, 3): the per-link blocks about the link origin; ``flange_*`` the same about ``sensor_pos`` for
    the links ``flange_on`` (L,) beyond a flange sensor; ``const``: r^T W r (+ the flange's w^T W w);
    ``edges``: the friction cone's edge angles (:func:`cone_edges`)."""
    a = np.empty((3, 3))
    b = np.empty(3)
    d = np.empty(3)
    f = np.empty(3)
    t1, t2, g = np.empty(3), np.empty(3), np.empty(3)
    sk = np.empty((3, 3))
    costs = np.empty(edges.shape[0])
    for m in range(idx.shape[0]):
        c = idx[m]
        li = link_of[c]
        for i in range(3):
            p = poses[li, i, 3]
            nv = 0.0
            for k in range(3):
                p += poses[li, i, k] * loc[c, k]
                nv += poses[li, i, k] * nrm_loc[c, k]
            point[m, i] = p
            normal[m, i] = nv
            d[i] = p - poses[li, i, 3]
        a[:] = 0.0
        b[:] = 0.0
        _assemble(joint_blocks[li], joint_b[li], d, a, b, sk)
        if flange_on[li]:
            for i in range(3):
                d[i] = point[m, i] - sensor_pos[i]
            _assemble(flange_blocks, flange_b, d, a, b, sk)
        for i in range(3):
            a[i, i] += ridge
        nrm = normal[m]
        if not _solve3(a, b, f) or not _in_cone(f, nrm, mu):
            _cone_fit(a, b, nrm, mu, f, t1, t2, g, edges, costs)
        q = const
        for i in range(3):
            q -= 2.0 * b[i] * f[i]
            for j in range(3):
                q += f[i] * a[i, j] * f[j]
        chi2[m] = q if q > 0.0 else 0.0
        for i in range(3):
            force[m, i] = f[i]
            for j in range(3):
                info[m, i, j] = a[i, j]


@njit(cache=True, nogil=True)
def posterior(chi2, post) -> None:
    """post = exp(-chi2 / 2), normalized (relative to the smallest chi2: no underflow of the best)."""
    lo = np.inf
    for k in range(chi2.shape[0]):
        if chi2[k] < lo:
            lo = chi2[k]
    total = 0.0
    for k in range(chi2.shape[0]):
        post[k] = math.exp(-0.5 * (chi2[k] - lo))
        total += post[k]
    for k in range(chi2.shape[0]):
        post[k] /= total


@njit(cache=True, nogil=True)
def spread(post, points, centre, radius2, link_of, own_link, cov, link_p, best_k) -> float:
    """About ``centre``: cov += sum_k post_k (p_k - c)(p_k - c)^T; link_p[l] = the posterior of link l;
    best_k[l] = link l's most probable point (on ``own_link``: the most probable farther than sqrt(radius2),
    -1 where none); returns the posterior mass farther than that from ``centre``."""
    far = 0.0
    for li in range(link_p.shape[0]):
        link_p[li] = 0.0
        best_k[li] = -1
    for k in range(post.shape[0]):
        d0, d1, d2 = points[k, 0] - centre[0], points[k, 1] - centre[1], points[k, 2] - centre[2]
        w = post[k]
        cov[0, 0] += w * d0 * d0
        cov[0, 1] += w * d0 * d1
        cov[0, 2] += w * d0 * d2
        cov[1, 1] += w * d1 * d1
        cov[1, 2] += w * d1 * d2
        cov[2, 2] += w * d2 * d2
        outside = d0 * d0 + d1 * d1 + d2 * d2 > radius2
        if outside:
            far += w
        li = link_of[k]
        link_p[li] += w
        if (li != own_link or outside) and (best_k[li] < 0 or w > post[best_k[li]]):
            best_k[li] = k
    cov[1, 0], cov[2, 0], cov[2, 1] = cov[0, 1], cov[0, 2], cov[1, 2]
    return far


@njit(cache=True, nogil=True)
def link_jacobians(xpos, xmat, body_ids, xaxis, xanchor, jids, hinge, moved, scene_joint, ratio, poses, jv, jw):
    """Each link's pose (rotation, origin) into ``poses`` (L, 3, 4) and its origin's Jacobians over the
    scene's joints into ``jv``, ``jw`` (L, 3, n): a hinge's column ``axis x (x - anchor)`` (linear) and
    ``axis`` (angular), a slide's ``axis`` (linear), times its ratio into its scene joint. ``moved`` (L, J):
    model joint j moves link l; ``jids``, ``hinge``, ``scene_joint``, ``ratio`` (J,) per model joint."""
    jv[:] = 0.0
    jw[:] = 0.0
    for li in range(body_ids.shape[0]):
        b = body_ids[li]
        for i in range(3):
            poses[li, i, 3] = xpos[b, i]
            for k in range(3):
                poses[li, i, k] = xmat[b, 3 * i + k]
        for j in range(jids.shape[0]):
            if not moved[li, j]:
                continue
            jid, c, s = jids[j], scene_joint[j], ratio[j]
            a0, a1, a2 = xaxis[jid, 0], xaxis[jid, 1], xaxis[jid, 2]
            if hinge[j]:
                d0, d1, d2 = xpos[b, 0] - xanchor[jid, 0], xpos[b, 1] - xanchor[jid, 1], xpos[b, 2] - xanchor[jid, 2]
                jv[li, 0, c] += s * (a1 * d2 - a2 * d1)
                jv[li, 1, c] += s * (a2 * d0 - a0 * d2)
                jv[li, 2, c] += s * (a0 * d1 - a1 * d0)
                jw[li, 0, c] += s * a0
                jw[li, 1, c] += s * a1
                jw[li, 2, c] += s * a2
            else:
                jv[li, 0, c] += s * a0
                jv[li, 1, c] += s * a1
                jv[li, 2, c] += s * a2
