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
    # Cholesky a = L L^T in place (lower triangle), then solve L y = w: d2 = |y|^2
    for j in range(n):
        s = a[j, j]
        for p in range(j):
            s -= a[j, p] * a[j, p]
        if not s > 0.0:
            return np.inf
        d = np.sqrt(s)
        a[j, j] = d
        for i in range(j + 1, n):
            t = a[i, j]
            for p in range(j):
                t -= a[i, p] * a[j, p]
            a[i, j] = t / d
    d2 = 0.0
    y = np.empty(n)
    for i in range(n):
        t = w[i]
        for p in range(i):
            t -= a[i, p] * y[p]
        y[i] = t / a[i, i]
        d2 += y[i] * y[i]
    return d2
