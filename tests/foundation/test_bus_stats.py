"""Stream statistics on synthetic timestamps, standalone and kept by the bus."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from ftc_hw.bus import Bus, StatsSnapshot, StreamStats, WrenchFrame

_W = np.zeros(6)
_W.flags.writeable = False
MS = 1_000_000


def test_uniform_stream_rate_and_zero_jitter():
    s = StreamStats(window_s=10)
    for i in range(1001):
        s.update(5 * MS + i * MS, seq=i)
    snap = s.snapshot()
    assert snap.count == 1001
    assert snap.rate_hz == pytest.approx(1000.0)
    assert snap.interval_mean_s == pytest.approx(1e-3)
    assert snap.jitter_s == pytest.approx(0.0, abs=1e-15)
    assert snap.max_gap_s == pytest.approx(1e-3)
    assert snap.seq_missing == 0 and snap.seq_backwards == 0 and snap.out_of_order == 0
    assert snap.first_t_host_ns == 5 * MS and snap.last_t_host_ns == 1005 * MS
    assert snap.window_frames == 1001


def test_alternating_intervals_give_known_jitter_and_p99():
    s = StreamStats(window_s=10)
    t = 0
    for i in range(2001):
        s.update(t)
        t += 900_000 if i % 2 else 1_100_000  # 0.9 ms / 1.1 ms: mean 1 ms, std 0.1 ms
    snap = s.snapshot()
    assert snap.rate_hz == pytest.approx(1000.0)
    assert snap.jitter_s == pytest.approx(1e-4, rel=1e-9)
    assert snap.interval_p99_s == pytest.approx(1.1e-3)
    assert snap.max_gap_s == pytest.approx(1.1e-3)


def test_sliding_window_follows_rate_change():
    s = StreamStats(window_s=1.0)
    t = 0
    for _ in range(2000):  # 2 s at 1 kHz
        t += MS
        s.update(t)
    for _ in range(400):  # then 2 s at 200 Hz
        t += 5 * MS
        s.update(t)
    snap = s.snapshot()
    assert snap.rate_hz == pytest.approx(200.0)
    assert snap.window_frames == 201  # arrivals within the last 1 s, both ends included
    assert snap.max_gap_s == pytest.approx(5e-3)
    capped = StreamStats(window_s=100, max_window=50)
    for i in range(500):
        capped.update(i * MS)
    assert capped.snapshot().window_frames == 50


def test_sequence_gaps_and_backwards():
    s = StreamStats()
    for t, seq in enumerate([0, 1, 2, 5, 6, 6, 3, 10]):
        s.update(t * MS, seq)
    snap = s.snapshot()
    assert snap.seq_missing == 2 + 3  # 3,4 then 7,8,9 (3 arrived late: counted missing, then backwards)
    assert snap.seq_backwards == 2  # 6 again, then 3


def test_max_gap_and_out_of_order():
    s = StreamStats()
    for t in [0, 1, 2, 50, 51, 40, 52]:
        s.update(t * MS)
    snap = s.snapshot()
    assert snap.max_gap_s == pytest.approx(48e-3)
    assert snap.out_of_order == 1 and snap.count == 7
    assert snap.last_t_host_ns == 52 * MS


def test_empty_and_single_frame():
    snap = StreamStats().snapshot()
    assert snap.count == 0 and snap.rate_hz == 0.0 and snap.last_t_host_ns is None
    s = StreamStats()
    s.update(7)
    snap = s.snapshot()
    assert snap.count == 1 and snap.rate_hz == 0.0 and snap.jitter_s == 0.0 and snap.first_t_host_ns == 7


def test_snapshot_is_immutable():
    snap = StreamStats().snapshot()
    assert isinstance(snap, StatsSnapshot)
    with pytest.raises(dataclasses.FrozenInstanceError):
        snap.count = 3  # type: ignore[misc]


arrivals = st.lists(st.tuples(st.integers(-5 * MS, 20 * MS), st.integers(-3, 5)), min_size=0, max_size=300)


@given(arrivals, st.lists(st.integers(1, 64), min_size=1, max_size=10), st.booleans())
def test_update_many_equals_update(steps, chunks, with_seq):
    """Batches (even with out-of-order arrivals inside) give the same figures as one by one."""
    t, seq, ts, seqs = 10**9, 0, [], []
    for dt, dseq in steps:
        t, seq = t + dt, seq + dseq
        ts.append(t)
        seqs.append(seq)
    one = StreamStats(window_s=0.05, max_window=40)
    many = StreamStats(window_s=0.05, max_window=40)
    for i, x in enumerate(ts):
        one.update(x, seqs[i] if with_seq else None)
    i, k = 0, 0
    while i < len(ts):
        n = chunks[k % len(chunks)]
        many.update_many(ts[i : i + n], seqs[i : i + n] if with_seq else None)
        i, k = i + n, k + 1
    assert one.snapshot() == many.snapshot()


def test_bus_stats_match_direct_feeding_across_batches():
    bus = Bus(history=100)  # small ring: the bus feeds its stats in batches of <= 100 frames
    ref = StreamStats()
    rng = np.random.default_rng(1)
    t, seq = 0, 0
    for _ in range(1234):
        t += int(rng.integers(500_000, 1_500_000))
        seq += int(rng.choice([1, 1, 1, 2]))
        bus.publish("wrench/ft0", WrenchFrame(t, None, seq, "ft0", _W))
        ref.update(t, seq)
    assert bus.stats("wrench/ft0") == ref.snapshot()
    assert bus.stats("wrench/ft0").seq_missing > 0


def test_bus_stats_for_frames_without_seq():
    from ftc_hw.bus import DeviceEvent

    bus = Bus()
    for t in (0, 10 * MS, 20 * MS):
        bus.publish("events/device", DeviceEvent.make(t, "ft0", "connect"))
    snap = bus.stats("events/device")
    assert snap.count == 3 and snap.rate_hz == pytest.approx(100.0) and snap.seq_missing == 0
