"""How regular a recording's timestamps are. Pure."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Timing:
    """Of the steps between consecutive kept rows, in s: ``rate_hz`` is 1 / their median (a missed
    row or a late one does not move it); ``jitter_s`` their standard deviation; ``p5_s``/``p95_s``,
    ``min_s``/``max_s`` their spread. ``duration_s``: last time minus first."""

    rate_hz: float
    median_s: float
    jitter_s: float
    p5_s: float
    p95_s: float
    min_s: float
    max_s: float
    duration_s: float

    def describe(self) -> str:
        ms = 1e3
        return (f"{self.duration_s:.1f} s at {self.rate_hz:.1f} Hz (steps {self.median_s * ms:.2f} ms median, "
                f"{self.p5_s * ms:.2f}-{self.p95_s * ms:.2f} ms p5-p95, {self.min_s * ms:.2f}-{self.max_s * ms:.2f} ms "
                f"min-max, jitter {self.jitter_s * ms:.2f} ms std)")


def timing_of(t: np.ndarray) -> Timing:
    """The timing of increasing times ``t`` (n >= 2, s)."""
    steps = np.diff(t)
    median = float(np.median(steps))
    p5, p95 = np.percentile(steps, [5, 95])
    return Timing(1.0 / median, median, float(np.std(steps)), float(p5), float(p95), float(steps.min()),
                  float(steps.max()), float(t[-1] - t[0]))
