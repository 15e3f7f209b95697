"""MCAP recording of the bus: one channel per topic with a JSON Schema, log/publish times, metadata,
a bit-exact round trip, and a recorder killed with SIGKILL (with or without the Foxglove channels)
leaves a file readable up to its last chunk."""
from __future__ import annotations

import dataclasses
import json
import signal
import sys
import textwrap
import time

import numpy as np
import pytest
from mcap.reader import make_reader

from ftc_hw.bus import Bus, ContactEvent, DeviceEvent, JointFrame, WrenchFlag, WrenchFrame
from ftc_hw.monitor import MONITOR_INPUT, MONITOR_JUDGED, JudgedFrame, PipelineInput
from ftc_hw.record.reader import RecordingError, read_recording
from ftc_hw.record.writer import McapRecorder

from .killing import kill_when_ready

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

RNG = np.random.default_rng(3)


def frames(n: int):
    out = []
    for k in range(n):
        t = 1_000_000_000 + k * 1_000_000
        out.append(("wrench/ft", WrenchFrame.make(t, RNG.normal(size=6) * 10, source="ft", seq=k, t_device_ns=7 * k + 3,
                                                  flags=WrenchFlag.SATURATED if k % 7 == 0 else 0)))
        if k % 2 == 0:
            out.append(("joints/arm", JointFrame.make(t + 1, RNG.normal(size=3), RNG.normal(size=3), RNG.normal(size=3),
                                                      source="arm", seq=k // 2)))
        out.append((MONITOR_INPUT, PipelineInput(t + 2, 7 * k + 3, k, "ft", RNG.normal(size=6), RNG.normal(size=3),
                                                 RNG.normal(size=3), RNG.normal(size=3), k % 5 == 0, k < 3,
                                                 joint_gap_ns=7_000_000 if k % 4 == 1 else 0)))
        if k % 3 == 0:  # what a monitor asked for its judged frames publishes (ROS outputs)
            out.append((MONITOR_JUDGED, JudgedFrame(t + 2, None, k, "ft", RNG.normal(size=6), float(k), k % 2 == 0)))
    out.append(("events/contact", ContactEvent.make(2_000_000_000, "onset", "link3", [0.1, 0.2, 0.3],
                                                    [1.0, -2.0, 3.5], [0.001, 0.002, 0.003], flags=("ambiguous",),
                                                    probability=0.75)))
    out.append(("events/device", DeviceEvent.make(2_000_000_001, "ft", "stale", "no frame for 0.1 s",
                                                  {"frames": 12})))
    return out


def same(a, b) -> bool:
    for name in ("t_host_ns", "t_device_ns", "seq", "source", "flags", "kind", "link", "probability", "message",
                 "saturated", "tare", "joint_gap_ns", "d2", "in_contact"):
        if getattr(a, name, None) != getattr(b, name, None):
            return False
    for name in ("wrench", "q", "qd", "current", "tau", "point", "force", "point_std", "external"):
        x, y = getattr(a, name, None), getattr(b, name, None)
        if (x is None) != (y is None) or (x is not None and not np.array_equal(x, y)):
            return False
    return dict(getattr(a, "counters", {})) == dict(getattr(b, "counters", {}))


def test_round_trip_is_bit_exact_with_one_channel_per_topic(tmp_path):
    path = tmp_path / "run.mcap"
    bus = Bus()
    sent = frames(300)
    with McapRecorder(bus, path, metadata={"scene": {"name": "leng2016"}}) as rec:
        for topic, f in sent:
            bus.publish(topic, f)
        time.sleep(0.3)
    rec.stop({"events": {"count": "1"}})  # already stopped by the with-block: a no-op
    got = read_recording(path)
    assert got.complete and got.error is None and got.bad_messages == 0
    assert [m.topic for m in got.messages] == [t for t, _ in sent]
    assert all(same(m.frame, f) for m, (_, f) in zip(got.messages, sent, strict=True))
    for m, (_, f) in zip(got.messages, sent, strict=True):
        assert m.log_time == f.t_host_ns
        t_dev = getattr(f, "t_device_ns", None)
        assert m.publish_time == (f.t_host_ns if t_dev is None else t_dev)
    assert got.metadata["scene"] == {"name": "leng2016"}
    assert got.metadata["recorder"]["drops"] == "0"
    # an ordinary MCAP reader sees a complete file: summary, schemas, channels
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    channels = {c.topic: c for c in summary.channels.values()}
    assert set(channels) == {"wrench/ft", "joints/arm", MONITOR_INPUT, MONITOR_JUDGED, "events/contact",
                             "events/device"}
    for c in channels.values():
        schema = summary.schemas[c.schema_id]
        assert c.message_encoding == "json" and schema.encoding == "jsonschema"
        assert json.loads(schema.data)["type"] == "object"
    assert summary.statistics.message_count == len(sent)


def test_a_file_that_is_not_mcap_is_refused(tmp_path):
    bad = tmp_path / "x.mcap"
    bad.write_bytes(b"not an mcap file at all" * 10)
    with pytest.raises(RecordingError):
        read_recording(bad)


RECORDER = textwrap.dedent("""
    import sys, time
    import numpy as np
    from ftc_hw.bus import Bus, WrenchFrame
    from ftc_hw.record.writer import McapRecorder
    from ftc_hw.scene import load_scene

    bus = Bus()
    scene = load_scene("ur5e") if sys.argv[2] == "foxglove" else None
    rec = McapRecorder(bus, sys.argv[1], metadata={"scene": {"name": "ur5e"}}, chunk_size=16 * 1024,
                       flush_s=0.1, scene=scene).start()
    k = 0
    t_end = time.monotonic() + 60
    while time.monotonic() < t_end:
        bus.publish("wrench/ft", WrenchFrame.make(time.monotonic_ns(), np.full(6, float(k)), source="ft", seq=k))
        k += 1
        if k == 1500:
            print("ready", flush=True)
        time.sleep(0.0005)
""")


@pytest.mark.parametrize("view", ["bus", "foxglove"])
def test_a_killed_recorder_leaves_a_file_readable_up_to_its_last_chunk(tmp_path, view):
    path = tmp_path / "killed.mcap"
    assert kill_when_ready([sys.executable, "-c", RECORDER, str(path), view], 0.5) == -signal.SIGKILL
    got = read_recording(path)
    assert not got.complete and got.error is not None
    seqs = [m.frame.seq for m in got.messages]
    assert len(seqs) >= 1000  # at least what was flushed before "ready"
    assert seqs == list(range(len(seqs)))  # everything up to the cut, in order, nothing lost in between
    assert all(np.array_equal(m.frame.wrench, np.full(6, float(m.frame.seq))) for m in got.messages)
    assert got.metadata["scene"] == {"name": "ur5e"}
    assert (got.view_messages > 0) == (view == "foxglove")  # the wrench's Foxglove messages, cut likewise
    with open(path, "rb") as f, pytest.raises(Exception):  # noqa: B017 - no footer: the summary reader fails
        list(make_reader(f).iter_messages())


def test_a_pipeline_input_recorded_before_joint_gaps_were_kept_reads_as_no_gap():
    import json

    from ftc_hw.record.schemas import decode, encode

    inp = PipelineInput(5, None, 1, "ft", np.zeros(6), np.zeros(3), np.zeros(3), np.zeros(3), joint_gap_ns=9_000_000)
    name, data = encode(inp)
    assert decode(name, data).joint_gap_ns == 9_000_000
    old = json.loads(data)
    del old["joint_gap_ns"]
    assert decode(name, json.dumps(old).encode()).joint_gap_ns == 0


def test_messages_with_non_finite_numbers_or_numpy_scalars_keep_their_values():
    """orjson writes NaN as null and refuses NumPy scalars: such messages are written by json, as before."""
    from ftc_hw.record.schemas import decode, encode

    ev = DeviceEvent.make(7, "ft", "error", "stalled", {"lost": float("nan"), "rate": float("inf"), "n": 3})
    name, data = encode(ev)
    assert b"NaN" in data and b"Infinity" in data
    got = decode(name, data)
    assert np.isnan(got.counters["lost"]) and got.counters["rate"] == float("inf") and got.counters["n"] == 3.0
    ce = ContactEvent.make(9, "onset", "wrist_3_link", [0.1, 0.2, 0.3], [1.0, 2.0, 3.0], [1e-3] * 3, probability=0.9)
    name, data = encode(dataclasses.replace(ce, duration_s=np.float64(0.125)))  # past make's float()
    assert decode(name, data).duration_s == 0.125
    inp = PipelineInput(5, None, 1, "ft", np.array([0.1, 1e-300, -2.5e17, 1 / 3, 0.0, -0.0]), np.zeros(3),
                        np.zeros(3), np.zeros(3))
    name, data = encode(inp)
    back = decode(name, data)
    assert back.wrench.tobytes() == inp.wrench.tobytes()  # bit for bit, -0.0 included
    assert json.loads(data) == json.loads(json.dumps(json.loads(data)))  # plain JSON
