"""A stream's state at a time (``ftc_hw.bus.history``), as the monitor takes the joint state at each F/T
sample: interpolated between samples, extrapolated a little past the newest, and each miss named."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.bus import SamplingPolicy, StateHistory
from ftc_hw.bus.history import Bracket, bracket

POLICY = SamplingPolicy(max_gap_ns=20, ahead="linear", max_ahead_ns=5)


def history(times, maxlen=4096) -> StateHistory:
    h = StateHistory(POLICY, maxlen=maxlen, period_samples=4)
    for t in times:
        assert h.add(t, np.array([float(t), 2.0 * t]))
    return h


def test_between_samples_the_state_is_interpolated_with_their_span():
    x, span = history([0, 10, 20]).at(14)
    np.testing.assert_allclose(x, [14.0, 28.0])
    assert span == 10


def test_at_a_sample_it_is_that_sample():
    h = history([0, 10, 40])  # a gap after 10: still the sample itself at 10
    x, span = h.at(10)
    assert x.tolist() == [10.0, 20.0] and span == 0


def test_past_the_newest_it_is_extrapolated_along_the_last_two_then_late():
    h = history([0, 10, 20])
    x, span = h.at(25)
    np.testing.assert_allclose(x, [25.0, 50.0])
    assert span == 15  # from the older of the two samples to t
    assert h.at(26) == "late"


def test_a_newest_pair_too_far_apart_is_held_not_extrapolated():
    x, span = history([0, 30]).at(33)
    assert x.tolist() == [30.0, 60.0] and span == 3


def test_misses_are_named():
    assert StateHistory(POLICY).at(5) == "before"
    assert history([10, 20]).at(5) == "before"
    assert history([0, 30]).at(15) == "gap"
    assert history([0, 10, 20, 30], maxlen=2).at(5) == "old"  # 0 and 10 were evicted


def test_samples_out_of_order_are_dropped_and_the_period_is_the_median_spacing():
    h = history([0, 10, 20, 30, 40, 50, 60, 70])
    assert not h.add(65, np.zeros(2)) and not h.add(70, np.zeros(2))
    assert h.newest() == 70 and h.period_ns == 10


@pytest.mark.parametrize("ahead, t, want", [("none", 20, Bracket(1, None, 0)), ("none", 21, "late"),
                                            ("hold", 25, Bracket(1, None, 5)), ("hold", 26, "late")])
def test_the_bus_policies_hold_or_refuse_past_the_newest(ahead, t, want):
    assert bracket([10, 20], t, SamplingPolicy(20, ahead, 5)) == want
