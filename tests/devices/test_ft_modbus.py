"""The generic Modbus F/T engine: register maps as data, over Modbus TCP and RTU, with faults."""
from __future__ import annotations

import time

import numpy as np
import pytest

from ftc_hw.bus import Bus, WrenchFlag
from ftc_hw.codecs import AXES
from ftc_hw.devices.modbus_ft import ModbusFTAdapter
from ftc_hw.devices.registry import make_adapter
from ftc_hw.scene import DeviceSpec, load_scene

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(60)]

INT32_LITTLE = {
    "name": "test-int32", "function": 4, "word_order": "little",
    "axes": [{"name": a, "address": 100 + 2 * i, "type": "int32", "scale": 1e-3} for i, a in enumerate(AXES)],
    "status": {"address": 120, "type": "uint16"},
    "identity": [{"name": "serial", "address": 200, "count": 4, "decoder": "ascii"}],
}


def _spec(transport: str, **params) -> DeviceSpec:
    return DeviceSpec("ft", "modbus-ft", transport, None, {"device_id": 3, **params})


def _values_ok(bus: Bus, topic: str, wrench_of) -> list:
    frames = bus.history(topic)
    known = {tuple(np.round(wrench_of(k), 3)) for k in range(2001)}
    assert frames and all(tuple(np.round(f.wrench, 3)) in known for f in frames)
    return frames


def _poll(ft_sim, wait_for, spec, *, until: int = 200, saturated=None, **options):
    scene = load_scene("leng2016")
    world = ft_sim.world(1000.0, saturated=saturated)
    emu = ft_sim.start_emulator(spec, scene, world, **options)
    bus = Bus()
    adapter = make_adapter(spec, bus, emu.endpoint, scene=scene)
    with adapter:
        assert adapter.wait_connected(5.0)
        assert wait_for(lambda: adapter.counters["polls"] >= until, 15.0)
    time.sleep(0.25)  # the emulator rewrites its stats every 0.1 s
    stats = ft_sim.read_stats(emu)
    ft_sim.stop()
    return adapter, bus, stats, emu.endpoint


def test_map_table_over_tcp_with_status_and_identity(ft_sim, wait_for, wrench_of):
    spec = _spec("modbus-tcp", map=INT32_LITTLE, identity={"serial": "AB-123"}, poll_hz=0)
    def sat(k: int) -> np.ndarray:
        return np.array([k % 2 == 0, False, False, False, False, False])

    adapter, bus, _, endpoint = _poll(ft_sim, wait_for, spec, until=300, saturated=sat)
    assert endpoint["port"] > 0 and endpoint["host"] == "127.0.0.1"
    assert adapter.identity == {"serial": "AB-123"}
    frames = _values_ok(bus, adapter.topic, wrench_of)
    index = {tuple(np.round(wrench_of(k), 3)): k for k in range(2001)}
    for f in frames:  # the status register's bits, whatever the value
        k = index[tuple(np.round(f.wrench, 3))]
        assert bool(f.flags & WrenchFlag.SATURATED) == (k % 2 == 0)
    rate = (len(frames) - 1) / ((frames[-1].t_host_ns - frames[0].t_host_ns) / 1e9)
    assert rate > 200  # loose here; `ftc bench devices` measures it


def test_builtin_map_over_rtu(ft_sim, wait_for, wrench_of):
    spec = _spec("modbus-rtu", map="generic-float32", baudrate=115200, poll_hz=0)
    adapter, bus, stats, _ = _poll(ft_sim, wait_for, spec, until=100, wire_time=False)
    _values_ok(bus, adapter.topic, wrench_of)
    assert adapter.counters["timeouts"] == adapter.counters["checksum_errors"] == 0
    assert stats["responses"] == adapter.counters["polls"] + 1  # + the identity read


def test_tcp_faults_counted_and_recovered(ft_sim, wait_for, wrench_of):
    spec = _spec("modbus-tcp", map=INT32_LITTLE, poll_hz=0)
    faults = {"drop": 0.01, "duplicate": 0.01, "truncate": 0.005}
    adapter, bus, stats, _ = _poll(ft_sim, wait_for, spec, until=2000, faults=faults, seed=2)
    _values_ok(bus, adapter.topic, wrench_of)
    inj = stats["faults"]
    c = adapter.counters
    assert inj["drop"] > 5 and inj["duplicate"] > 5 and inj["truncate"] > 2
    assert c["timeouts"] == inj["drop"]
    # a truncated answer resets the connection: each one a disconnect, then a reconnect
    assert c["disconnects"] == inj["truncate"]
    assert c["event_connect"] - c["disconnects"] in (0, 1)  # 0: closed while reconnecting


def test_tcp_unplug_and_replug_on_the_same_port(ft_sim, wait_for, wrench_of):
    spec = _spec("modbus-tcp", map="generic-float32", poll_hz=200)
    faults = {"disconnect_at_s": 0.5, "reconnect_after_s": 0.3}
    adapter, bus, stats, _ = _poll(ft_sim, wait_for, spec, until=250, faults=faults)
    assert stats["faults"]["disconnects"] == 1
    assert adapter.counters["event_connect"] == 2 and adapter.counters["disconnects"] == 1
    frames = _values_ok(bus, adapter.topic, wrench_of)
    gap = max(b.t_host_ns - a.t_host_ns for a, b in zip(frames, frames[1:], strict=False))
    assert 0.25e9 < gap < 1.0e9


def test_ft300_polled_over_tcp_through_the_registry(ft_sim, wait_for, wrench_of):
    scene, spec = ft_sim.device("dxl-arm", "ft300", transport="modbus-tcp")
    world = ft_sim.world(100.0, n_joints=4)
    emu = ft_sim.start_emulator(spec, scene, world)
    bus = Bus()
    adapter = make_adapter(spec, bus, emu.endpoint, scene=scene)
    assert adapter.mode == "poll" and adapter.transport == "modbus-tcp"
    with adapter:
        assert wait_for(lambda: adapter.counters["polls"] >= 50, 5.0)
    ft_sim.stop()
    assert adapter.identity["firmware"] == "FTS-3.0.1"
    _values_ok(bus, adapter.topic, wrench_of)


def test_bad_configurations_are_reported():
    with pytest.raises(ValueError):
        ModbusFTAdapter("ft", Bus(), {"axes": []}, transport="modbus-tcp")
    from ftc_hw.devices.base import DeviceError
    with pytest.raises(DeviceError):
        ModbusFTAdapter("ft", Bus(), "ft300", transport="modbus-rtu")  # no port
    with pytest.raises(DeviceError):
        make_adapter(_spec("modbus-tcp"), Bus(), {"host": "127.0.0.1", "port": 1})  # no map
