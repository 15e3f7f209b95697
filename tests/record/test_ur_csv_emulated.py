"""UR recordings of the emulated arm as users make them (tests/record/ur_recording.py: 2 s of ur5e's
sweep through ur_rtde): ur_rtde's own file recording and UR's client format written from what
ur_rtde received read back to the world's joint samples; the bad rows real logs have are counted and
skipped in both."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.record.ur_csv import UR_CLIENT, UR_RTDE, parse_ur_csv, read_ur_csv, ur_csv_text
from tests.record.ur_recording import record_emulated_arm, with_bad_rows

pytestmark = pytest.mark.realtime  # the world, the emulator and ur_rtde against the wall clock

HALF_LSB = 5e-7 * (1 + 1e-9)  # ur_rtde prints 6 decimals


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    return record_emulated_arm(tmp_path_factory.mktemp("ur"), seconds=2.0)


def test_ur_rtdes_own_file_reads_back_to_the_world(recorded):
    rec = read_ur_csv(recorded.ur_rtde_csv)
    world = {round(j.t * 1e6): j for j in recorded.world}
    assert rec.format == UR_RTDE and rec.sensing == {"currents", "flange_ft"}
    # t is the controller's time: 2 ms a sample at 500 Hz (more where the loaded host missed some)
    steps = np.diff(rec.t) / 0.002
    assert np.all(steps >= 1 - 1e-6) and np.abs(steps - np.round(steps)).max() < 1e-3
    assert rec.rate_hz == pytest.approx(1 / np.median(np.diff(rec.t)), rel=1e-9)
    assert set(rec.skipped) <= {"time_repeated"}  # its recorder writes the newest state on its own timer
    assert len(rec.t) > 20
    # each row is the world's sample at its timestamp; a few may hold the next sample's values (the
    # recorder reads the fields one by one while the next state arrives)
    matches = []
    for i, t in enumerate(rec.t):
        now, after = world[round(t * 1e6)], world.get(round(t * 1e6) + 2000)
        same = [np.abs(rec.q[i] - j.q).max() <= HALF_LSB and np.abs(rec.current[i] - j.current).max() <= HALF_LSB
                and np.abs(rec.qd[i] - j.qd).max() <= HALF_LSB for j in (now, after) if j is not None]
        assert any(same), f"row at line {rec.line[i]} is neither the world's sample at t={t} nor the next"
        matches.append(same[0])
    assert np.mean(matches) > 0.95


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
    assert all(np.array_equal(world[round(t * 1e6)].current, c) for t, c in zip(rec.t, rec.current, strict=True))


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
