"""A UR e-Series' built-in flange F/T sensor as its controller sees it: the world's F/T samples (the F/T
ring, as the scene's sensor reports them), held so that each RTDE packet takes the sample of its time.

The world publishes an F/T sample before the joint sample of the same step, so once the emulator has
read a joint sample, the F/T sample at or before its time is on the ring: :meth:`FlangeSamples.at` reads
what is new, then returns the newest sample no later than the packet's time, as a controller sends the
newest reading of its sensor. The world's F/T samples fall between the RTDE grid points (at
``(k + 1/2) / rate``: ``emulator.sample_number``), so the one sent is up to one sensor period older
than the packet (half a physics step at 1 kHz).
"""
from __future__ import annotations

from collections import Counter, deque

import numpy as np

from .link import RingReader

_HELD = 4096  # samples held: more than the ring reader's batch between two packets at any sensor rate here
_EPS_S = 1e-9  # world times of one step agree to far better than this


class FlangeSamples:
    """The F/T ring's samples ``[t, wrench (6), saturated (6)]`` for packets at given times; ``counts``:
    ``ft_missing`` (the world published none yet: zeros were sent), ``ft_not_at_time`` (no sample at or
    before the time: the oldest held was used), ``ft_late`` (the sample used is more than two sensor
    periods older than the packet)."""

    def __init__(self, reader: RingReader, rate_hz: float) -> None:
        self.reader = reader
        self.period_s = 1.0 / float(rate_hz)
        self.held: deque[np.ndarray] = deque(maxlen=_HELD)
        self.counts: Counter[str] = Counter()

    def at(self, t: float) -> np.ndarray:
        """The wrench (shape (6,), sensor frame) of the newest sample at or before world time ``t``."""
        self.held.extend(self.reader.new())
        if not self.held:
            self.counts["ft_missing"] += 1
            return np.zeros(6)
        chosen = None
        for rec in reversed(self.held):
            if rec[0] <= t + _EPS_S:
                chosen = rec
                break
        if chosen is None:
            self.counts["ft_not_at_time"] += 1
            chosen = self.held[0]
        elif t - chosen[0] > 2.0 * self.period_s + _EPS_S:
            self.counts["ft_late"] += 1
        return chosen[1:7]
