"""The live page's feed slows down while the monitor falls behind, and comes back as it catches up
(``ftc_hw.app.web.feed.RatePacer``): the view degrades before the pipeline does."""
from __future__ import annotations

import pytest

from ftc_hw.app.web.feed import BEHIND_MS, SLOWEST_HZ, RatePacer

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others


def test_the_rate_halves_while_behind_down_to_the_slowest_and_comes_back():
    pacer = RatePacer(10.0)
    assert pacer.update(1.0, 0.1) == 10.0 and pacer.slowdowns == 0
    rates = [pacer.update(BEHIND_MS + 1, 0.1) for _ in range(6)]
    assert rates == [5.0, 2.5, 1.25, SLOWEST_HZ, SLOWEST_HZ, SLOWEST_HZ]
    assert pacer.slowdowns == 1  # one episode
    # between half the threshold and the threshold: held where it is
    assert pacer.update(0.75 * BEHIND_MS, 1.0) == SLOWEST_HZ
    back = [pacer.update(0.0, 1.0) for _ in range(12)]
    assert back[0] == pytest.approx(1.25) and back == sorted(back) and back[-1] == 10.0
    # slowed from each update that found it under 10 Hz: 5 x 0.1 s, the held 1 s, 11 x 1 s on the way back
    assert pacer.slowed_s == pytest.approx(0.5 + 1.0 + 11.0)
    pacer.update(BEHIND_MS + 1, 0.1)
    assert pacer.slowdowns == 2


def test_a_rate_under_the_slowest_is_kept():
    pacer = RatePacer(0.5)
    assert pacer.update(BEHIND_MS * 10, 1.0) == 0.5 and pacer.slowdowns == 0
