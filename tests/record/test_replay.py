"""Record a monitor run on emulated devices, then replay it: the same pipeline on the recorded inputs
gives the recorded events, bit for bit; another setting gives other events (the comparison can fail).
The run's Foxglove channels are valid and put every contact marker on its event's point."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from mcap.reader import make_reader

from ftc_hw.monitor import MONITOR_INPUT
from ftc_hw.pipeline import PipelineSettings
from ftc_hw.record.events import read_events
from ftc_hw.record.reader import read_recording
from ftc_hw.record.replay import replay
from tests.record.foxglove_check import contact_markers_in_base, read_foxglove

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others


def ftc(*args: str, timeout: float = 180) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ftc_hw", *args], capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory, clean_or_loaded):
    d = tmp_path_factory.mktemp("rec")
    proc = ftc("monitor", "--scene", "dxl-arm", "--sim", "--duration", "4", "--record", str(d / "run.mcap"),
               "--events", str(d / "events.jsonl"), "--no-view")
    clean_or_loaded(proc.returncode, proc.stdout + proc.stderr)
    return d


def test_the_recording_has_one_channel_per_topic_and_the_run_as_metadata(recorded):
    with open(recorded / "run.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    topics = {c.topic for c in summary.channels.values()}
    assert {"wrench/ft", "joints/arm", MONITOR_INPUT, "events/contact", "events/device"} <= topics
    assert all(summary.schemas[c.schema_id].encoding == "jsonschema" and c.message_encoding == "json"
               for c in summary.channels.values())
    assert {"foxglove/tf", "foxglove/arm", "foxglove/contacts", "foxglove/wrench"} <= topics
    assert metadata["scene"]["name"] == "dxl-arm" and "[[devices]]" in metadata["scene"]["toml"]
    assert metadata["monitor"]["ft_source"] == "ft" and metadata["monitor"]["sim"] == "True"
    settings = PipelineSettings.from_json(metadata["monitor"]["pipeline"])
    assert settings.to_json() == PipelineSettings().with_level("dynamics").to_json()
    events = read_events(recorded / "events.jsonl")
    contacts = [e for e in events if "contact_id" in e]  # the file has the run's device events too
    assert [json.loads(line) for line in metadata["events"]["jsonl"].splitlines()] == contacts
    assert any(e["kind"] == "onset" for e in events)


def test_replay_reproduces_the_recorded_events_exactly(recorded):
    out = recorded / "replayed.jsonl"
    proc = ftc("replay", str(recorded / "run.mcap"), "--speed", "0", "--check", "--events", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "identical" in proc.stdout
    assert out.read_text() == (recorded / "events.jsonl").read_text()


def test_replay_with_another_setting_gives_other_events(recorded):
    rec = read_recording(recorded / "run.mcap")
    same = replay(rec)
    assert same.identical and same.inputs == len(rec.topic(MONITOR_INPUT))
    other = replay(rec, settings=PipelineSettings().with_level("gravity"))  # the arm's inertia no longer compensated
    assert not other.identical and other.first_difference() is not None


def test_the_recording_shows_each_contact_where_its_event_says_in_foxglove(recorded):
    fox = read_foxglove(recorded / "run.mcap")  # every Foxglove message valid against its schema in the file
    placed = contact_markers_in_base(fox)
    events = [e for e in read_events(recorded / "events.jsonl")
              if "contact_id" in e and "no_estimate" not in e["flags"]]  # contact events: the file has device ones too
    assert len(placed) == len(events) > 0
    for ev, centre, _ in placed:
        assert np.linalg.norm(centre - np.array(ev["point"])) < 1e-3, (ev, centre)
    rec = fox.metadata["recorder"]
    assert rec["foxglove_errors"] == "0"
    skipped = {k for k in rec if k.startswith("foxglove_skipped:")}  # an event without an estimate has no marker
    assert skipped <= {"foxglove_skipped:contact_no_estimate"}
