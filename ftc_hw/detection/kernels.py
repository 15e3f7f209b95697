"""Compiled core of the detector: the Mahalanobis distance under a per-sample covariance update.

A 6x6 Cholesky written out is a microsecond; numpy's linalg costs ten in call overhead alone, on
every frame of a moving arm.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def mahalanobis2(w: np.ndarray, cov: np.ndarray, u: np.ndarray) -> float:
    """w^T (cov + u^T u)^-1 w for a wrench w (6,), covariance cov (6, 6) and rows u (k, 6).
    Returns inf when the matrix is not positive definite (a broken covariance, not a wrench)."""
    n = 6
    a = cov.copy()
    for k in range(u.shape[0]):
        for i in range(n):
            for j in range(n):
                a[i, j] += u[k, i] * u[k, j]
    return chol_quad(w, a)


@njit(cache=True, nogil=True)
def chol_quad(w: np.ndarray, a: np.ndarray) -> float:
    """w^T a^-1 w for w (n,) and a symmetric (n, n), by a Cholesky factorization in place (``a`` is
    overwritten); inf when ``a`` is not positive definite."""
    n = w.shape[0]
    # Cholesky a = L L^T in place (lower triangle), then solve L y = w: d2 = |y|^2
    if not cholesky_in_place(a):
        return np.inf
    d2 = 0.0
    y = np.empty(n)
    for i in range(n):
        t = w[i]
        for p in range(i):
            t -= a[i, p] * y[p]
        y[i] = t / a[i, i]
        d2 += y[i] * y[i]
    return d2


@njit(cache=True, nogil=True)
def cholesky_in_place(a: np.ndarray) -> bool:
    """a = L L^T for a symmetric (n, n), L written into a's lower triangle; False when a is not positive
    definite (a then partly overwritten)."""
    n = a.shape[0]
    for j in range(n):
        s = a[j, j]
        for p in range(j):
            s -= a[j, p] * a[j, p]
        if not s > 0.0:
            return False
        d = np.sqrt(s)
        a[j, j] = d
        for i in range(j + 1, n):
            t = a[i, j]
            for p in range(j):
                t -= a[i, p] * a[j, p]
            a[i, j] = t / d
    return True


@njit(cache=True, nogil=True)
def window_change(ring, ring_t, t_now, window_ns, x, out) -> float:
    """out[j] = the largest |x[j] - ring[k, j]| over the ring's rows stamped within ``window_ns`` before
    ``t_now``, and over the newest row older than that (so a sparse stream still has a past sample);
    rows stamped -1 are empty. Returns max(out)."""
    n = x.shape[0]
    for j in range(n):
        out[j] = 0.0
    older = -1
    for k in range(ring.shape[0]):
        tk = ring_t[k]
        if tk < 0:
            continue
        if tk >= t_now - window_ns:
            for j in range(n):
                d = abs(x[j] - ring[k, j])
                if d > out[j]:
                    out[j] = d
        elif older < 0 or tk > ring_t[older]:
            older = k
    if older >= 0:
        for j in range(n):
            d = abs(x[j] - ring[older, j])
            if d > out[j]:
                out[j] = d
    best = 0.0
    for j in range(n):
        if out[j] > best:
            best = out[j]
    return best


@njit(cache=True, nogil=True)
def quad_sum(u: np.ndarray, inv: np.ndarray) -> float:
    """sum_k u_k^T inv u_k over the rows u_k of u (k, 6): how large the rows are against a noise
    whose inverse covariance is ``inv`` (chi-square scale)."""
    acc = 0.0
    for k in range(u.shape[0]):
        for i in range(6):
            t = 0.0
            for j in range(6):
                t += inv[i, j] * u[k, j]
            acc += u[k, i] * t
    return acc


@njit(cache=True, nogil=True)
def nested_quads(w: np.ndarray, a: np.ndarray, out: np.ndarray) -> bool:
    """out[k - 1] = the matched-subspace statistic of w (n,) for the subspace of its first k coordinates,
    k = 1..n, under covariance a (n, n) (left intact): w^T a^-1 w less the trailing n - k coordinates'
    own w_b^T a_bb^-1 w_b. One Cholesky factorization of a in reversed order gives every trailing
    block's statistic as a running sum. False when ``a`` is not positive definite (``out`` then inf)."""
    n = w.shape[0]
    c = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            c[i, j] = a[n - 1 - i, n - 1 - j]
    if not cholesky_in_place(c):
        out[:] = np.inf
        return False
    y = np.empty(n)
    tail = np.zeros(n + 1)  # tail[m]: the statistic of the last m coordinates alone
    for i in range(n):
        t = w[n - 1 - i]
        for p in range(i):
            t -= c[i, p] * y[p]
        y[i] = t / c[i, i]
        tail[i + 1] = tail[i] + y[i] * y[i]
    for k in range(1, n + 1):
        out[k - 1] = tail[n] - tail[n - k]
    return True
