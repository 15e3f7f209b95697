"""Users' UR recordings in (ftc_hw.record.ur_csv), on written files: both formats told from their
content, the columns read in SI units, the sensing the columns allow, bad rows counted by reason and
never used, timing from 500 Hz down to 100 Hz with jittered steps, malformed files refused by name and
line. ``tests/data/recordings/ur5e-sweep-ur_rtde.csv`` was written by ur_rtde 1.6.5's own
``startFileRecording`` from the emulated ur5e (tests/record/ur_recording.py; 120 rows as written, from
the middle of a 2 s recording): the real format."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ftc_hw.record.reader import RecordingError
from ftc_hw.record.ur_csv import (
    UR_CLIENT,
    UR_RTDE,
    PhysicalBounds,
    URCsvError,
    parse_ur_csv,
    read_ur_csv,
    read_ur_csvs,
    ur_csv_text,
    write_ur_csv,
)
from tests.record.ur_bad_rows import with_bad_rows

pytestmark = pytest.mark.compute  # files written and read: nothing against the wall clock

SAMPLE = Path(__file__).parent.parent / "data" / "recordings" / "ur5e-sweep-ur_rtde.csv"


def arm_columns(times: np.ndarray, *, ft: bool = True, current: bool = True) -> dict[str, np.ndarray]:
    """A UR arm's fields at ``times`` (s): a smooth motion, currents, temperatures, wrenches, and fields
    the reader does not use (integers among them), in the order UR's record_configuration.xml has."""
    k = np.arange(1, 7)
    q = 0.8 * np.sin(np.outer(times, 0.3 * k) + k)
    qd = 0.8 * 0.3 * k * np.cos(np.outer(times, 0.3 * k) + k)
    cols = {"timestamp": times, "target_current": 1.5 * np.sin(q)}
    cols["target_moment"] = 13.0 * cols["target_current"]
    cols["actual_q"], cols["actual_qd"] = q, qd
    if current:
        cols["actual_current"] = cols["target_current"] + 0.01 * np.cos(3 * q)
    cols["actual_TCP_pose"] = np.cos(q)
    cols["actual_TCP_force"] = np.column_stack([5 * np.sin(q[:, :3]), 0.5 * np.cos(q[:, 3:])])
    cols["joint_temperatures"] = 33.0 + 0.1 * np.sin(q)
    cols["robot_mode"] = np.full(len(times), 7)
    cols["joint_mode"] = np.full((len(times), 6), 253)
    if ft:
        cols["ft_raw_wrench"] = np.column_stack([2 * np.cos(q[:, :3]), 0.2 * np.sin(q[:, 3:])])
    return cols


def at_500hz(seconds: float = 2.0, t0: float = 1234.5) -> np.ndarray:
    return t0 + np.arange(round(seconds * 500)) * 0.002


@pytest.mark.parametrize("style", [UR_CLIENT, UR_RTDE])
def test_each_format_reads_back_what_was_written(tmp_path, style):
    cols = arm_columns(at_500hz())
    rec = read_ur_csv(write_ur_csv(tmp_path / "run.csv", cols, style=style))
    exact = 0.0 if style == UR_CLIENT else 5e-7  # repr round-trips; ur_rtde prints 6 decimals
    assert rec.format == style and rec.n_joints == 6 and rec.rows == len(rec.t) == 1000
    for got, want in ((rec.t, cols["timestamp"]), (rec.q, cols["actual_q"]), (rec.qd, cols["actual_qd"]),
                      (rec.current, cols["actual_current"]), (rec.ft_raw_wrench, cols["ft_raw_wrench"]),
                      (rec.actual_tcp_force, cols["actual_TCP_force"]), (rec.target_current, cols["target_current"]),
                      (rec.target_moment, cols["target_moment"]),
                      (rec.joint_temperatures, cols["joint_temperatures"])):
        assert np.abs(got - want).max() <= exact * (1 + 1e-9)
    assert rec.skipped == {} and rec.rate_hz == pytest.approx(500.0, rel=1e-6)
    assert rec.sensing == {"currents", "flange_ft"}
    assert list(rec.line[:2]) == [2, 3]


def test_the_format_is_told_from_the_content_not_the_name(tmp_path):
    cols = arm_columns(at_500hz(0.1))
    client = tmp_path / "ur_rtde_recording.csv"  # names that say the other format
    rtde = tmp_path / "robot_data.txt"
    client.write_text(ur_csv_text(cols, style=UR_CLIENT))
    rtde.write_text(ur_csv_text(cols, style=UR_RTDE))
    assert read_ur_csv(client).format == UR_CLIENT and read_ur_csv(rtde).format == UR_RTDE
    bom = tmp_path / "saved_by_an_editor.csv"  # a byte-order mark before the header
    bom.write_text("\ufeff" + ur_csv_text(cols, style=UR_RTDE), encoding="utf-8")
    assert np.array_equal(read_ur_csv(bom).t, read_ur_csv(rtde).t)


def test_urs_client_writer_form_exactly(tmp_path):
    """csv.writer(delimiter=" ") as rtde/csv_writer.py: \\r\\n line ends, Python's str of each value."""
    text = ur_csv_text({"timestamp": np.array([0.002, 0.004]), "actual_q": np.full((2, 6), 0.1),
                        "robot_mode": np.array([7, 7])}, style=UR_CLIENT)
    header, first = text.split("\r\n")[:2]
    assert header == "timestamp " + " ".join(f"actual_q_{j}" for j in range(6)) + " robot_mode"
    assert first == "0.002 " + "0.1 " * 6 + "7"


def test_the_real_ur_rtde_file_is_read_and_our_ur_rtde_writer_reproduces_it():
    """The sample ur_rtde itself wrote: its repeated rows (its recorder samples the newest state on its
    own timer) are counted; our writer of its format, given the values, writes the same text."""
    rec = read_ur_csv(SAMPLE)
    lines = SAMPLE.read_text().splitlines()
    header = lines[0].split(",")
    assert rec.format == UR_RTDE and rec.sensing == {"currents", "flange_ft"} and rec.n_joints == 6
    t = [float(line.split(",")[0]) for line in lines[1:]]
    assert rec.skipped == ({"time_repeated": len(t) - len(set(t))} if len(set(t)) < len(t) else {})
    assert np.all(np.diff(rec.t) > 0) and len(rec.t) == len(set(t))
    q0 = header.index("actual_q_0")
    assert rec.q[0, 0] == float(lines[1].split(",")[q0])
    values = {name: [] for name in header}
    for line in lines[1:]:
        for name, token in zip(header, line.split(","), strict=True):
            values[name].append(int(token) if "." not in token else float(token))
    again = ur_csv_text({n: np.array(v) for n, v in values.items()}, style=UR_RTDE)
    assert again == SAMPLE.read_text()


@pytest.mark.parametrize("style", [UR_CLIENT, UR_RTDE])
def test_bad_rows_are_counted_by_reason_and_never_used(style):
    clean = ur_csv_text(arm_columns(at_500hz(0.4)), style=style)
    text, expected = with_bad_rows(clean, at=20)
    lines = text.splitlines(keepends=True)
    sep = "," if style == UR_RTDE else " "
    header = lines[0].strip().split(sep)
    row = lines[40].rstrip("\r\n").split(sep)
    end = lines[40][len(lines[40].rstrip("\r\n")):]

    def variant(col: str, value: str, r: list[str] = row) -> str:
        r = list(r)
        r[header.index(col)] = value
        return sep.join(r) + end

    more = [variant("actual_current_2", "inf"), variant("actual_current_0", "1000.0"),  # 1000 A: not physical
            variant("ft_raw_wrench_4", "-nan"), variant("joint_temperatures_1", "abc"),
            sep.join(row + ["0.5"]) + end, "\r\n" if style == UR_CLIENT else "\n",
            variant("timestamp", "1234.0"),  # before the file's first row: time going backwards
            variant("timestamp", "5.0e8")]  # one corrupted time far ahead: the rows after it are used
    lines[41:41] = more
    # a column the reader does not use (actual_TCP_pose) is not checked: that row is used
    lines[50] = variant("actual_TCP_pose_3", "nan", lines[50].rstrip("\r\n").split(sep))
    cut_end = lines[60].rstrip("\r\n")[:30]  # the file ends inside a row: no line end
    rec = parse_ur_csv("".join(lines) + cut_end, path="bad.csv")
    expected = {**expected, "not_finite:actual_current": 1, "out_of_range:actual_current": 1,
                "not_finite:ft_raw_wrench": 1, "unparsable:joint_temperatures": 1, "too_many_fields": 1,
                "blank": 1, "time_backwards": 1, "unterminated": 1, "time_jump": 1}
    assert dict(rec.skipped) == expected
    good = parse_ur_csv(clean, path="clean.csv")  # every clean row kept, none of the bad ones
    for name in ("t", "q", "qd", "current", "ft_raw_wrench", "joint_temperatures", "target_moment"):
        assert np.array_equal(getattr(rec, name), getattr(good, name)), name
    assert rec.rows == len(lines)  # data lines: all but the header, and the unterminated one
    assert rec.skipped_by_reason()["not_finite"] == 3
    assert "skipped:" in rec.summary() and "1 cut short" in rec.summary()


def test_jittered_100_hz_timing_is_reported(tmp_path):
    """Real UR logs found in public repositories: about 100 Hz, steps of 8 to 34 ms. Resampled here from
    the 500 Hz motion: most steps 8-12 ms, one in ten 12-34 ms."""
    rng = np.random.default_rng(7)
    steps = np.where(rng.random(3000) < 0.9, rng.uniform(0.008, 0.012, 3000), rng.uniform(0.012, 0.034, 3000))
    times = 50.0 + np.concatenate([[0.0], np.cumsum(steps)])
    dense = arm_columns(at_500hz(40.0, t0=50.0))
    cols = {name: (np.column_stack([np.interp(times, dense["timestamp"], v[:, j]) for j in range(v.shape[1])])
                   if v.ndim == 2 else np.interp(times, dense["timestamp"], v)) if v.dtype.kind == "f"
            else v[: len(times)] for name, v in dense.items()}
    rec = read_ur_csv(write_ur_csv(tmp_path / "slow.csv", cols))
    assert rec.timing.rate_hz == pytest.approx(1 / np.median(steps), rel=1e-9)
    assert 90 < rec.rate_hz < 105
    assert rec.timing.min_s == pytest.approx(steps.min(), rel=1e-9)
    assert rec.timing.max_s == pytest.approx(steps.max(), rel=1e-9)
    assert rec.timing.jitter_s == pytest.approx(np.std(steps), rel=1e-6)
    assert rec.timing.max_s > 0.03 and rec.skipped == {}
    assert f"at {rec.rate_hz:.1f} Hz" in rec.summary()


def test_the_sensing_follows_the_columns(tmp_path):
    times = at_500hz(0.1)
    cases = {"both": ({}, {"currents", "flange_ft"}), "no_ft": ({"ft": False}, {"currents"}),
             "no_current": ({"current": False}, {"flange_ft"}),
             "neither": ({"ft": False, "current": False}, set())}
    for name, (kw, kinds) in cases.items():
        rec = read_ur_csv(write_ur_csv(tmp_path / f"{name}.csv", arm_columns(times, **kw)))
        assert rec.sensing == kinds, name
        assert (rec.current is None) == ("currents" not in kinds)
    assert "sensing: none (joint state only)" in rec.summary()


def test_several_files_at_once(tmp_path):
    a = write_ur_csv(tmp_path / "a.csv", arm_columns(at_500hz(0.2)))
    b = write_ur_csv(tmp_path / "b.csv", arm_columns(at_500hz(0.3, t0=10.0)), style=UR_RTDE)
    recs = read_ur_csvs([b, a])
    assert [r.path for r in recs] == [b, a] and [r.format for r in recs] == [UR_RTDE, UR_CLIENT]
    bad = tmp_path / "bad.csv"
    bad.write_text("timestamp actual_q_0\r\n")
    with pytest.raises(URCsvError, match="bad.csv:1: no actual_qd_0"):
        read_ur_csvs([a, bad])
    with pytest.raises(URCsvError, match="no recording given"):
        read_ur_csvs([])


@pytest.mark.parametrize("case", ["empty", "numbers", "no_timestamp", "no_qd", "short_vector", "binary",
                                  "twice", "no_rows", "missing"])
def test_malformed_files_raise_a_typed_error_naming_file_and_line(tmp_path, case):
    cols = arm_columns(at_500hz(0.02))
    body = ur_csv_text(cols)
    header, rows = body.split("\r\n", 1)
    texts = {
        "empty": ("", r"empty.csv:1: no header line"),
        "numbers": (rows, r"numbers.csv:1: no header: the first line holds numbers"),
        "no_timestamp": (header.replace("timestamp", "time_stamp") + "\r\n" + rows,
                         r"no_timestamp.csv:1: no 'timestamp'"),
        "no_qd": (header.replace("actual_qd", "target_qdd") + "\r\n" + rows, r"no_qd.csv:1: no actual_qd_0"),
        "short_vector": (header.replace("actual_q_5", "actual_x_5") + "\r\n" + rows,
                         r"short_vector.csv:1: actual_q: 5 columns actual_q_0 .. actual_q_4, RTDE has 6"),
        "binary": (header + "\nDOUBLE DOUBLE DOUBLE\n\x00\x01", r"binary.csv:2: RTDE's binary recording"),
        "twice": (header + " robot_mode\r\n" + rows, r"twice.csv:1: column 'robot_mode' twice"),
        "no_rows": (header + "\r\n", r"no_rows.csv: 0 usable rows of 0"),
        "missing": (None, r"missing.csv: cannot read"),
    }
    text, message = texts[case]
    path = tmp_path / f"{case}.csv"
    if text is not None:
        path.write_text(text, newline="")
    with pytest.raises(URCsvError, match=message) as err:
        read_ur_csv(path)
    assert isinstance(err.value, RecordingError) and err.value.path == str(path)


def test_bounds_are_settings():
    cols = arm_columns(at_500hz(0.4))
    per_row = np.maximum(np.abs(cols["actual_current"]), np.abs(cols["target_current"])).max(axis=1)
    limit = float(np.median(per_row))
    text = ur_csv_text(cols)
    strict = parse_ur_csv(text, path="x.csv", bounds=PhysicalBounds(current_a=limit))
    loose = parse_ur_csv(text, path="x.csv")
    assert loose.skipped == {} and len(loose.t) == len(per_row)
    assert sum(strict.skipped.values()) == (per_row > limit).sum() > 0
    assert set(strict.skipped) <= {"out_of_range:actual_current", "out_of_range:target_current"}
    assert np.array_equal(strict.t, cols["timestamp"][per_row <= limit])
