"""Adapters by scene device kind, fault options, and the whole path: ``ftc sim`` -> endpoint line -> adapter."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ftc_hw.bus import Bus
from ftc_hw.devices.base import DeviceError
from ftc_hw.devices.can_ft import CanFTAdapter
from ftc_hw.devices.ft300 import FT300Adapter
from ftc_hw.devices.modbus_ft import ModbusFTAdapter
from ftc_hw.devices.netft_rdt import RdtFTAdapter
from ftc_hw.devices.registry import ADAPTERS, kinds, make_adapter
from ftc_hw.devices.serial_stream import SerialStreamFTAdapter
from ftc_hw.scene import DeviceSpec, load_scene
from ftc_hw.sim_devices.faults import FaultConfig, FaultInjector
from ftc_hw.sim_devices.registry import EMULATORS

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(60)]
ROOT = Path(__file__).resolve().parents[2]


def test_every_kind_has_an_adapter_and_an_emulator():
    assert set(kinds("ft")) == {"ft300", "modbus-ft", "ft-serial-stream", "ft-can", "ft-rdt", "ros-wrench"}
    assert set(kinds("arm")) == {"dynamixel", "ur-rtde", "franka", "ros-joint-state"}  # ROS: read, not emulated
    assert set(ADAPTERS) == set(EMULATORS)


def test_builtin_scene_devices_build_the_right_adapters():
    bus = Bus()
    built = {}
    for name in ("leng2016", "ur5e", "dxl-arm"):
        scene = load_scene(name)
        for d in scene.devices:
            if d.kind in kinds("ft"):
                built[name] = make_adapter(d, bus, {"endpoint": "/tmp/x.tty", "transport": d.transport}, scene=scene)
    assert isinstance(built["leng2016"], SerialStreamFTAdapter) and built["leng2016"].fmt.name == "ftc-1k"
    assert isinstance(built["ur5e"], CanFTAdapter) and built["ur5e"].codec.base_id == 8
    rdt = make_adapter(DeviceSpec("ft", "ft-rdt", "udp", "192.168.1.1", {"mode": "buffered", "buffer": 20}), bus)
    assert isinstance(rdt, RdtFTAdapter) and (rdt.host, rdt.port, rdt.http_port, rdt.buffer) == ("192.168.1.1", 49152,
                                                                                               80, 20)
    ft = built["dxl-arm"]
    assert isinstance(ft, FT300Adapter) and ft.mode == "stream" and ft.device_id == 9 and ft.baudrate == 19200
    assert list(ft.range) == [300, 300, 300, 30, 30, 30]
    tcp = make_adapter(DeviceSpec("m", "modbus-ft", "modbus-tcp", "10.0.0.5:1502", {"map": "generic-float32"}), bus)
    assert isinstance(tcp, ModbusFTAdapter) and (tcp.host, tcp.tcp_port) == ("10.0.0.5", 1502)
    with pytest.raises(DeviceError):
        make_adapter(DeviceSpec("x", "dynamixel", "serial"), bus, {})
    with pytest.raises(DeviceError):
        make_adapter(DeviceSpec("x", "ft-serial-stream", "serial"), bus, {})  # nowhere to connect


def test_fault_config_validation_and_determinism():
    with pytest.raises(ValueError):
        FaultConfig.from_options({"faults": {"explode": 0.1}})
    with pytest.raises(ValueError):
        FaultConfig.from_options({"faults": {"drop": 0.7, "corrupt": 0.5}})
    with pytest.raises(ValueError):
        FaultConfig.from_options({"faults": {"corrupt": 0.1}}, supported=frozenset({"drop"}))
    cfg = FaultConfig.from_options({"faults": {"drop": 0.1, "corrupt": 0.1, "garbage": 0.1}, "seed": 4})

    def run() -> list:
        inj = FaultInjector(cfg)
        return [(inj.next_fault(), tuple(inj.apply(inj.next_fault(), b"\x20\x4e" + bytes(14), 2))) for _ in range(500)]

    a, b = run(), run()
    assert a == b and {f for f, _ in a} == {None, "drop", "corrupt", "garbage"}
    for _, chunks in a:  # the header is never touched
        assert all(c[:2] == b"\x20\x4e" for c in chunks if len(c) == 16)


def test_ftc_sim_endpoint_line_to_adapter():
    """The real world (MuJoCo) -> shared-memory link -> emulator process -> pty -> adapter."""
    proc = subprocess.Popen([sys.executable, "-m", "ftc_hw", "sim", "leng2016", "--scenario", "static-pokes",
                             "--duration", "8"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        line = json.loads(proc.stdout.readline())
        assert line["scene"] == "leng2016"
        scene = load_scene(line["scene"])
        (endpoint,) = line["devices"]
        spec = next(d for d in scene.devices if d.name == endpoint["name"])
        bus = Bus()
        with make_adapter(spec, bus, endpoint, scene=scene) as adapter:
            assert adapter.wait_connected(5.0)
            time.sleep(1.5)
        frames = bus.history(adapter.topic)
    finally:
        proc.send_signal(signal.SIGINT)  # Ctrl-C: ftc sim stops its emulators and exits
        proc.wait(15)
    assert len(frames) > 1000
    seqs = [f.seq for f in frames]
    assert seqs == sorted(set(seqs)) and seqs[-1] - seqs[0] + 1 - len(seqs) <= len(seqs) // 100
    w = np.array([f.wrench for f in frames])
    # leng2016 at rest: the arm's weight on the base sensor, along +y (conventions.md), plus noise
    assert 10 < np.median(w[:, 1]) < 200 and np.all(np.isfinite(w))
    assert all(f.t_device_ns is not None for f in frames)


def test_device_bench_runs_and_reports(tmp_path, capsys):
    from ftc_hw.bench.devices import run

    out = run(tmp_path / "bench.json", duration=1.0, sections=["modbus_tcp", "serial_1k"])
    assert "Modbus TCP polling" in capsys.readouterr().out
    assert json.loads((tmp_path / "bench.json").read_text())["serial_1k"]["frames"] == out["serial_1k"]["frames"]
    assert out["modbus_tcp"]["polls_per_s"] > 50
    s = out["serial_1k"]
    assert s["frames"] > 500 and s["lost"] == 0 and s["mismatched_values"] == 0
    assert out["serial_1k_gaps"]["gaps_exact"]


def test_emulator_exits_when_its_runner_dies(wait_for):
    """A runner killed outright (no cleanup) leaves no emulator behind."""
    proc = subprocess.Popen([sys.executable, "-m", "ftc_hw", "sim", "leng2016", "--duration", "30"], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        (endpoint,) = json.loads(proc.stdout.readline())["devices"]
        target = os.readlink(endpoint["endpoint"])  # /proc/<emulator pid>/fd/<n>
        pid = int(target.split("/")[2])
    finally:
        proc.kill()
        proc.wait(10)
    assert wait_for(lambda: not os.path.exists(f"/proc/{pid}"), 3.0)
