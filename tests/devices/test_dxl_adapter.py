"""The DYNAMIXEL arm adapter against the emulator (separate processes): JointFrames in SI, torque as a
context manager that restores, stop(), and dead / hung / restarted devices."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from ftc_hw.bus import Bus
from ftc_hw.devices.base import DeviceError
from ftc_hw.devices.dynamixel import DynamixelArm
from ftc_hw.devices.registry import make_adapter
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.host import WorldHost

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others

SCENE = load_scene("dxl-arm")
DEVICE = next(d for d in SCENE.devices if d.kind == "dynamixel")
FAST = {"stale_after": 0.1, "dead_after": 0.5}


@pytest.fixture(scope="module")
def world():
    with WorldHost(SCENE, "sweep", devices=["arm"], noise=False) as w:
        yield w


@pytest.fixture
def arm(world):
    bus = Bus()
    events = bus.subscribe("events/", maxsize=10_000)
    adapter = make_adapter(DEVICE, bus, world.endpoint("arm"), scene=SCENE, **FAST)
    with adapter:
        if not adapter.wait_connected(10.0):
            pytest.fail(f"no connection: {[(e.kind, e.message) for e in events.drain()][-5:]}")
        end = time.monotonic() + 2.0
        while bus.latest(adapter.topic) is None and time.monotonic() < end:
            time.sleep(0.01)
        yield adapter, bus, events


def test_frames_are_si_and_match_the_world(world, arm):
    adapter, bus, _ = arm
    assert isinstance(adapter, DynamixelArm)
    frames = bus.subscribe("joints/arm", maxsize=10_000)
    got: list = []
    end = time.monotonic() + 5.0
    while len(got) < 100 and time.monotonic() < end:
        time.sleep(0.1)
        got += frames.drain()
    assert len(got) >= 100
    f = got[-1]
    assert f.t_device_ns is None and f.source == "arm" and f.n_joints == SCENE.n_joints == 5
    assert [g.seq for g in got] == list(range(got[0].seq, got[0].seq + len(got)))
    js = world.latest_joints()
    # the arm sweeps joints 1-2 at up to ~0.6 rad/s: allow a few ms of motion plus one tick
    assert f.q == pytest.approx(js.q, abs=0.02)
    assert f.tau == pytest.approx(f.current * 4.1 / 2.3)
    assert f.current == pytest.approx(js.current, abs=0.05)
    assert np.all(np.abs(f.q - np.round(f.q / (2 * math.pi / 4096)) * (2 * math.pi / 4096)) < 1e-12)


def test_fast_sync_read_and_hardware_error_events(world, wait_event):
    world.restart("arm", {"hardware_error": {"13": 32}})
    bus = Bus()
    events = bus.subscribe("events/", maxsize=1000)
    try:
        with DynamixelArm.from_spec(DEVICE, bus, world.endpoint("arm"), fast_read=True, **FAST) as adapter:
            assert adapter.wait_connected(10.0)
            ev = wait_event(events, "error", 10.0)
            assert "servo 13" in ev.message and "overload" in ev.message
            end = time.monotonic() + 10.0
            while adapter.counters["frames"] < 50 and time.monotonic() < end:
                time.sleep(0.05)
            assert adapter.counters["frames"] >= 50
            assert adapter.hardware_errors == {11: 0, 12: 0, 13: 32, 14: 0, 15: 0}
            assert bus.latest("joints/arm").q == pytest.approx(world.latest_joints().q, abs=0.03)
    finally:
        world.restart("arm", {})


def test_torque_context_manager_restores_even_on_error(world, arm):
    adapter, _, _ = arm
    assert all(adapter.torque_states().values())
    with pytest.raises(RuntimeError, match="inside"), adapter.torque(False):
        assert not any(adapter.torque_states().values())
        raise RuntimeError("inside")
    assert all(adapter.torque_states().values())
    end = time.monotonic() + 3.0  # the last command may still be on its way to the world
    while (kinds := [(a.kind, a.on) for a in world.applied() if a.kind == "torque"])[-1:] != [("torque", True)] \
            and time.monotonic() < end:
        time.sleep(0.02)
    assert kinds[-2:] == [("torque", False), ("torque", True)]


def test_stop_holds_the_present_position(world, arm):
    adapter, bus, _ = arm
    before = len(world.applied())
    adapter.stop()
    time.sleep(0.3)
    goals = [a for a in world.applied()[before:] if a.kind == "goal"]
    assert len(goals) == 1
    q_stop = np.array(goals[0].q)
    time.sleep(0.5)  # the sweep would have moved joint 1 by ~0.2 rad by now
    assert bus.latest("joints/arm").q == pytest.approx(q_stop, abs=0.01)
    assert adapter.counters["stops"] == 1


def test_goal_positions_move_the_arm(arm):
    adapter, bus, _ = arm
    target = np.array([0.2, -0.9, 0.3, 0.6, 0.4])  # the gripper opens (its servo turns negative)
    with pytest.raises(ValueError, match="5 joint positions"):
        adapter.set_goal(target[:4])
    adapter.set_goal(target)
    end = time.monotonic() + 10.0
    while time.monotonic() < end and not np.allclose(bus.latest("joints/arm").q, target, atol=0.01):
        time.sleep(0.05)
    assert bus.latest("joints/arm").q == pytest.approx(target, abs=0.01)


def test_killed_then_restarted_emulator(world, arm, kill_and_restart, check_kill_and_restart):
    adapter, bus, events = arm
    r = kill_and_restart(world, adapter, bus, events)
    # a killed emulator closes the pty: the next transfer fails at once (not dead_after later)
    check_kill_and_restart(r, lost_by=lambda message: message.startswith(adapter.port_name))
    assert adapter.counters["disconnects"] >= 1


def test_hung_emulator_goes_stale_then_reconnects(world, arm, collect_events):
    adapter, _, events = arm
    events.drain()
    was_stale = adapter.stale  # a load-induced blip may have declared it already
    world.suspend("arm")
    try:  # stale after stale_after, disconnect after dead_after without an answer
        dead = collect_events(events, lambda k: "disconnect" in k and ("stale" in k or was_stale), 10.0)
    finally:
        world.resume("arm")
    assert next(e for e in dead if e.kind == "disconnect").message.startswith("no answer for")
    collect_events(events, lambda k: {"connect", "recovered"} <= k, 10.0)


def test_commands_need_a_link():
    adapter = DynamixelArm("arm", Bus(), "/nonexistent/tty", [1, 2])
    with pytest.raises(DeviceError):
        adapter.stop()
    with pytest.raises(DeviceError, match="unknown DYNAMIXEL model"):
        DynamixelArm("arm", Bus(), "/dev/null", [1], model="AX-12")
