"""Emulator killed (a pulled plug) and restarted: stale reported, reconnected, nothing from the dead period.

Loose time bounds here; ``ftc bench devices`` measures the acceptance's 100 ms and 1 s."""
from __future__ import annotations

import time

import pytest

from ftc_hw.bus import EVENTS_DEVICE, Bus
from ftc_hw.devices.registry import make_adapter

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(60)]

CASES = {
    "ft-serial-stream": ("leng2016", "ft-serial-stream", None, 1000.0, 3),
    "ft-can": ("ur5e", "ft-can", None, 1000.0, 6),
    "ft300-stream": ("dxl-arm", "ft300", None, 100.0, 4),
    "ft300-tcp": ("dxl-arm", "ft300", "modbus-tcp", 100.0, 4),
}


@pytest.mark.parametrize("case", list(CASES))
def test_kill_and_restart(ft_sim, wait_for, case):
    scene_name, kind, transport, rate, n_joints = CASES[case]
    scene, spec = ft_sim.device(scene_name, kind, transport)
    world = ft_sim.world(rate, n_joints=n_joints)
    emu = ft_sim.start_emulator(spec, scene, world)
    bus = Bus()
    events = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    adapter = make_adapter(spec, bus, emu.endpoint, scene=scene)
    with adapter:
        assert adapter.wait_connected(5.0)
        assert wait_for(lambda: len(bus.history(adapter.topic)) > 20, 3.0)
        events.drain()
        t_kill = time.monotonic_ns()
        emu.kill()
        assert wait_for(lambda: adapter.stale, 1.0)
        time.sleep(0.4)
        assert not adapter.connected.is_set()
        keep = {"port": emu.endpoint["port"]} if "port" in emu.endpoint else {}
        t_restart = time.monotonic_ns()
        emu = ft_sim.start_emulator(spec, scene, world, **keep)
        t_back = emu.endpoint["ready_ns"]
        assert wait_for(lambda: bool(bus.window(adapter.topic, t_back, time.monotonic_ns())), 3.0)
        time.sleep(0.2)
    ft_sim.stop()
    evs = [e for e in events.drain() if e.source == adapter.name]
    stale = next(e for e in evs if e.kind == "stale")
    assert stale.t_host_ns - t_kill < 300_000_000
    assert [e.kind for e in evs].count("connect") == 1 and "disconnect" in {e.kind for e in evs}
    frames = bus.history(adapter.topic)
    first_back = next(f for f in frames if f.t_host_ns > t_back)
    assert first_back.t_host_ns - t_back < 2_000_000_000
    # nothing received while the device was dead (frames already on the wire at the kill aside)
    assert not [f for f in frames if t_kill + 20_000_000 < f.t_host_ns < t_restart]
    before = [f for f in frames if f.t_host_ns <= t_kill]
    after = [f for f in frames if f.t_host_ns > t_back]
    assert after[0].seq > before[-1].seq
    if before[-1].t_device_ns is not None:  # the device's clock: no sample of the dead period either
        dead_ns = (t_restart - t_kill) * 0.9
        assert after[0].t_device_ns - before[-1].t_device_ns > dead_ns
