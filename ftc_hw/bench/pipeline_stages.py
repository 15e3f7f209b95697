"""Per-stage timing of one :class:`~ftc_hw.monitor.LiveMonitor`'s pipeline, for ``ftc bench pipeline``:
clocks the pipeline tells of each frame's beginning, each stage's end and the frame's end
(:class:`~ftc_hw.pipeline.StageClock`, the pipeline's ``clock``). Nothing in the pipeline is wrapped or
replaced. The stage laps cost a few hundred nanoseconds a frame; the bench times the totals in a second
pass with a clock that only reads the frame's beginning and end.
"""
from __future__ import annotations

import time

import numpy as np

from ftc_hw.pipeline import STAGES, StageClock


class FrameClock(StageClock):
    """The frame's wall and thread-CPU time, ns (``wall_ns``, ``cpu_ns``: 0 until a frame is processed;
    ``reset`` before each frame tells a judged frame from one the monitor dropped)."""

    def __init__(self) -> None:
        self.wall_ns = self.cpu_ns = 0
        self._t0 = self._c0 = 0

    def reset(self) -> None:
        self.wall_ns = self.cpu_ns = 0

    def begin(self) -> None:
        self._c0, self._t0 = time.thread_time_ns(), time.perf_counter_ns()

    def end(self) -> None:
        self.wall_ns = time.perf_counter_ns() - self._t0
        self.cpu_ns = time.thread_time_ns() - self._c0


class StageTimer(FrameClock):
    """Also the wall time of each stage in the frame (``frame_times``, in :data:`STAGES` order): the time
    since the previous lap (or the frame's beginning) goes to the stage that ends."""

    def __init__(self) -> None:
        super().__init__()
        self.ns = dict.fromkeys(STAGES, 0)
        self._last = 0

    def reset(self) -> None:
        super().reset()
        for k in self.ns:
            self.ns[k] = 0

    def begin(self) -> None:
        super().begin()
        self._last = self._t0

    def lap(self, stage: str) -> None:
        now = time.perf_counter_ns()
        self.ns[stage] += now - self._last
        self._last = now

    def frame_times(self) -> list[int]:
        return [self.ns[k] for k in STAGES]


def summarize_us(ns: np.ndarray) -> dict[str, float]:
    """Median, p99 and max (us) of per-frame times in ns; NaN for none."""
    if ns.size == 0:
        return {"median": float("nan"), "p99": float("nan"), "max": float("nan"), "frames": 0}
    us = ns / 1e3
    return {"median": float(np.median(us)), "p99": float(np.percentile(us, 99)), "max": float(us.max()),
            "frames": int(us.size)}
