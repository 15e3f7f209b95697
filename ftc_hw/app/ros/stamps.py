"""A ROS stream's sequence from its header stamps. ROS 2 messages carry no sequence number, so the frames'
``seq`` counts the messages, and, where the driver's rate is known, the messages missing between two
stamps more than 1.5 periods apart are added to it (a gap the frames' ``SEQ_GAP`` flag and the adapters'
``lost`` counters then say, as for a device's own counter). A stamp equal to the last is a duplicate; an
earlier one is a clock reset (the driver restarted, a bag looped): counted, and the frame's device time
then starts a new epoch (``CLOCK_SUSPECT`` until the alignment trusts it again)."""
from __future__ import annotations

from dataclasses import dataclass

GAP_PERIODS = 1.5  # a step this many periods long or longer misses round(step / period) - 1 messages


@dataclass(frozen=True)
class Step:
    seq: int
    lost: int = 0  # messages missing just before this one (0 without a rate)
    duplicate: bool = False  # the same stamp as the last: not a new sample
    backwards: bool = False  # an earlier stamp than the last: the driver's clock went back


class StampSequence:
    """``update(stamp_ns) -> Step`` for each message in arrival order; ``period_ns`` None: no gap judged."""

    def __init__(self, period_ns: int | None = None) -> None:
        if period_ns is not None and period_ns <= 0:
            raise ValueError("period_ns must be > 0")
        self.period_ns = period_ns
        self.last: int | None = None
        self.seq = -1

    def update(self, stamp_ns: int) -> Step:
        last = self.last
        if last is not None and stamp_ns == last:
            return Step(self.seq, duplicate=True)
        self.last = stamp_ns
        backwards = last is not None and stamp_ns < last
        lost = 0
        if last is not None and not backwards and self.period_ns is not None \
                and stamp_ns - last >= GAP_PERIODS * self.period_ns:
            lost = round((stamp_ns - last) / self.period_ns) - 1
        self.seq += 1 + lost
        return Step(self.seq, lost, backwards=backwards)
