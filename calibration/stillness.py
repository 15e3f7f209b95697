"""Is the arm still? From the joint speeds and the F/T signal's spread and trend over a window.

A sample window passes when every joint is slower than ``qd_max``, the joint angles moved less than
``q_span_max``, each F/T axis's standard deviation is within ``variance_ratio`` times the sensor noise
(a moving arm or a hand on it adds more) and the first and second halves' means agree within
``trend_sigma`` standard errors (a slow push or a settling oscillation).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ftc_hw.scene import Scene

AXES = ("fx", "fy", "fz", "tx", "ty", "tz")


@dataclass(frozen=True)
class StillnessReport:
    still: bool
    reason: str
    qd_max: float
    variance_ratio: float  # largest F/T std / expected noise std over the axes
    trend_sigma: float  # largest half-to-half change of the mean, in standard errors


class StillnessGate:
    def __init__(self, scene: Scene, *, qd_max: float = 0.03, q_span_max: float = 0.004,
                 variance_ratio: float = 2.0, trend_sigma: float = 5.0) -> None:
        self.noise = np.sqrt(np.diag(scene.sensor.noise_cov))
        self.qd_max = qd_max
        self.q_span_max = q_span_max
        self.variance_ratio = variance_ratio
        self.trend_sigma = trend_sigma

    def check(self, wrenches: np.ndarray, q: np.ndarray, qd: np.ndarray | None = None) -> StillnessReport:
        """``wrenches`` (N, 6), ``q`` (k, n), ``qd`` (k, n) over the same window."""
        w = np.asarray(wrenches, dtype=float).reshape(-1, 6)
        q = np.atleast_2d(np.asarray(q, dtype=float))
        speed = 0.0 if qd is None or np.size(qd) == 0 else float(np.abs(qd).max())
        if len(w) < 6 or len(q) < 1:
            return StillnessReport(False, "not enough samples yet", speed, float("nan"), float("nan"))
        span = float(np.ptp(q, axis=0).max()) if len(q) > 1 else 0.0
        ratio_axes = w.std(axis=0, ddof=1) / self.noise
        half = len(w) // 2
        diff = np.abs(w[:half].mean(axis=0) - w[half:].mean(axis=0))
        se = self.noise * np.sqrt(1.0 / half + 1.0 / (len(w) - half))
        trend_axes = diff / se
        ratio, trend = float(ratio_axes.max()), float(trend_axes.max())
        if speed > self.qd_max:
            return StillnessReport(False, f"joints moving ({speed:.3f} rad/s)", speed, ratio, trend)
        if span > self.q_span_max:
            return StillnessReport(False, f"joint angles changed by {span * 1e3:.1f} mrad", speed, ratio, trend)
        if ratio > self.variance_ratio:
            a = AXES[int(np.argmax(ratio_axes))]
            return StillnessReport(False, f"F/T {a} spread {ratio:.1f} x the sensor noise (motion or contact)",
                                   speed, ratio, trend)
        if trend > self.trend_sigma:
            a = AXES[int(np.argmax(trend_axes))]
            return StillnessReport(False, f"F/T {a} still changing ({trend:.1f} standard errors across the window)",
                                   speed, ratio, trend)
        return StillnessReport(True, "still", speed, ratio, trend)
