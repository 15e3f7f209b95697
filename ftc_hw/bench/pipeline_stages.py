"""Per-stage timing of one :class:`~ftc_hw.monitor.LiveMonitor` and its pipeline, for ``ftc bench pipeline``.

The stages' methods are wrapped on the instances (nothing in the pipeline changes): each call adds its
wall time to the stage's sum for the current frame. A stage called from inside another (the onset's
extra solve inside the events, say) is counted once, in the outer one. The wrappers cost about a
microsecond a frame; the bench times the totals in a second, unwrapped pass.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ftc_hw.monitor import LiveMonitor

STAGES = ("compensation", "detection", "localization", "events")

# (stage, path of the object from the pipeline, method name)
_WRAPPED = (
    ("compensation", "qdd", "update"),
    ("compensation", "", "_lag_errors"),
    ("compensation", "", "_gap_held"),
    ("compensation", "", "_model_error"),
    ("compensation", "compensator", "loads"),
    ("compensation", "compensator", "unbiased"),
    ("compensation", "compensator", "contact_wrench"),
    ("detection", "detector", "update"),
    ("localization", "residuals", "external_torques"),
    ("localization", "", "_solve"),
    ("localization", "", "_track_onset_start"),
    ("events", "track", "update"),
    ("events", "", "_contact_events"),
)


class StageTimer:
    """Wall time per stage for the frame under way (``start_frame`` / ``frame_times``)."""

    def __init__(self) -> None:
        self.ns = dict.fromkeys(STAGES, 0)
        self._inside = False

    def wrap(self, stage: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any, **kwargs: Any) -> Any:
            if self._inside:
                return fn(*args, **kwargs)
            self._inside = True
            t0 = time.perf_counter_ns()
            try:
                return fn(*args, **kwargs)
            finally:
                self.ns[stage] += time.perf_counter_ns() - t0
                self._inside = False
        return timed

    def start_frame(self) -> None:
        for k in self.ns:
            self.ns[k] = 0

    def frame_times(self) -> list[int]:
        return [self.ns[k] for k in STAGES]


def instrument(monitor: LiveMonitor) -> StageTimer:
    """Wrap the pipeline's stage methods of ``monitor`` (on its instances) with a timer."""
    timer = StageTimer()
    pipe = monitor.pipeline
    for stage, path, name in _WRAPPED:
        owner = getattr(pipe, path) if path else pipe
        if owner is not None:
            setattr(owner, name, timer.wrap(stage, getattr(owner, name)))
    return timer


def summarize_us(ns: np.ndarray) -> dict[str, float]:
    """Median, p99 and max (us) of per-frame times in ns; NaN for none."""
    if ns.size == 0:
        return {"median": float("nan"), "p99": float("nan"), "max": float("nan"), "frames": 0}
    us = ns / 1e3
    return {"median": float(np.median(us)), "p99": float(np.percentile(us, 99)), "max": float(us.max()),
            "frames": int(us.size)}
