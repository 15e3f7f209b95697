"""Recordings made by an earlier version (ftc-hw at 4270665, before the pipeline's settings became one
typed object) replay to their recorded events, bit for bit, and the CLI says so.

- ``ur5e-typical-identified.mcap``: ``ftc monitor --scene ur5e --sim --reality typical --calibration
  cal.toml --duration 6 --record ...``, the calibration identified offline from 60 s of the typical
  world's sweep (bias, payload, gain, contact gain, inertials, joints, model error: every correction
  the calibration file carries).
- ``dxl-arm-ideal.mcap``: ``ftc monitor --scene dxl-arm --sim --duration 8 --record ...`` (ideal
  world, no calibration: the settings hold only the compensation level).
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from ftc_hw.record.reader import read_recording
from ftc_hw.record.replay import ReplayError, replay

pytestmark = pytest.mark.compute  # replays as fast as it goes: nothing against the wall clock

DATA = Path(__file__).parent.parent / "data" / "recordings"
RECORDINGS = {"ur5e-typical-identified.mcap": (1, 50), "dxl-arm-ideal.mcap": (2, 109)}  # onsets, events


@pytest.mark.parametrize("name", sorted(RECORDINGS))
def test_an_earlier_recording_replays_to_its_events(name):
    result = replay(read_recording(DATA / name))
    onsets, events = RECORDINGS[name]
    assert len(result.recorded) == events
    assert sum(getattr(e, "kind", "") == "onset" for e in result.recorded) == onsets
    assert result.identical, result.first_difference()


def test_ftc_replay_check_says_identical_on_an_earlier_recording():
    proc = subprocess.run([sys.executable, "-m", "ftc_hw", "replay", str(DATA / "dxl-arm-ideal.mcap"), "--check",
                           "--view", "none"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "identical to the 109 recorded events" in proc.stdout


def test_a_recording_whose_settings_this_version_cannot_read_names_what():
    rec = read_recording(DATA / "dxl-arm-ideal.mcap")
    rec.metadata["monitor"]["pipeline"] = '{"level": "dynamics", "lag_floor": 0.1}'  # a setting never made
    with pytest.raises(ReplayError, match="dxl-arm-ideal.mcap.*lag_floor.*unknown"):
        replay(rec)
