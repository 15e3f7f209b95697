"""Time queries: window boundaries, sample_at interpolation, hold and stale refusal."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from ftc_hw.bus import Bus, JointFlag, JointFrame, StaleDataError, WrenchFlag, WrenchFrame

_W = np.zeros(6)
_W.flags.writeable = False


def wf(t: int) -> WrenchFrame:
    return WrenchFrame(t, None, t, "ft0", _W)


@pytest.fixture
def bus10() -> Bus:
    bus = Bus()
    for t in range(0, 100, 10):  # 0, 10, ..., 90
        bus.publish("wrench/ft0", wf(t))
    return bus


@pytest.mark.parametrize(
    ("t0", "t1", "expected"),
    [
        (10, 30, [10, 20, 30]),  # both ends inclusive
        (11, 29, [20]),
        (11, 19, []),
        (-100, 0, [0]),
        (90, 1000, [90]),
        (-5, 1000, list(range(0, 100, 10))),
        (30, 10, []),  # reversed interval
        (91, 1000, []),
    ],
)
def test_window_boundaries(bus10, t0, t1, expected):
    assert [f.t_host_ns for f in bus10.window("wrench/ft0", t0, t1)] == expected


def test_window_with_equal_timestamps_and_unknown_topic():
    bus = Bus()
    for t in (1, 2, 2, 2, 3):
        bus.publish("wrench/ft0", wf(t))
    assert [f.t_host_ns for f in bus.window("wrench/ft0", 2, 2)] == [2, 2, 2]
    assert bus.window("wrench/none", 0, 10) == []


def joint(t: int, q, qd=None, cur=None, tau=None, seq: int = 0, t_dev=None, flags=JointFlag.NONE):
    q = np.asarray(q, dtype=float)
    qd = q * 2 if qd is None else qd
    cur = q * 3 if cur is None else cur
    return JointFrame.make(t, q, qd, cur, tau, source="arm", seq=seq, t_device_ns=t_dev, flags=flags)


finite = st.floats(-1e3, 1e3, allow_nan=False)


@given(
    c0=st.lists(finite, min_size=1, max_size=7),
    slope=finite,
    times=st.lists(st.integers(0, 10**6), min_size=2, max_size=20, unique=True).map(sorted),
    frac=st.floats(0, 1),
)
def test_linear_data_interpolates_exactly(c0, slope, times, frac):
    """q(t) = c0 + slope * t is reproduced at any time between two stored frames."""
    bus = Bus(max_gap_ns=10**7)
    c0 = np.array(c0)

    def q_at(t):
        return c0 + slope * (t * 1e-6)

    for i, t in enumerate(times):
        bus.publish("joints/arm", joint(t, q_at(t), tau=-q_at(t), seq=i, t_dev=2 * t))
    t = times[0] + round(frac * (times[-1] - times[0]))
    s = bus.sample_at("joints/arm", t)
    assert s.t_host_ns == t
    scale = 1 + np.abs(c0).max() + abs(slope)
    np.testing.assert_allclose(s.q, q_at(t), rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(s.qd, 2 * q_at(t), rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(s.current, 3 * q_at(t), rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(s.tau, -q_at(t), rtol=0, atol=1e-12 * scale)
    assert s.t_device_ns == 2 * t
    assert all(not a.flags.writeable for a in (s.q, s.qd, s.current, s.tau))
    if t in times:
        assert s.flags == JointFlag.NONE  # the stored frame itself
    else:
        assert s.flags & JointFlag.INTERPOLATED


def test_sample_at_exact_time_returns_stored_frame_and_merges_flags():
    bus = Bus()
    a = joint(100, [0.0], seq=1, flags=JointFlag.SEQ_GAP)
    b = joint(200, [1.0], seq=2)
    bus.publish("joints/arm", a)
    bus.publish("joints/arm", b)
    assert bus.sample_at("joints/arm", 100) is a
    assert bus.sample_at("joints/arm", 200) is b
    mid = bus.sample_at("joints/arm", 125)
    assert mid.q.tolist() == [0.25] and mid.seq == 1
    assert mid.flags == JointFlag.SEQ_GAP | JointFlag.INTERPOLATED
    assert mid.tau is None and mid.t_device_ns is None


def test_sample_at_tau_only_when_both_frames_have_it():
    bus = Bus()
    bus.publish("joints/arm", joint(0, [0.0], tau=[1.0]))
    bus.publish("joints/arm", joint(10, [1.0]))
    assert bus.sample_at("joints/arm", 5).tau is None


@pytest.mark.parametrize("limit", [2, 10, 1000])
def test_bracketing_gap_refused_beyond_limit_at_the_boundary(limit):
    bus = Bus(max_gap_ns=limit)
    bus.publish("joints/arm", joint(0, [0.0]))
    bus.publish("joints/arm", joint(limit, [1.0]))  # gap == limit: allowed
    bus.publish("joints/arm", joint(2 * limit + 1, [2.0]))  # gap == limit + 1: refused
    assert bus.sample_at("joints/arm", limit // 2).flags == JointFlag.INTERPOLATED
    with pytest.raises(StaleDataError) as err:
        bus.sample_at("joints/arm", limit + 1)
    assert err.value.gap_ns == limit + 1 and err.value.limit_ns == limit
    assert "apart" in str(err.value)
    assert bus.sample_at("joints/arm", limit + 1, max_gap_ns=limit + 1).flags & JointFlag.INTERPOLATED


def test_hold_after_newest_up_to_the_limit_then_refuse():
    bus = Bus(max_gap_ns=20)
    last = joint(100, [1.0], t_dev=7)
    bus.publish("joints/arm", joint(90, [0.0]))
    bus.publish("joints/arm", last)
    held = bus.sample_at("joints/arm", 120)  # 20 ns after the newest: hold
    assert held.t_host_ns == 120 and held.q is last.q and held.t_device_ns is None
    assert held.flags == JointFlag.HELD
    with pytest.raises(StaleDataError, match="after the newest") as err:
        bus.sample_at("joints/arm", 121)
    assert err.value.gap_ns == 21 and err.value.limit_ns == 20
    with pytest.raises(StaleDataError, match="hold disabled"):
        bus.sample_at("joints/arm", 101, hold=False)


def test_before_oldest_and_unknown_topic_refused():
    bus = Bus(history=3)
    for t in range(0, 50, 10):
        bus.publish("joints/arm", joint(t, [float(t)]))
    with pytest.raises(StaleDataError, match="before the oldest"):
        bus.sample_at("joints/arm", 19)  # 0 and 10 were evicted
    assert bus.sample_at("joints/arm", 20).q.tolist() == [20.0]
    with pytest.raises(StaleDataError, match="no frame"):
        bus.sample_at("joints/none", 0)


@given(t=st.integers(-100, 300), limit=st.integers(1, 150))
def test_sample_at_never_extrapolates(t, limit):
    """Every time either is refused or lies within the limit of the data it is derived from."""
    bus = Bus(max_gap_ns=limit)
    times = [0, 50, 60, 200]
    for k in times:
        bus.publish("joints/arm", joint(k, [float(k)]))
    try:
        s = bus.sample_at("joints/arm", t)
    except StaleDataError:
        before = [k for k in times if k <= t]
        after = [k for k in times if k > t]
        assert (
            not before
            or (not after and t - before[-1] > limit)
            or (after and before[-1] != t and after[0] - before[-1] > limit)
        )
    else:
        assert 0 <= t <= 200 + limit
        assert s.q[0] == pytest.approx(min(t, 200))  # q == t in the data, held after 200


def test_sample_at_on_wrench_topic():
    bus = Bus()
    a = WrenchFrame.make(0, [0, 0, 0, 0, 0, 0], source="ft0", seq=0, flags=WrenchFlag.SATURATED)
    b = WrenchFrame.make(10, [10, 20, 30, 40, 50, 60], source="ft0", seq=1)
    bus.publish("wrench/ft0", a)
    bus.publish("wrench/ft0", b)
    s = bus.sample_at("wrench/ft0", 3)
    assert s.wrench.tolist() == pytest.approx([3, 6, 9, 12, 15, 18])
    assert s.flags == WrenchFlag.SATURATED | WrenchFlag.INTERPOLATED
    assert bus.sample_at("wrench/ft0", 12).flags == WrenchFlag.HELD
