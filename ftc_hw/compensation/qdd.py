"""Joint acceleration from measured joint velocity, causally (for dynamics compensation).

Backward difference of qd, then a first-order low-pass with time constant ``tau``:

    a_k = alpha a_{k-1} + (1 - alpha) (qd_k - qd_{k-1}) / dt_k,   alpha = exp(-dt_k / tau)

Lag: a ramp in qdd is followed with a delay of about ``tau`` (the backward difference's dt/2 and the
discrete filter's tau - dt/2 add up; 2 ms at the pipeline's default); a step in qdd reaches 63 %
after about ``tau``. Noise: white velocity noise of std s_v gives an
output std of ``s_v * sqrt(2) / dt * (1 - alpha) / sqrt(1 + alpha)`` (the difference's noise is
correlated from one sample to the next; at 1 kHz: 0.23 s_v / dt for tau = 4 ms, 0.44 s_v / dt for
tau = 2 ms). Larger ``tau`` trades lag for noise.
"""
from __future__ import annotations

import math

import numpy as np

from .kernels import qdd_step


class QddEstimator:
    def __init__(self, n_joints: int, tau: float = 0.004) -> None:
        if tau <= 0:
            raise ValueError("tau must be > 0 s")
        self.tau = tau
        self._t: float | None = None
        self._qd = np.zeros(n_joints)
        self._a = np.zeros(n_joints)

    def reset(self) -> None:
        self._t = None
        self._a[:] = 0.0

    def update(self, t: float, qd) -> np.ndarray:
        """Feed the velocity measured at time t (s); returns the acceleration estimate (rad/s^2)."""
        qd = np.asarray(qd, dtype=float)
        if self._t is None or t <= self._t:
            self._t = t
            self._qd = qd.copy()
            return self._a.copy()
        dt = t - self._t
        out = np.empty_like(self._a)
        qdd_step(self._a, self._qd, qd, math.exp(-dt / self.tau), dt, out)  # the state too
        self._t = t
        return out

    @staticmethod
    def noise_gain(dt: float, tau: float) -> float:
        """Output std per unit of white velocity-noise std."""
        alpha = math.exp(-dt / tau)
        return math.sqrt(2.0) / dt * (1.0 - alpha) / math.sqrt(1.0 + alpha)


class RecentPeak:
    """Per-component maximum of a vector over a sliding time window, kept in ``bucket_ns`` buckets
    (a ring of ``buckets``): ``add`` costs one elementwise maximum, ``max_since`` one over the ring.
    The window is resolved to a bucket: ``max_since(t0)`` covers from the start of t0's bucket."""

    def __init__(self, n: int, bucket_ns: int = 5_000_000, buckets: int = 64) -> None:
        self.bucket_ns = int(bucket_ns)
        self._peak = np.zeros((buckets, n))
        self._id = np.full(buckets, -1, dtype=np.int64)  # which bucket each row holds
        self._bucket = -1
        self._row = self._peak[0]

    def add(self, t_ns: int, x: np.ndarray) -> None:
        b = t_ns // self.bucket_ns
        if b == self._bucket:
            np.maximum(self._row, x, out=self._row)
            return
        self._bucket = b
        i = b % len(self._id)
        self._id[i] = b
        self._row = self._peak[i]
        self._row[:] = x

    def max_since(self, t0_ns: int, t_now_ns: int) -> np.ndarray | None:
        """The maximum over the buckets from t0's to t_now's (None when none holds a value); a window
        longer than the ring is cut to the ring."""
        b_now = t_now_ns // self.bucket_ns
        lo = max(t0_ns // self.bucket_ns, b_now - len(self._id) + 1)
        keep = (self._id >= lo) & (self._id <= b_now)
        return self._peak[keep].max(axis=0) if keep.any() else None
