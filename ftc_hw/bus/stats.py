"""Per-stream statistics: count, rate, inter-arrival jitter, max gap, sequence gaps.

:class:`StreamStats` is fed host receive times (ns) and, when frames have one, sequence numbers.
Cumulative figures (count, max gap, sequence gaps, out-of-order arrivals) cover the whole stream;
rate and jitter cover a sliding window: the last ``window_s`` seconds of arrivals, capped at
``max_window`` arrivals. ``update_many`` is the vectorised equivalent of calling ``update`` once per
frame (the bus feeds its per-topic stats in batches of that kind, which keeps publish cheap).

Sequence numbers are expected to increase by one per frame (readers unwrap device counters and
handle device restarts): ``seq_missing`` adds ``seq - highest - 1`` for every jump past the highest
sequence number seen so far, ``seq_backwards`` counts arrivals with ``seq <= highest`` (duplicates,
late frames; a late frame was already counted as missing when it was skipped). A frame whose host
time is older than the newest one seen is counted in ``out_of_order`` and left out of the interval
figures.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["StatsSnapshot", "StreamStats"]


@dataclass(frozen=True, slots=True)
class StatsSnapshot:
    """Immutable statistics of one stream. Interval figures are 0.0 with fewer than 2 frames."""

    count: int
    rate_hz: float  # over the sliding window
    interval_mean_s: float  # mean inter-arrival time over the window
    jitter_s: float  # standard deviation of the inter-arrival time over the window
    interval_p99_s: float  # 99th percentile inter-arrival time over the window
    max_gap_s: float  # longest inter-arrival time since the start
    seq_missing: int
    seq_backwards: int
    out_of_order: int
    first_t_host_ns: int | None
    last_t_host_ns: int | None
    window_frames: int


class StreamStats:
    """Accumulates :class:`StatsSnapshot` figures for one stream. Not thread-safe on its own."""

    __slots__ = (
        "_count",
        "_first_t",
        "_last_t",
        "_last_seq",
        "_max_gap",
        "_seq_missing",
        "_seq_backwards",
        "_out_of_order",
        "_win",
        "_win_n",
        "_win_head",
        "_window_ns",
    )

    def __init__(self, window_s: float = 1.0, max_window: int = 8192) -> None:
        if window_s <= 0 or max_window < 2:
            raise ValueError("window_s must be > 0 and max_window >= 2")
        self._window_ns = int(window_s * 1e9)
        self._win = np.zeros(int(max_window), dtype=np.int64)  # ring of in-order arrival times
        self._win_n = 0
        self._win_head = 0  # next write index
        self._count = 0
        self._first_t: int | None = None
        self._last_t: int | None = None
        self._last_seq: int | None = None
        self._max_gap = 0
        self._seq_missing = 0
        self._seq_backwards = 0
        self._out_of_order = 0

    @property
    def count(self) -> int:
        return self._count

    def update(self, t_host_ns: int, seq: int | None = None) -> None:
        """Account for one frame received at ``t_host_ns``."""
        self._count += 1
        if seq is not None:
            last_seq = self._last_seq
            if last_seq is not None:
                d = seq - last_seq
                if d > 1:
                    self._seq_missing += d - 1
                elif d <= 0:
                    self._seq_backwards += 1
                    seq = last_seq
            self._last_seq = seq
        last = self._last_t
        if last is None:
            self._first_t = t_host_ns
        elif t_host_ns < last:
            self._out_of_order += 1
            return
        elif t_host_ns - last > self._max_gap:
            self._max_gap = t_host_ns - last
        self._last_t = t_host_ns
        self._win[self._win_head] = t_host_ns
        self._win_head = (self._win_head + 1) % self._win.shape[0]
        self._win_n = min(self._win_n + 1, self._win.shape[0])

    def update_many(
        self, t_host_ns: Sequence[int] | np.ndarray, seq: Sequence[int] | np.ndarray | None = None
    ) -> None:
        """Same result as ``update`` called for each element in order, vectorised."""
        t = np.asarray(t_host_ns, dtype=np.int64).ravel()
        k = t.shape[0]
        if k == 0:
            return
        s = None if seq is None else np.asarray(seq, dtype=np.int64).ravel()
        if s is not None and s.shape[0] != k:
            raise ValueError(f"seq has {s.shape[0]} elements, t_host_ns has {k}")
        last = self._last_t
        t_full = t if last is None else np.concatenate((np.array([last], dtype=np.int64), t))
        dt = np.diff(t_full)
        if (dt < 0).any():  # rare: out-of-order arrivals need the sequential logic
            for i in range(k):
                self.update(int(t[i]), None if s is None else int(s[i]))
            return
        self._count += k
        if s is not None:
            s_full = s if self._last_seq is None else np.concatenate((np.array([self._last_seq]), s))
            highest = np.maximum.accumulate(s_full)
            ds = s_full[1:] - highest[:-1]
            self._seq_missing += int((ds[ds > 1] - 1).sum())
            self._seq_backwards += int((ds <= 0).sum())
            self._last_seq = int(highest[-1])
        if last is None:
            self._first_t = int(t[0])
        if dt.shape[0]:
            self._max_gap = max(self._max_gap, int(dt.max()))
        self._last_t = int(t[-1])
        self._write_window(t)

    def _write_window(self, t: np.ndarray) -> None:
        cap = self._win.shape[0]
        if t.shape[0] >= cap:
            self._win[:] = t[-cap:]
            self._win_head, self._win_n = 0, cap
            return
        head, k = self._win_head, t.shape[0]
        first = min(k, cap - head)
        self._win[head : head + first] = t[:first]
        self._win[: k - first] = t[first:]
        self._win_head = (head + k) % cap
        self._win_n = min(self._win_n + k, cap)

    def window_times(self) -> np.ndarray:
        """In-order arrival times (ns) in the sliding window, oldest first (a copy)."""
        n, cap, head = self._win_n, self._win.shape[0], self._win_head
        w = self._win[:n].copy() if n < cap else np.concatenate((self._win[head:], self._win[:head]))
        if n:
            w = w[w >= w[-1] - self._window_ns]
        return w

    def snapshot(self) -> StatsSnapshot:
        """Immutable copy of the current figures."""
        w = self.window_times()
        rate = mean = jitter = p99 = 0.0
        if w.shape[0] >= 2:
            dts = np.diff(w).astype(np.float64) * 1e-9
            span = (int(w[-1]) - int(w[0])) * 1e-9
            rate = (w.shape[0] - 1) / span if span > 0 else float("inf")
            mean = float(dts.mean())
            jitter = float(dts.std())
            p99 = float(np.percentile(dts, 99))
        return StatsSnapshot(
            count=self._count,
            rate_hz=rate,
            interval_mean_s=mean,
            jitter_s=jitter,
            interval_p99_s=p99,
            max_gap_s=self._max_gap * 1e-9,
            seq_missing=self._seq_missing,
            seq_backwards=self._seq_backwards,
            out_of_order=self._out_of_order,
            first_t_host_ns=self._first_t,
            last_t_host_ns=self._last_t,
            window_frames=int(w.shape[0]),
        )
