"""Clock alignment against simulated device clocks with positive, spiky transport delays."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ftc_hw.bus import ClockAligner, ClockNotReadyError

H0 = 987_654_321_000  # host time of device time DEV0
DEV0 = 5_000_000_000
US = 1_000


# no deadline: the first example loads the aligner's compiled kernels (about a second on a loaded host)
@settings(deadline=None)
@given(
    st.lists(st.tuples(st.integers(1, 4_000_000), st.integers(0, 10**8)), min_size=1, max_size=200),
    st.integers(-(10**12), 10**12),
)
def test_without_skew_offset_is_window_minimum_of_delay(steps, offset):
    """The offset is the true offset plus the smallest delay of the samples in the window, except that
    it rises no faster than max_skew (a backlog is no clock)."""
    al = ClockAligner(window_s=0.01, estimate_skew=False, min_samples=1)
    t_dev, seen, expected = DEV0, [], None
    for period, delay in steps:
        t_dev += period
        al.update(t_dev, t_dev + offset + delay)
        seen.append((t_dev, delay))
        in_window = min(d for t, d in seen if t >= t_dev - 10_000_000)
        expected = in_window if expected is None else min(in_window, expected + al.max_skew * period)
        assert al.offset_ns == pytest.approx(offset + expected, abs=2)
        assert al.to_host(t_dev) == pytest.approx(t_dev + offset + expected, abs=2)
    assert al.resets == 0 and al.skew == 0.0


def test_a_reader_falling_behind_keeps_its_frames_true_time():
    """A reader that falls behind its 1 kHz device: for 5 s every frame arrives 150 ms per second later
    than the last. Once the window has slid past the prompt frames, its minimum is the backlog; the
    estimate must not follow it (the frames would take the joint state of another moment)."""
    al = ClockAligner()
    offset = H0 - DEV0
    for i in range(8000):
        t_dev = DEV0 + i * 1_000_000
        backlog = 0 if i < 3000 else round(0.15 * (i - 3000) * 1_000_000)
        al.update(t_dev, t_dev + offset + 200 * US + backlog)
    elapsed_ns = 5_000_000_000
    err = al.to_host(t_dev) - (t_dev + offset + 200 * US)
    assert 0 <= err <= al.max_skew * elapsed_ns + 1_000  # at most the rate a clock may drift, not 750 ms
    assert al.capped > 0 and al.resets == 0


def simulate(seed, skew, floor_ns, mean_ns, p_spike, n=4000, period_ns=1_000_000):
    """Yield (t_device, t_host, true host time of the device event) for a 1 kHz device."""
    rng = np.random.default_rng(seed)
    delays = floor_ns + rng.exponential(mean_ns, n)
    spikes = rng.random(n) < p_spike
    delays[spikes] += rng.uniform(1e6, 50e6, spikes.sum())  # 1-50 ms transport hiccups
    for i in range(n):
        t_dev = DEV0 + i * period_ns
        true = H0 + round(i * period_ns * (1 + skew))
        yield t_dev, true + int(delays[i]), true


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    skew=st.floats(-100e-6, 100e-6),
    floor_ns=st.integers(0, 1_000_000),
    mean_ns=st.floats(10e3, 300e3),
    p_spike=st.floats(0, 0.3),
)
def test_aligned_time_error_is_the_delay_floor(seed, skew, floor_ns, mean_ns, p_spike):
    """After warm-up, to_host(t_device) = true host time + delay floor, within 20 us, despite spikes."""
    al = ClockAligner()
    errors = []
    for i, (t_dev, t_host, true) in enumerate(simulate(seed, skew, floor_ns, mean_ns, p_spike)):
        al.update(t_dev, t_host)
        if i >= 2500:  # the 2 s window is full
            errors.append(al.to_host(t_dev) - true - floor_ns)
    errors = np.array(errors)
    assert np.abs(errors).max() <= 20 * US, (errors.min(), errors.max())
    assert al.skew == pytest.approx(skew, abs=5e-6)
    assert al.resets == 0 and al.ready


def test_skew_estimation_beats_min_filter_alone():
    plain, fitted = ClockAligner(estimate_skew=False), ClockAligner()
    err_plain, err_fit = [], []
    for t_dev, t_host, true in simulate(7, 80e-6, 50_000, 100e3, 0.1):
        plain.update(t_dev, t_host)
        fitted.update(t_dev, t_host)
        err_plain.append(plain.to_host(t_dev) - true - 50_000)
        err_fit.append(fitted.to_host(t_dev) - true - 50_000)
    # min filter alone lags by ~skew * window (160 us); the fit does not
    assert abs(np.mean(err_plain[-1000:])) > 100 * US
    assert abs(np.mean(err_fit[-1000:])) < 10 * US


def test_not_ready_and_errors_before_samples():
    al = ClockAligner(min_samples=3)
    with pytest.raises(ClockNotReadyError):
        al.to_host(0)
    with pytest.raises(ClockNotReadyError):
        _ = al.offset_ns
    for i in range(3):
        assert not al.ready
        al.update(i * 1000, 10**9 + i * 1000 + 7)
    assert al.ready and al.samples == 3
    assert al.offset_ns == 10**9 + 7


def test_device_clock_going_backwards_resets():
    al = ClockAligner(min_samples=2, estimate_skew=False)
    for i in range(10):
        al.update(10**9 + i * 1000, 5 * 10**9 + i * 1000)
    assert al.offset_ns == 4 * 10**9
    al.update(0, 6 * 10**9)  # device rebooted: its clock restarts at 0
    assert al.resets == 1 and al.samples == 1 and not al.ready
    assert al.offset_ns == 6 * 10**9


def test_impossibly_early_sample_resets_but_late_spike_does_not():
    al = ClockAligner(estimate_skew=False, jump_ns=100_000_000)
    for i in range(10):
        al.update(i * 1000, 10**9 + i * 1000)
    al.update(10_000, 10**9 + 10_000 + 10**9)  # 1 s late: just a delay spike
    assert al.resets == 0 and al.offset_ns == 10**9
    al.update(11_000, 11_000 + 10**8)  # 0.9 s earlier than possible: the device clock jumped
    assert al.resets == 1 and al.offset_ns == 10**8


def numpy_hull_slope(x, y, span, buckets, max_skew):
    """The skew fit's slope as first written in numpy (bucket minima by a sort by bucket, then by delay):
    the oracle of both faster forms' bucket minima (the hull over them is ``lower_hull_slope``)."""
    from ftc_hw.bus.clock import lower_hull_slope

    bucket = (x - x[0]) * buckets // (span + 1)
    order = np.lexsort((y, bucket))
    _, first = np.unique(bucket[order], return_index=True)
    return lower_hull_slope(x[order][first].astype(float), y[order][first].astype(float), float(x.mean()), max_skew)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 3_000_000), st.integers(-50_000, 50_000)), min_size=2, max_size=300),
       st.integers(2, 20), st.floats(1e-5, 1e-1))
def test_both_forms_of_the_skew_fit_match_the_sorted_one_to_the_bit(steps, buckets, max_skew):
    """The compiled fit and the numpy one without a sort; repeated device times, ties in delay and empty
    buckets included."""
    from ftc_hw.bus.clock import _hull_slope_numpy, _lowest_intercept_numpy
    from ftc_hw.bus.clock_kernels import hull_slope, lowest_intercept

    x = np.cumsum([s for s, _ in steps]).astype(np.int64)
    y = np.array([d // 1000 * 1000 for _, d in steps], dtype=np.int64)  # coarse: ties within buckets
    span = int(x[-1] - x[0])
    want = numpy_hull_slope(x, y, span, buckets, max_skew)
    b = hull_slope(x, y, span, buckets, float(x.mean()), max_skew)
    assert b == want == _hull_slope_numpy(x, y, span, buckets, float(x.mean()), max_skew)
    assert lowest_intercept(x, y, b) == float(np.min(y - b * x)) == _lowest_intercept_numpy(x, y, b)
