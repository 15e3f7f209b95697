"""``ftc monitor`` on a cell whose drivers are ROS nodes: ``ftc ros publish`` plays the drivers (the ur5e's
emulated devices in the typical world, read through their client libraries, published as
ur_robot_driver and the F/T broadcaster publish them) in a process of its own, the monitor reads the
topics through a rig file in another. Each process joins the test's private domain, discovery on this host
only (conftest.ros_env): nothing leaves the machine.

The F/T topic arrives at the sensor's 1 kHz without a message missing; the scripted pokes are detected
where they were; the publisher killed in a contact is ``sensor_lost`` and that contact closed, flagged
``lost``."""
from __future__ import annotations

import ast
import json
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from ftc_hw.app.monitor.evaluate import evaluate
from ftc_hw.record.events import read_events, read_truth
from ftc_hw.record.reader import read_recording

from .conftest import UR_RIG, ros_env

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(240)]

def ftc(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "ftc_hw", *args], env=ros_env(), text=True, **kw)


def _events(path) -> list[dict]:
    return read_events(path) if path.exists() else []


def _open_contact(events: list[dict]) -> int | None:
    """The contact id of an onset not yet closed, after at least two onsets."""
    onsets = [e["contact_id"] for e in events if e["kind"] == "onset"]
    closed = {e["contact_id"] for e in events if e["kind"] == "offset"}
    return onsets[-1] if len(onsets) >= 2 and onsets[-1] not in closed else None


def test_a_monitor_reads_the_drivers_topics_and_a_killed_publisher_is_sensor_lost(tmp_path):
    (tmp_path / "ros.toml").write_text(UR_RIG)
    events, truth, rec = tmp_path / "e.jsonl", tmp_path / "truth.jsonl", tmp_path / "r.mcap"
    pub = ftc("ros", "publish", "--scene", "ur5e", "--sim", "--scenario", "static-pokes", "--reality", "typical",
              "--duration", "20", "--truth", str(truth), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    mon = ftc("monitor", "--scene", "ur5e", "--rig", str(tmp_path / "ros.toml"), "--duration", "120", "--events",
              str(events), "--record", str(rec), "--no-view", "--readers", "thread",
              stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        topics = json.loads(pub.stdout.readline())["topics"]
        assert [t["topic"] for t in topics] == ["/joint_states", "/force_torque_sensor_broadcaster/wrench"]
        deadline = time.monotonic() + 120
        while (contact := _open_contact(_events(events))) is None:
            assert time.monotonic() < deadline and pub.poll() is None and mon.poll() is None, "no contact seen"
            time.sleep(0.01)
        pub.kill()
        t_kill_ns = time.monotonic_ns()
        pub.wait(10)
        while not any(e["kind"] == "sensor_lost" for e in _events(events)):
            assert time.monotonic() < deadline and mon.poll() is None, "no sensor_lost"
            time.sleep(0.05)
    finally:
        pub.kill()
        mon.send_signal(signal.SIGTERM)
        out = mon.communicate(timeout=60)[0]
    got = read_events(events)
    report = out[-3000:]
    # the contact open at the kill is closed, flagged lost; the F/T stream was lost after the kill
    offsets = [e for e in got if e["kind"] == "offset" and e["contact_id"] == contact]
    assert len(offsets) == 1 and "lost" in offsets[0]["flags"], report
    lost = next(e for e in got if e["kind"] == "sensor_lost")
    assert lost["t_host_ns"] > t_kill_ns and lost["source"] == "ft", report
    # the F/T topic: every message of the sensor's 1 kHz stream, none missing between the stamps
    counters = ast.literal_eval(re.search(r"ft \(ros-wrench\): (\{.*?\})", " ".join(out.split())).group(1))
    assert counters["frames"] > 1000 and "lost" not in counters and "seq_gaps" not in counters, (counters, report)
    wrenches = read_recording(rec).topic("wrench/ft")
    stamps = np.array([w.t_device_ns for w in wrenches], dtype=np.int64)
    steps_ms = np.diff(stamps) / 1e6
    assert len(wrenches) > 1000 and np.all(steps_ms > 0.5) and np.all(steps_ms < 1.5), \
        (len(wrenches), steps_ms.min(), steps_ms.max(), counters, report)
    # the pokes ended before the kill were each detected
    before = [e for e in got if e["t_host_ns"] < t_kill_ns]
    ended = [r for r in read_truth(truth) if r["t_host_ns"] < t_kill_ns - 400_000_000]
    ev = evaluate(before, ended, 1e-3)
    assert len(ev.contacts) >= 1 and all(c.onsets >= 1 for c in ev.contacts if not c.cut), (ev.contacts, report)
