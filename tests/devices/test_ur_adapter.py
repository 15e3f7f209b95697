"""The UR arm adapter against the emulator (separate processes, loopback address 127.0.0.43): JointFrames
with device timestamps, the flange F/T sensor's WrenchFrames on the same RTDE connection (the module's
world is ur5e with an e-Series flange sensor, tests/ur_flange.py), stop()/pause() through the
dashboard, and dead / hung / restarted controllers."""
from __future__ import annotations

import time

import numpy as np
import pytest

from ftc_hw.bus import Bus, JointFlag, WrenchFlag
from ftc_hw.devices.base import DeviceError
from ftc_hw.devices.registry import make_adapter
from ftc_hw.devices.ur import DashboardLink, URArm, probe_rtde
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.host import WorldHost
from ftc_hw.sim_devices.link import JointRecord
from tests.ur_flange import flange_scene

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others

ADDRESS = "127.0.0.43"
SCENE = load_scene("ur5e")
DEVICE = next(d for d in SCENE.devices if d.kind == "ur-rtde")


@pytest.fixture(scope="module")
def flange(tmp_path_factory):
    """ur5e whose F/T sensor is its flange sensor, read by the arm device (same joints, same arm device)."""
    return flange_scene(tmp_path_factory.mktemp("ur-flange"))


@pytest.fixture(scope="module")
def world(flange):
    with WorldHost(flange, "sweep", devices=["arm"], options={"arm": {"address": ADDRESS}}, noise=False) as w:
        yield w


@pytest.fixture(scope="module")
def arm(world, flange):
    bus = Bus()
    events = bus.subscribe("events/", maxsize=10_000)
    adapter = make_adapter(flange.devices[0], bus, world.endpoint("arm"), scene=flange, dead_after=0.3)
    with adapter:
        assert adapter.wait_connected(10.0)
        yield adapter, bus, events


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
    world_state = {round(j.t * 1e9): j for j in (JointRecord.from_row(r, SCENE.n_joints) for r in ring.new())}
    assert len(got) >= 200
    for f in got[-20:]:
        joints = world_state[f.t_device_ns]
        assert np.array_equal(f.q, joints.q) and np.array_equal(f.current, joints.current)
        assert f.seq == round(f.t_device_ns * 500 / 1e9)
        assert f.tau == pytest.approx(SCENE.robot.torque_constant * f.current)
    assert all(b.seq > a.seq for a, b in zip(got, got[1:], strict=False))
    gaps = [f for f in got if f.flags & JointFlag.SEQ_GAP]
    assert len(gaps) <= adapter.counters["missed_packets"]


def test_the_flange_sensor_comes_on_the_same_connection_with_every_500_hz_packet(world, arm):
    """Each packet's WrenchFrame is the world's flange reading at the packet's time (the newest F/T sample
    at or before it, bit for bit through ur_rtde), beside the packet's JointFrame; packets on the 500 Hz
    grid, every controller period either delivered or counted missed."""
    adapter, bus, _ = arm
    assert adapter.roles == {"arm", "ft"}
    ring = world.ft_reader()
    wrenches, joints = bus.subscribe("wrench/arm", maxsize=10_000), bus.subscribe("joints/arm", maxsize=10_000)
    got: list = []
    js: list = []
    end = time.monotonic() + 5.0
    while len(got) < 250 and time.monotonic() < end:  # about 0.5 s, longer on a loaded host
        time.sleep(0.1)
        got += wrenches.drain()
        js += joints.drain()
    js += joints.drain()
    records = ring.new()
    t_ring = np.array([r[0] for r in records])
    by_time = {j.t_device_ns: j for j in js}
    assert len(got) >= 200 and sum(f.t_device_ns not in by_time for f in got) <= 1  # (one around subscribing)
    assert all((f.seq, f.t_host_ns) == (by_time[f.t_device_ns].seq, by_time[f.t_device_ns].t_host_ns)
               for f in got if f.t_device_ns in by_time)  # each packet's two frames
    for f in got[-100:]:
        k = int(np.searchsorted(t_ring, f.t_device_ns / 1e9 + 1e-9)) - 1
        assert k >= 0 and f.t_device_ns / 1e9 - t_ring[k] < 0.002 + 1e-9  # within one sensor period
        assert np.array_equal(f.wrench, records[k][1:7])
        assert not f.flags & WrenchFlag.SATURATED  # a sweep without a contact on the tool: within 100 N / 10 N m
    assert any(np.abs(f.wrench).max() > 0.1 for f in got)  # the reading is there, not zeros
    seqs = np.array([f.seq for f in got])
    assert np.array_equal(seqs * 2_000_000, [f.t_device_ns for f in got])  # the 500 Hz grid
    steps = np.diff(seqs)
    assert [bool(f.flags & WrenchFlag.SEQ_GAP) for f in got[1:]] == list(steps > 1)  # a gap, flagged where it is
    assert int((steps - 1).sum()) <= adapter.counters["missed_packets"]  # and counted (every packet of the grid
    # is sent: tests/sim/test_ur_emulator.py; ur_rtde keeps only the newest, so a slow poller misses some)


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


def test_killed_then_restarted_controller(world, arm, kill_and_restart, check_kill_and_restart):
    adapter, bus, events = arm
    r = kill_and_restart(world, adapter, bus, events)
    before, after = check_kill_and_restart(r)
    # ur_rtde kept serving the dead controller's last packet: it was not published again, and what came
    # after the reconnection is the restarted controller's (the world's later time)
    assert before and min(f.t_device_ns for f in after) > max(f.t_device_ns for f in before)
    adapter.stop()  # the dashboard link was re-opened too


def test_hung_controller_goes_stale_then_reconnects(world, arm, collect_events):
    adapter, _, events = arm
    events.drain()
    was_stale = adapter.stale
    world.suspend("arm")
    try:  # stale after stale_after, disconnect after dead_after without a packet, then the probe fails
        seen = collect_events(events, lambda k: "disconnect" in k and ("stale" in k or was_stale), 10.0)
        seen = collect_events(events, lambda k: "reconnecting" in k, 5.0, seen)
    finally:
        world.resume("arm")
    assert "does not answer" in next(e for e in seen if e.kind == "reconnecting").message
    collect_events(events, lambda k: {"connect", "recovered"} <= k, 10.0)


def test_no_controller_at_all():
    with pytest.raises(DeviceError, match="does not answer"):
        probe_rtde("127.0.0.44", timeout=0.2)
    with pytest.raises(DeviceError):
        DashboardLink("127.0.0.44", timeout=0.2).command("stop")


def test_an_operator_resumes_the_scenario_after_each_stop():
    """With ``resume_after_s`` the emulated controller plays again after a stop: the world holds the arm
    for that long, then continues the sweep from where it was; a second stop halts it again."""
    options = {"arm": {"address": "127.0.0.44", "resume_after_s": 0.3}}
    with WorldHost(SCENE, "sweep", devices=["arm"], options=options, noise=False) as w:
        bus = Bus()
        frames = bus.subscribe("joints/arm", maxsize=100_000)
        adapter = make_adapter(DEVICE, bus, w.endpoint("arm"), scene=SCENE)
        with adapter:
            assert adapter.wait_connected(10.0)
            time.sleep(0.3)
            for _ in range(2):
                adapter.stop()
                time.sleep(0.15)
                frames.drain()
                time.sleep(0.1)
                held = frames.drain()  # well inside the halt
                time.sleep(0.35)
                frames.drain()
                time.sleep(0.1)
                moving = frames.drain()
                assert max(np.abs(f.qd).max() for f in held) < 0.01
                assert max(np.abs(f.qd).max() for f in moving) > 0.05
            kinds = [a.kind for a in w.applied()]
        assert kinds == ["stop", "resume", "stop", "resume"]
        assert adapter.runtime_state == 2 and adapter.counters["stops"] == 2  # playing again
