"""The UR arm adapter against the emulator (separate processes, loopback address 127.0.0.43): JointFrames
with device timestamps, stop()/pause() through the dashboard, and dead / hung / restarted controllers."""
from __future__ import annotations

import queue
import time

import numpy as np
import pytest

from devices.arm_registry import make_arm_adapter
from devices.base import DeviceError
from devices.ur import DashboardLink, URArm, probe_rtde
from ftc_hw.bus import Bus, JointFlag
from ftc_hw.scene import load_scene
from sim_devices.world_process import WorldProcess

ADDRESS = "127.0.0.43"
SCENE = load_scene("ur5e")
DEVICE = next(d for d in SCENE.devices if d.kind == "ur-rtde")


@pytest.fixture(scope="module")
def world():
    with WorldProcess(SCENE, "sweep", devices=["arm"], options={"arm": {"address": ADDRESS}}) as w:
        yield w


@pytest.fixture(scope="module")
def arm(world):
    bus = Bus()
    events = bus.subscribe("events/", maxsize=10_000)
    adapter = make_arm_adapter(DEVICE, bus, world.endpoint("arm"), scene=SCENE, dead_after=0.3)
    with adapter:
        assert adapter.wait_connected(10.0)
        yield adapter, bus, events


def wait_event(sub, kind: str, timeout: float):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            ev = sub.get(timeout=0.05)
        except queue.Empty:
            continue
        if ev.kind == kind:
            return ev
    raise AssertionError(f"no {kind!r} event within {timeout} s")


def test_frames_carry_the_controller_timestamp_and_the_world_values(world, arm):
    adapter, bus, _ = arm
    assert isinstance(adapter, URArm)
    ring = world.joint_reader()
    frames = bus.subscribe("joints/arm", maxsize=10_000)
    got: list = []
    end = time.monotonic() + 5.0
    while len(got) < 200 and time.monotonic() < end:
        time.sleep(0.1)
        got += frames.drain()
    world_state = {round(float(r[0]) * 1e9): r for r in ring.new()}
    assert len(got) >= 200
    for f in got[-20:]:
        rec = world_state[f.t_device_ns]
        assert np.array_equal(f.q, rec[1:7]) and np.array_equal(f.current, rec[19:25])
        assert f.seq == round(f.t_device_ns * 500 / 1e9)
        assert f.tau == pytest.approx(SCENE.robot.torque_constant * f.current)
    assert all(b.seq > a.seq for a, b in zip(got, got[1:], strict=False))
    gaps = [f for f in got if f.flags & JointFlag.SEQ_GAP]
    assert len(gaps) <= adapter.counters["missed_packets"]


def test_stop_and_pause_through_the_dashboard(world, arm):
    adapter, _, _ = arm
    before = len(world.applied())
    adapter.stop()
    adapter.stop()  # already stopped: accepted
    time.sleep(0.05)
    assert [a.kind for a in world.applied()[before:]] == ["stop"]
    assert adapter.runtime_state == 1
    assert adapter.dashboard.command("play") == "Starting program"
    adapter.pause()
    time.sleep(0.05)
    assert adapter.runtime_state == 4 and world.applied()[-1].kind == "stop"
    assert adapter.dashboard.command("play") == "Starting program"
    assert adapter.counters["stops"] == 2 and adapter.counters["pauses"] == 1


def test_killed_then_restarted_controller(world, arm):
    adapter, _, events = arm
    events.drain()
    already_stale = adapter.stale
    t_kill = time.monotonic_ns()
    world.kill("arm")
    if not already_stale:
        wait_event(events, "stale", 5.0)
    wait_event(events, "disconnect", 5.0)
    world.restart("arm")
    wait_event(events, "connect", 10.0)
    assert wait_event(events, "recovered", 5.0).t_host_ns > t_kill
    adapter.stop()  # the dashboard link was re-opened too


def test_hung_controller_goes_stale_then_reconnects(world, arm):
    adapter, _, events = arm
    events.drain()
    already_stale = adapter.stale
    world.suspend("arm")
    try:
        if not already_stale:
            wait_event(events, "stale", 5.0)
        wait_event(events, "disconnect", 5.0)  # dead_after without a packet
        assert wait_event(events, "reconnecting", 5.0).message.find("does not answer") >= 0
    finally:
        world.resume("arm")
    wait_event(events, "connect", 10.0)
    wait_event(events, "recovered", 5.0)


def test_no_controller_at_all():
    with pytest.raises(DeviceError, match="does not answer"):
        probe_rtde("127.0.0.44", timeout=0.2)
    with pytest.raises(DeviceError):
        DashboardLink("127.0.0.44", timeout=0.2).command("stop")
