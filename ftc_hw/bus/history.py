"""A stream's state at a time: which samples make it, and when there is none to trust. Said once, for
the bus (``Bus.sample_at``, on host times) and the monitor (the joint state at each F/T sample, on
aligned times: :class:`StateHistory`).

Between two samples at most ``max_gap_ns`` apart the state is interpolated linearly; exactly at a
sample it is that sample's (span 0: nothing between samples is guessed). Past the newest sample, by
at most ``max_ahead_ns``, the policy's ``ahead`` says what it is: ``none`` (no state), ``hold`` (the
newest sample's), ``linear`` (extrapolated from the newest two when they are at most ``max_gap_ns``
apart, else held). Anything else is a miss, with its reason: ``before`` (t precedes the first sample
ever kept), ``old`` (t precedes the oldest sample still kept), ``late`` (too far past the newest),
``gap`` (the samples around t too far apart).
"""
from __future__ import annotations

import threading
from bisect import bisect_right
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, NamedTuple

import numpy as np

Ahead = Literal["none", "hold", "linear"]
Miss = Literal["before", "old", "late", "gap"]


@dataclass(frozen=True)
class SamplingPolicy:
    """How a state is made at a time: ``max_gap_ns`` the widest span interpolated (and the widest pair
    extrapolated from); ``ahead`` and ``max_ahead_ns`` past the newest sample (module docstring)."""

    max_gap_ns: int
    ahead: Ahead = "none"
    max_ahead_ns: int = 0


class Bracket(NamedTuple):
    """The samples a state at ``t`` is made from: ``i`` the one at or before t; ``j`` the other one
    weighed in (after t: interpolated; before ``i``: extrapolated; None: ``i`` alone, exact or held);
    ``span_ns`` the time between the samples it was made from (to t itself when held or extrapolated)."""

    i: int
    j: int | None
    span_ns: int


def bracket(ts: Sequence[Any], t: int, policy: SamplingPolicy,
            key: Callable[[Any], int] | None = None) -> Bracket | Miss:
    """Which samples of ``ts`` (sorted by time; ``key`` gives an item's time) make the state at ``t``,
    or why none does (``before`` here stands for ``before`` or ``old``: the caller knows which)."""
    time_of = key or int
    i = bisect_right(ts, t, key=key)
    if i == 0:
        return "before"
    t0 = time_of(ts[i - 1])
    if t0 == t:
        return Bracket(i - 1, None, 0)
    if i == len(ts):
        if policy.ahead == "none" or t - t0 > policy.max_ahead_ns:
            return "late"
        if policy.ahead != "linear" or i < 2 or t0 - time_of(ts[i - 2]) > policy.max_gap_ns:
            return Bracket(i - 1, None, t - t0)
        return Bracket(i - 1, i - 2, t - time_of(ts[i - 2]))
    t1 = time_of(ts[i])
    if t1 - t0 > policy.max_gap_ns:
        return "gap"
    return Bracket(i - 1, i, t1 - t0)


class StateHistory:
    """A stream's recent samples (time ns, state vector) and its state at any time, by a
    :class:`SamplingPolicy`; thread-safe (one writer, any readers). ``period_ns``: the median spacing
    of the newest ``period_samples`` samples, refreshed every ``period_samples`` samples (None before)."""

    def __init__(self, policy: SamplingPolicy, *, maxlen: int = 4096, period_samples: int = 64) -> None:
        self.policy = policy
        self._lock = threading.Lock()
        self._t: deque[int] = deque(maxlen=maxlen)
        self._x: deque[np.ndarray] = deque(maxlen=maxlen)
        self._period_samples = period_samples
        self.count = 0  # samples ever added
        self.period_ns: int | None = None

    def add(self, t: int, x: np.ndarray) -> bool:
        """Keep a sample; False (dropped) when it is not newer than the newest (out of order, duplicate)."""
        with self._lock:
            ts = self._t
            if ts and t <= ts[-1]:
                return False
            ts.append(t)
            self._x.append(x)
            self.count += 1
            k = self._period_samples
            if self.count % k == 0 and len(ts) > k:
                self.period_ns = int(np.median(np.diff([ts[m] for m in range(len(ts) - k - 1, len(ts))])))
            return True

    def newest(self) -> int | None:
        with self._lock:
            return self._t[-1] if self._t else None

    def newest_two(self) -> tuple[tuple[int, np.ndarray], tuple[int, np.ndarray]] | None:
        """The newest sample and the one before it, each (time ns, state); None with fewer than two."""
        with self._lock:
            if len(self._t) < 2:
                return None
            return (self._t[-1], self._x[-1]), (self._t[-2], self._x[-2])

    def at(self, t: int) -> tuple[np.ndarray, int] | Miss:
        """The state at ``t`` and the span, ns, between the samples it was made from; or why there is none."""
        with self._lock:
            b = bracket(self._t, t, self.policy)
            if isinstance(b, str):
                return "old" if b == "before" and self.count > len(self._t) else b
            x0 = self._x[b.i]
            if b.j is None:
                return x0, b.span_ns
            t0, tj, xj = self._t[b.i], self._t[b.j], self._x[b.j]
        if b.j < b.i:  # past the newest: extrapolated along the last two samples
            return x0 + (t - t0) / (t0 - tj) * (x0 - xj), b.span_ns
        w = (t - t0) / (tj - t0) if tj > t0 else 0.0
        return x0 + w * (xj - x0), b.span_ns
