"""Compiled per-frame steps of the compensation: at 7 kHz numpy's call overhead on 6-vectors (a few
microseconds per expression) was a tenth of the frame's budget. Same float operations, in the same
order, as the numpy expressions they replace (no fast-math): the same numbers to the bit.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def qdd_step(a: np.ndarray, qd_prev: np.ndarray, qd: np.ndarray, alpha: float, dt: float, out: np.ndarray) -> None:
    """out = alpha a + (1 - alpha) (qd - qd_prev) / dt; then a = out and qd_prev = qd (the filter's state)."""
    c = 1.0 - alpha
    for i in range(a.shape[0]):
        out[i] = alpha * a[i] + c * (qd[i] - qd_prev[i]) / dt
        a[i] = out[i]
        qd_prev[i] = qd[i]


@njit(cache=True, nogil=True)
def lag_rows(g_rows: np.ndarray, lag: np.ndarray, floor: float) -> np.ndarray:
    """Rows g_rows[j] * lag[j] (n x 6), a row zero where |lag[j]| is below ``floor``."""
    out = np.empty(g_rows.shape)
    for j in range(g_rows.shape[0]):
        s = lag[j] if abs(lag[j]) >= floor else 0.0
        for r in range(g_rows.shape[1]):
            out[j, r] = g_rows[j, r] * s
    return out
