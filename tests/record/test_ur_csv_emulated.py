"""UR recordings of the emulated arm as users make them (tests/record/ur_recording.py: 2 s of ur5e's
sweep through ur_rtde): ur_rtde's own file recording and UR's client format written from what
ur_rtde received read back to the world's joint samples; the bad rows real logs have are counted and
skipped in both."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.record.ur_csv import UR_CLIENT, UR_RTDE, parse_ur_csv, read_ur_csv, ur_csv_text, write_ur_csv
from tests.record.ur_bad_rows import with_bad_rows
from tests.record.ur_recording import record_emulated_arm

pytestmark = pytest.mark.realtime  # the world, the emulator and ur_rtde against the wall clock

HALF_LSB = 5e-7 * (1 + 1e-9)  # ur_rtde prints 6 decimals


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    return record_emulated_arm(tmp_path_factory.mktemp("ur"), seconds=2.0)


def test_ur_rtdes_own_file_reads_back_to_the_world(recorded):
    rec = read_ur_csv(recorded.ur_rtde_csv)
    world = {round(j.t * 1e6): j for j in recorded.world}
    assert rec.format == UR_RTDE and rec.sensing == {"currents", "flange_ft"}, rec.summary()
    # t is the controller's time: 2 ms a sample at 500 Hz (more where the loaded host missed some)
    steps = np.diff(rec.t) / 0.002
    assert np.all(steps >= 1 - 1e-6) and np.abs(steps - np.round(steps)).max() < 1e-3
    assert rec.rate_hz == pytest.approx(1 / np.median(np.diff(rec.t)), rel=1e-9)
    assert set(rec.skipped) <= {"time_repeated"}  # its recorder writes the newest state on its own timer
    assert len(rec.t) > 20
    # each row is the world's sample at its timestamp, but for a few: ur_rtde's recorder reads the fields
    # one by one, in the file's order, while newer states come in, so a field may hold a later sample's
    seen = [i for i, t in enumerate(rec.t) if round(t * 1e6) in world]  # the ring is short: a loaded host
    assert len(seen) > 0.8 * len(rec.t), (len(seen), len(rec.t))         # may miss a stretch of it
    lags = np.array([[_lag(world, round(rec.t[i] * 1e6), getattr(rec, f)[i], f) for f in ("q", "qd", "current")]
                     for i in seen])
    late = {tuple(r): int(n) for r, n in zip(*np.unique(lags, axis=0, return_counts=True), strict=True)}
    assert (lags >= 0).all(), f"values the world never had at or after the row's time: {late}"
    assert (np.diff(lags, axis=1) >= 0).all(), late  # read in the file's order: q, then qd, then current
    assert (lags == 0).all(axis=1).mean() > 0.9, late


def _lag(world: dict, t_us: int, values: np.ndarray, field: str, packets: int = 25) -> int:
    """In 2 ms packets, how much later than ``t_us`` the world's sample of ``field`` equal to ``values``
    (to ur_rtde's 6 decimals) is; -1 if none within ``packets``."""
    for k in range(packets + 1):
        j = world.get(t_us + 2000 * k)
        if j is not None and np.abs(values - getattr(j, field)).max() <= HALF_LSB:
            return k
    return -1


def test_urs_client_format_from_what_ur_rtde_received(recorded):
    rec = read_ur_csv(recorded.ur_client_csv)
    got = recorded.received
    assert rec.format == UR_CLIENT and rec.skipped == {} and rec.sensing == {"currents", "flange_ft"}
    assert np.array_equal(rec.t, got["timestamp"]) and np.array_equal(rec.q, got["actual_q"])
    assert np.array_equal(rec.current, got["actual_current"])
    assert np.array_equal(rec.ft_raw_wrench, got["ft_raw_wrench"])
    assert np.array_equal(rec.actual_tcp_force, got["actual_TCP_force"])
    assert rec.timing.rate_hz == pytest.approx(1 / np.median(np.diff(got["timestamp"])), rel=1e-9)
    world = {round(j.t * 1e6): j for j in recorded.world}
    seen = [(world[round(t * 1e6)], c) for t, c in zip(rec.t, rec.current, strict=True) if round(t * 1e6) in world]
    assert len(seen) > 0.8 * len(rec.t) and all(np.array_equal(j.current, c) for j, c in seen)


def test_our_writer_of_ur_rtdes_format_writes_what_ur_rtde_writes(recorded):
    """The same header, and the same text for a state (where ur_rtde's row is that one state)."""
    theirs = recorded.ur_rtde_csv.read_text().splitlines()
    ours = ur_csv_text(recorded.received, style=UR_RTDE).splitlines()
    assert ours[0] == theirs[0]
    by_time = {line.split(",")[0]: line for line in theirs[:0:-1]}  # the first row of each timestamp
    common = [line for line in ours[1:] if line.split(",")[0] in by_time]
    assert len(common) > 20
    assert np.mean([by_time[line.split(",")[0]] == line for line in common]) > 0.95


def test_bad_rows_are_counted_and_skipped_in_both(recorded):
    for path in (recorded.ur_rtde_csv, recorded.ur_client_csv):
        text = path.read_text()
        clean = parse_ur_csv(text, path=path)
        bad, expected = with_bad_rows(text, at=len(clean.t) // 2)
        rec = parse_ur_csv(bad, path=path)
        assert rec.skipped - clean.skipped == expected and clean.skipped - rec.skipped == {}
        assert np.array_equal(rec.t, clean.t) and np.array_equal(rec.q, clean.q)


def test_resampled_to_100_hz_with_jittered_steps(recorded, tmp_path):
    """What real UR logs look like (about 100 Hz, steps of 8 to 34 ms), from the emulated arm's data:
    the reader reports that rate and spread, not 500 Hz."""
    got = recorded.received
    t = got["timestamp"]
    rng = np.random.default_rng(3)
    steps = np.where(rng.random(400) < 0.9, rng.uniform(0.008, 0.012, 400), rng.uniform(0.012, 0.034, 400))
    times = t[0] + np.cumsum(steps)
    times = times[times <= t[-1]]
    cols = {"timestamp": times}
    for name in ("actual_q", "actual_qd", "actual_current", "ft_raw_wrench"):
        cols[name] = np.column_stack([np.interp(times, t, got[name][:, j]) for j in range(6)])
    rec = read_ur_csv(write_ur_csv(tmp_path / "slow.csv", cols))
    used = np.diff(times)
    assert rec.rate_hz == pytest.approx(1 / np.median(used), rel=1e-9) and 80 < rec.rate_hz < 110
    assert rec.timing.min_s == pytest.approx(used.min(), rel=1e-9) and rec.timing.min_s >= 0.008
    assert rec.timing.max_s == pytest.approx(used.max(), rel=1e-9) and rec.timing.max_s <= 0.034
    assert rec.skipped == {} and rec.sensing == {"currents", "flange_ft"}
