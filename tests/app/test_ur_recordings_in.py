"""Users' UR recordings in, the way a user runs them: UR-format CSV files (UR's RTDE client's and
ur_rtde's, with bad rows, at 500 Hz and at about 100 Hz with jittered steps) written from a drawn
("typical") ur10e world, then ``ftc identify FILE... --scene ur10e`` and ``ftc replay FILE --scene ur10e``
(tests/ur_world_csv.py writes them; tests/record/test_ur_csv_emulated.py records the same formats from
the emulated arm through ur_rtde)."""
from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest

from ftc_hw.calibration.file import load_calibration
from ftc_hw.record.ur_csv import UR_CLIENT, UR_RTDE
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world import with_reality
from tests.ur_world_csv import run_world, thinned, write_with_bad_rows

pytestmark = pytest.mark.compute  # the world runs in this process; nothing is timed

SCENE = load_scene("ur10e")
WORLD = with_reality(SCENE, "typical", seed=3)


def ftc(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ftc_hw", *args], capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def excitation_files(tmp_path_factory):
    """40 s of the planned excitation, as two files: ur_rtde's at 500 Hz, UR's client's thinned to ~100 Hz."""
    folder = tmp_path_factory.mktemp("ur-csv")
    run = run_world(SCENE, WORLD, "excitation", 40.0, seed=1)
    half = len(run.columns["timestamp"]) // 2
    first = {k: v[:half] for k, v in run.columns.items()}
    second = thinned({k: v[half:] for k, v in run.columns.items()}, np.random.default_rng(0))
    a, b = folder / "rtde.csv", folder / "client.csv"
    return folder, [(a, write_with_bad_rows(a, first, style=UR_RTDE)), (b, write_with_bad_rows(b, second,
                                                                                                   style=UR_CLIENT))]


@pytest.fixture(scope="module")
def identified(excitation_files):
    """``ftc identify`` on both files: (its output, the calibration file)."""
    folder, files = excitation_files
    out = folder / "cal.toml"
    proc = ftc("identify", *(str(p) for p, _ in files), "--scene", "ur10e", "--sensing", "currents",
               "--out", str(out))
    return proc, out


def test_ftc_identify_takes_several_ur_recordings_skips_their_bad_rows_and_finds_the_drawn_arm(excitation_files,
                                                                                              identified):
    _, files = excitation_files
    proc, out = identified
    text = proc.stdout + proc.stderr
    assert proc.returncode in (0, 4), text[-3000:]  # 4: poorly excited (some inertial parameter untold)
    flat = " ".join(text.split())  # rich wraps at the terminal's width
    for path, bad in files:  # what each file holds is said, its bad rows counted and skipped
        line = flat.split(path.name + ":", 1)[1][:600]
        for reason in bad:
            assert reason.replace("_", " ") in line, line
    rates = sorted(float(hz) for hz in re.findall(r" s at ([0-9.]+) Hz", flat))
    assert len(rates) == 2 and 80.0 <= rates[0] <= 120.0 and rates[1] == 500.0, rates  # ~100 Hz, jittered; 500 Hz
    cal = load_calibration(out, scene=SCENE)
    kt = cal.identification.joints["torque_constant"]
    true_kt = WORLD.world.torque_constant if WORLD.world.torque_constant is not None else SCENE.robot.torque_constant
    # the joints whose links load their motors tell their torque constants (the wrists' load little)
    err = np.abs(kt - true_kt) / true_kt
    assert np.all(err[:4] < 0.05), (kt, true_kt)


def test_a_recording_without_the_currents_the_scene_uses_is_refused_by_name(tmp_path):
    run = run_world(SCENE, SCENE, "hold", 0.5, seed=0)
    cols = {k: v for k, v in run.columns.items() if k != "actual_current"}
    path = tmp_path / "nocurrent.csv"
    write_with_bad_rows(path, cols)
    proc = ftc("identify", str(path), "--scene", "ur10e", "--sensing", "currents", "--out", str(tmp_path / "c.toml"))
    assert proc.returncode == 1 and "no actual_current column" in " ".join((proc.stdout + proc.stderr).split())
    proc = ftc("identify", str(path), "--out", str(tmp_path / "c.toml"))
    assert proc.returncode == 2 and "give --scene" in proc.stderr


def _onsets(text: str) -> int:
    return int(re.search(r"'onset': (\d+)", " ".join(text.split())).group(1))  # rich wraps its lines


@pytest.mark.parametrize("calibrated", [False, True])
def test_ftc_replay_judges_a_ur_recording_no_onset_when_free_one_per_contact(excitation_files, identified,
                                                                            calibrated):
    folder, _ = excitation_files
    proc, out = identified
    assert out.is_file(), proc.stdout[-2000:]
    cal = ["--calibration", str(out)] if calibrated else []
    free = run_world(SCENE, WORLD, "sweep", 8.0, seed=4)
    path = folder / "free.csv"
    write_with_bad_rows(path, free.columns, style=UR_RTDE)
    proc = ftc("replay", str(path), "--scene", "ur10e", *cal, "--view", "none")
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0, text[-3000:]
    assert "sensing used: flange_ft + currents" in " ".join(text.split()) and _onsets(text) == 0, text[-2000:]
    hit = run_world(SCENE, WORLD, "sweep-with-collision", 10.0, seed=4)
    episodes = int(np.sum(np.diff(hit.contact.astype(int)) == 1))
    assert episodes >= 1
    path, events = folder / "hit.csv", folder / "events.jsonl"
    write_with_bad_rows(path, thinned(hit.columns, np.random.default_rng(1)), style=UR_CLIENT)
    proc = ftc("replay", str(path), "--scene", "ur10e", *cal, "--view", "none", "--events", str(events))
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0, text[-3000:]
    assert _onsets(text) == episodes, (episodes, text[-2000:])
    assert events.read_text().count('"onset"') == episodes
