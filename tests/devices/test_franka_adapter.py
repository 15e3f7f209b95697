"""The Franka arm adapter (pylibfranka, the default client) against the emulator (separate processes,
loopback address 127.0.0.52): JointFrames with tau = tau_J and the controller's clock, stop() reaching
the world, and a killed controller shown as a disconnect, then reconnected."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from ftc_hw.bus import Bus
from ftc_hw.codecs import franka as F
from ftc_hw.devices.base import DeviceError
from ftc_hw.devices.franka import FrankaArm, probe_fci
from ftc_hw.devices.registry import make_adapter
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.host import WorldHost
from ftc_hw.sim_devices.link import JointRecord

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others

ADDRESS = "127.0.0.52"
SCENE = load_scene("fr3")
DEVICE = SCENE.devices[0]


@pytest.fixture(scope="module")
def world():
    with WorldHost(SCENE, "sweep", devices=["arm"], options={"arm": {"address": ADDRESS}}, noise=False) as w:
        yield w


@pytest.fixture(scope="module")
def arm(world):
    bus = Bus()
    events = bus.subscribe("events/", maxsize=10_000)
    adapter = make_adapter(DEVICE, bus, world.endpoint("arm"), scene=SCENE)
    with adapter:
        assert adapter.wait_connected(20.0)
        yield adapter, bus, events


def drain_for(sub, seconds: float, want: int, ring=None, ticks: dict | None = None) -> list:
    """Frames until ``want`` came; with ``ring``, the world's first sample of each tick (ms) into ``ticks``
    meanwhile (the ring holds about 2 s of the world)."""
    got: list = []
    end = time.monotonic() + seconds
    while len(got) < want and time.monotonic() < end:
        time.sleep(0.05)
        got += sub.drain()
        for rec in ring.new() if ring is not None else ():
            j = JointRecord.from_row(rec, SCENE.n_joints)
            ticks.setdefault(math.floor(j.t * 1000 + 1e-6), j)
    return got


def test_frames_carry_tau_j_and_the_controller_clock(world, arm):
    adapter, bus, _ = arm
    assert isinstance(adapter, FrankaArm) and adapter.client == "pylibfranka"
    ring = world.joint_reader()
    frames = bus.subscribe("joints/arm", maxsize=10_000)
    ticks: dict[int, JointRecord] = {}
    got = drain_for(frames, 5.0, 200, ring, ticks)
    assert len(got) >= 200
    matched = [(f, ticks[f.seq]) for f in got if f.seq in ticks]
    assert len(matched) >= 0.9 * len(got)
    for f, j in matched:
        assert f.t_device_ns == f.seq * 1_000_000
        np.testing.assert_allclose(f.q, j.q, rtol=1e-6, atol=1e-6)  # float32 on the wire (protocol 10)
        np.testing.assert_allclose(f.tau, j.tau_j, rtol=1e-6, atol=1e-5)
        assert not f.current.any()
    assert all(b.seq > a.seq for a, b in zip(got, got[1:], strict=False))
    assert adapter.robot_mode == "Move"


def test_stop_goes_through_the_library_to_the_world(world, arm):
    adapter, _, _ = arm
    before = world.applied_count()
    adapter.stop()
    deadline = time.monotonic() + 2.0
    while world.applied_count() == before and time.monotonic() < deadline:
        time.sleep(0.01)
    assert [a.kind for a in world.applied()[before:]] == ["stop"]
    assert adapter.counters["stops"] == 1


def test_a_killed_controller_is_a_disconnect_and_the_adapter_reconnects(world, arm):
    adapter, bus, events = arm
    events.drain()
    world.kill("arm")
    deadline = time.monotonic() + 5.0
    kinds: list[str] = []
    while "disconnect" not in kinds and time.monotonic() < deadline:
        time.sleep(0.05)
        kinds += [e.kind for e in events.drain()]
    assert "stale" in kinds and "disconnect" in kinds
    with pytest.raises(DeviceError):
        adapter.stop()  # no controller: said, never silent
    world.restart("arm", {"address": ADDRESS})
    assert adapter.wait_connected(15.0)
    frames = bus.subscribe("joints/arm", maxsize=10_000)
    assert len(drain_for(frames, 5.0, 50)) >= 50
    assert adapter.counters["disconnects"] >= 1


def test_the_probe_names_the_client_a_controller_of_the_other_version_takes(world, arm):
    with pytest.raises(DeviceError, match="set client = 'pylibfranka'"):
        probe_fci(ADDRESS, F.V5)
