"""The recorder in its own process (``ftc monitor --record``): frames handed over as columns come back
bit for bit and in order; a writer that cannot start, dies, or outlives a killed monitor is said, and
the file holds what reached it."""
from __future__ import annotations

import dataclasses
import signal
import sys
import textwrap
import time

import numpy as np
import pytest

from ftc_hw.bus import Bus, ContactEvent, DeviceEvent, JointFrame, WrenchFlag, WrenchFrame
from ftc_hw.monitor import MONITOR_INPUT, MONITOR_JUDGED, JudgedFrame, PipelineInput
from ftc_hw.record.reader import read_recording
from ftc_hw.record.writer_process import RecorderProcess, pack, unpack

from .killing import kill_when_ready

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others


def _frames(n: int, rng: np.random.Generator) -> list:
    out: list = []
    for i in range(n):
        t = 10**12 + i * 142_857
        w = rng.normal(size=6) * 10.0 ** rng.integers(-8, 8, size=6)
        out.append(WrenchFrame.make(t, w, source="ft", seq=i, t_device_ns=None if i % 5 == 0 else t - 7,
                                    flags=WrenchFlag.SATURATED if i % 7 == 0 else WrenchFlag.NONE))
        out.append(PipelineInput(t, t - 7, i, "ft", w, rng.normal(size=6), rng.normal(size=6), rng.normal(size=6),
                                 saturated=i % 3 == 0, tare=i < 3, joint_gap_ns=i))
        out.append(JudgedFrame(t, t - 7, i, "ft", rng.normal(size=6), float(i), i % 2 == 0))
        if i % 10 == 0:
            out.append(JointFrame.make(t, rng.normal(size=6), rng.normal(size=6), rng.normal(size=6), source="arm",
                                       seq=i // 10, t_device_ns=t))
        if i == 40:
            out.append(DeviceEvent.make(t, "ft", "error", "stalled", {"lost": float("nan"), "n": 3}))
            out.append(ContactEvent.make(t, "onset", "wrist_3_link", [0.1, 0.2, 0.3], [1.0, -2.0, 3.0], [1e-3] * 3))
    return out


def _same(a, b) -> bool:
    if type(a) is not type(b):
        return False
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            if np.asarray(y).tobytes() != x.tobytes():
                return False
        elif f.name == "counters":  # as floats in the recording, either way (NaN compared by its text)
            if {k: repr(float(v)) for k, v in x.items()} != {k: repr(float(v)) for k, v in y.items()}:
                return False
        elif x != y or type(x) is not type(y):
            return False
    return True


def test_a_batch_comes_back_bit_for_bit_in_order():
    frames = _frames(300, np.random.default_rng(3))
    back = unpack(pack(frames))
    assert len(back) == len(frames) and all(_same(a, b) for a, b in zip(frames, back, strict=True))


def test_odd_shapes_go_as_json_and_unknown_kinds_come_back_as_none():
    frames = _frames(5, np.random.default_rng(4))
    odd = dataclasses.replace(frames[1], q=np.zeros(7))  # one input with a longer q than the others
    back = unpack(pack([*frames, odd, object()]))
    assert all(_same(a, b) for a, b in zip([*frames, odd], back, strict=False)) and back[-1] is None


def _topic(f) -> str:
    return {WrenchFrame: "wrench/ft", PipelineInput: MONITOR_INPUT, JudgedFrame: MONITOR_JUDGED,
            JointFrame: "joints/arm", DeviceEvent: "events/device", ContactEvent: "events/contact"}[type(f)]


def test_what_the_bus_carried_is_in_the_file(tmp_path):
    frames = _frames(3000, np.random.default_rng(5))
    bus = Bus()
    path = tmp_path / "run.mcap"
    with RecorderProcess(bus, path, metadata={"scene": {"name": "ur5e"}}, poll_s=0.005) as rec:
        for f in frames:
            bus.publish(_topic(f), f)
    assert rec.error is None and rec.drops == 0 and rec.lost == 0
    got = read_recording(path)
    assert got.complete and got.metadata["scene"] == {"name": "ur5e"}
    assert sum(rec.counts.values()) == len(frames) == len(got.messages)
    assert all(_same(a, m.frame) for a, m in zip(frames, got.messages, strict=True))


def test_a_file_that_cannot_be_written_is_refused_at_the_start(tmp_path):
    with pytest.raises(OSError, match="cannot write"):
        RecorderProcess(Bus(), tmp_path / "no" / "such" / "dir" / "x.mcap").start()


def test_a_writer_that_dies_is_said_and_what_it_missed_is_counted(tmp_path):
    bus = Bus()
    rec = RecorderProcess(bus, tmp_path / "run.mcap", poll_s=0.005).start()
    bus.publish("wrench/ft", WrenchFrame.make(1, np.zeros(6), source="ft", seq=0))
    time.sleep(0.3)
    rec._proc.kill()
    rec._proc.join(5)
    for k in range(1, 200):
        bus.publish("wrench/ft", WrenchFrame.make(1 + k, np.zeros(6), source="ft", seq=k))
        time.sleep(0.001)
    rec.stop()
    assert rec.error is not None and "gone" in rec.error
    assert rec.lost > 0 and rec.counts["wrench/ft"] + rec.lost == 200


MONITOR = textwrap.dedent("""
    import sys, time
    import numpy as np
    from ftc_hw.bus import Bus, WrenchFrame
    from ftc_hw.record.writer_process import RecorderProcess

    if __name__ == "__main__":
        bus = Bus()
        rec = RecorderProcess(bus, sys.argv[1], metadata={"scene": {"name": "ur5e"}}, poll_s=0.005).start()
        k = 0
        while True:
            bus.publish("wrench/ft", WrenchFrame.make(time.monotonic_ns(), np.full(6, float(k)), source="ft", seq=k))
            k += 1
            if k == 1500:
                print("ready", flush=True)
            time.sleep(0.0005)
""")


def test_a_killed_monitor_leaves_the_writer_to_finish_the_file(tmp_path):
    path, script = tmp_path / "killed.mcap", tmp_path / "monitor.py"
    script.write_text(MONITOR)
    assert kill_when_ready([sys.executable, str(script), str(path)], 0.3) == -signal.SIGKILL
    end = time.monotonic() + 10
    while time.monotonic() < end and not read_recording(path).complete:
        time.sleep(0.1)
    got = read_recording(path)
    assert got.complete  # the writer saw its pipe close and wrote the footer
    seqs = [m.frame.seq for m in got.messages]
    assert len(seqs) >= 1500 and seqs == list(range(len(seqs)))
    assert got.metadata["recorder"]["drops"] == "0"
