"""Issue 38's cell, end to end, each node in a process of its own: ``ftc ros publish`` plays the drivers (the
ur5e's emulated devices in the typical world, read through their client libraries and published as
ur_robot_driver and the F/T broadcaster publish them), ``ftc monitor --rig ros.toml --ros`` reads those
topics and publishes its answers, and a user's node (tests/app/ros/subscriber.py, rclpy's own classes)
subscribes to them. The domain is private and discovery stays on this host (conftest.ros_env).

Checked: the F/T topic arrives at the sensor's 1 kHz without a message missing; every press that ended before
the kill is detected; every event arrives whole and in order at the user's node, each estimate with markers
whose point is within 1 mm of the event's; the external wrench stream loses no message (one per judged
frame); the publisher killed in a contact gives ``sensor_lost`` and that contact closed, flagged ``lost``;
the ROS 2 bag written beside holds the same events and wrenches."""
from __future__ import annotations

import ast
import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import Reader

from ftc_hw.app.monitor.evaluate import evaluate
from ftc_hw.record.events import read_events, read_truth
from ftc_hw.record.reader import read_recording

from .conftest import UR_RIG, ros_env

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(240)]

SUBSCRIBER = Path(__file__).with_name("subscriber.py")


def ftc(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "ftc_hw", *args], env=ros_env(), text=True, **kw)


def _subscriber(out: Path) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, str(SUBSCRIBER), str(out), "/ftc"], env=ros_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    if line.strip() != "ready":
        proc.kill()
        pytest.fail(f"the subscriber did not start: {line}{proc.stderr.read()}")
    return proc


def _received(path: Path) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.endswith("}"):  # the last line may be cut where the process was killed
            record = json.loads(line)
            out.setdefault(record["topic"], []).append(record)
    return out


def _drained(path: Path, quiet_s: float = 1.5, most_s: float = 30.0) -> None:
    """Until the user's node has written nothing for ``quiet_s``: its DDS reader acknowledged every message
    before the monitor ended (the publisher waits for that), but a loaded host's Python callbacks may still
    be taking them from its queue (CI: 219 of 1796 wrenches were queued when the node was killed at once)."""
    end, size, still = time.monotonic() + most_s, -1, time.monotonic()
    while time.monotonic() < end:
        now_size = path.stat().st_size if path.exists() else 0
        if now_size != size:
            size, still = now_size, time.monotonic()
        elif time.monotonic() - still >= quiet_s:
            return
        time.sleep(0.1)


def _events(path: Path) -> list[dict]:
    return read_events(path) if path.exists() else []


def _open_contact(events: list[dict]) -> int | None:
    """The contact id of an onset not yet closed, after at least two onsets."""
    onsets = [e["contact_id"] for e in events if e["kind"] == "onset"]
    closed = {e["contact_id"] for e in events if e["kind"] == "offset"}
    return onsets[-1] if len(onsets) >= 2 and onsets[-1] not in closed else None


def _run_cell(tmp_path: Path) -> tuple[str, int, dict[str, list[dict]]]:
    """The three nodes until the publisher is killed in the second contact and the monitor says it lost the
    sensor: the monitor's output, the kill's host time, what the user's node received."""
    (tmp_path / "ros.toml").write_text(UR_RIG)
    events, truth, rec = tmp_path / "e.jsonl", tmp_path / "truth.jsonl", tmp_path / "r.mcap"
    sub = _subscriber(tmp_path / "received.jsonl")
    # a poke, then a press held 2 s: the F/T stream is cut in the press however far behind the cell's delivery
    # runs (0.3 s pokes ended before the kill when it ran 0.5-0.8 s behind: the loaded host's 1 kHz came at 715 Hz)
    pub = ftc("ros", "publish", "--scene", "ur5e", "--sim", "--scenario", "static-presses", "--reality", "typical",
              "--duration", "20", "--truth", str(truth), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    mon = ftc("monitor", "--scene", "ur5e", "--rig", str(tmp_path / "ros.toml"), "--duration", "120", "--events",
              str(events), "--record", str(rec), "--record-format", "both", "--no-view", "--readers", "thread",
              "--ros", stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        topics = json.loads(pub.stdout.readline())["topics"]
        assert [t["topic"] for t in topics] == ["/joint_states", "/force_torque_sensor_broadcaster/wrench"]
        deadline = time.monotonic() + 120
        while _open_contact(_events(events)) is None:
            assert time.monotonic() < deadline and pub.poll() is None and mon.poll() is None, "no contact seen"
            time.sleep(0.01)
        pub.kill()
        t_kill_ns = time.monotonic_ns()
        pub.wait(10)
        while not any(e["kind"] == "sensor_lost" and e["t_host_ns"] > t_kill_ns for e in _events(events)):
            assert time.monotonic() < deadline and mon.poll() is None, "no sensor_lost"
            time.sleep(0.05)
    finally:
        pub.kill()
        mon.send_signal(signal.SIGTERM)
        out = mon.communicate(timeout=60)[0]
        _drained(tmp_path / "received.jsonl")
        sub.kill()  # its lines are flushed as they come
        sub.wait(10)
    return out, t_kill_ns, _received(tmp_path / "received.jsonl")


def test_a_cell_of_ros_drivers_is_monitored_and_a_users_node_receives_every_answer(tmp_path):
    out, t_kill_ns, rx = _run_cell(tmp_path)
    report = out[-3000:]
    got = read_events(tmp_path / "e.jsonl")
    # the contact open at the kill is closed, flagged lost; the F/T stream was lost after the kill
    lost = [e for e in got if e["kind"] == "sensor_lost" and e["t_host_ns"] > t_kill_ns]
    assert len(lost) == 1 and lost[0]["source"] == "ft", report
    open_at_kill = {e["contact_id"] for e in got if e["kind"] == "onset" and e["t_host_ns"] < t_kill_ns} - {
        e["contact_id"] for e in got if e["kind"] == "offset" and e["t_host_ns"] < t_kill_ns}
    offsets = [e for e in got if e["kind"] == "offset" and e["contact_id"] in open_at_kill]
    assert open_at_kill and len(offsets) == len(open_at_kill) and all("lost" in e["flags"] for e in offsets), report
    # the F/T topic: every message of the sensor's 1 kHz stream, none missing between the stamps
    counters = ast.literal_eval(re.search(r"ft \(ros-wrench\): (\{.*?\})", " ".join(out.split())).group(1))
    assert counters["frames"] > 1000 and "lost" not in counters and "seq_gaps" not in counters, (counters, report)
    stamps = np.array([w.t_device_ns for w in read_recording(tmp_path / "r.mcap").topic("wrench/ft")])
    steps_ms = np.diff(stamps) / 1e6
    assert len(stamps) > 1000 and np.all(steps_ms > 0.5) and np.all(steps_ms < 1.5), (steps_ms.min(), steps_ms.max())
    # every press that ended before the kill was detected
    before = [e for e in got if e["t_host_ns"] < t_kill_ns]
    ended = [r for r in read_truth(tmp_path / "truth.jsonl") if r["t_host_ns"] < t_kill_ns - 400_000_000]
    # the F/T frames' times are the ROS stamps placed on this host's clock (their least delay seen): on a loaded
    # host that placed a poke's onset 1.4 ms before its first sample was due (CI), outside evaluate's 1 ms
    ev = evaluate(before, ended, 1e-3, early_s=0.01)
    assert len(ev.contacts) >= 1 and all(c.onsets >= 1 for c in ev.contacts if not c.cut), (ev.contacts, report)
    # the user's node: every event whole and in order, each estimate's marker on its point
    arrived = [r["data"] for r in rx.get("events", [])]
    assert [(e["t_host_ns"], e["kind"]) for e in arrived] == [(e["t_host_ns"], e["kind"]) for e in got], report
    for a, w in zip(arrived, got, strict=True):
        assert {k: a[k] for k in w} == w and a["frame_id"] == "world"
    estimated = [e for e in got if e["kind"] in ("onset", "update", "offset") and "no_estimate" not in e["flags"]]
    markers = rx.get("markers", [])
    assert len(markers) == len(estimated) > 0, report
    for m, e in zip(markers, estimated, strict=True):
        point = next(k for k in m["markers"] if k["id"] == 100 * e["contact_id"])
        assert np.linalg.norm(np.subtract(point["position"], e["point"])) < 1e-3 and point["frame"] == "world"
    # the external wrench: one message per judged frame, none lost, in order, in the base frame
    flat = " ".join(out.split())  # the console wraps its lines wherever it likes
    judged = ast.literal_eval(re.search(r"monitor: (\{.*?\})", flat).group(1))["frames"]
    published = int(re.search(r"/ftc/external_wrench (\d+)", flat).group(1))
    wrenches = rx.get("wrench", [])
    skips = re.search(r"failed 0, frames dropped 0, not published \d+(?: \(([^)]*)\))?", flat)
    assert skips and "external" not in (skips.group(1) or ""), report  # only an event without estimate has no markers
    # half a second of the 1 kHz stream at least: a loaded host's publisher misses arm packets (ur_rtde keeps
    # only its newest; CI: 727 of 1086), and F/T frames without a joint state are not judged
    assert judged > 500, report
    assert published == judged and len(wrenches) == judged, (judged, published, len(wrenches), report)
    wstamps = [w["stamp"] for w in wrenches]
    assert all(b > a for a, b in zip(wstamps, wstamps[1:], strict=False))
    assert {w["frame"] for w in wrenches} == {"world"}
    # stream health reached the node; the ROS 2 bag holds what was published
    names = {s["name"] for d in rx.get("diagnostics", []) for s in d["status"]}
    assert {"ftc: F/T ft", "ftc: joints arm", "ftc: judged frames", "ftc: monitor"} <= names, names
    with Reader(tmp_path / "r_ros2") as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts["/ftc/external_wrench"] == judged and counts["/ftc/events"] == len(got), (counts, report)
