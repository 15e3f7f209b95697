"""``ftc monitor`` without ``--sim``, as next to a real arm: the devices at the scene's addresses. Here
the "hardware" is ``ftc sim`` started separately (its emulators on ptys) and a copy of the dxl-arm
scene whose ``[[devices]]`` carry those addresses."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from importlib import resources

import pytest

from ftc_hw.record.events import read_events
from ftc_hw.record.reader import read_recording
from ftc_hw.sim_devices.host import free_loopback


@pytest.mark.realtime
def test_monitor_connects_to_the_devices_at_the_scene_addresses(tmp_path, clean_or_loaded):
    builtin = resources.files("ftc_hw") / "scene" / "builtin"
    sim = subprocess.Popen([sys.executable, "-m", "ftc_hw", "sim", "dxl-arm", "--scenario", "hold", "--duration", "60"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        endpoints = {d["name"]: d["endpoint"] for d in json.loads(sim.stdout.readline())["devices"]}
        text = (builtin / "dxl-arm.toml").read_text()
        for name, where in endpoints.items():
            text = text.replace(f'name = "{name}"\n', f'name = "{name}"\naddress = "{where}"\n', 1)
        scene = tmp_path / "bench-arm.toml"
        scene.write_text(text)
        shutil.copy(builtin / "dxl-arm.xml", tmp_path / "dxl-arm.xml")
        proc = subprocess.run([sys.executable, "-m", "ftc_hw", "monitor", "--scene", str(scene), "--duration", "3",
                               "--events", str(tmp_path / "e.jsonl"), "--record", str(tmp_path / "r.mcap"),
                               "--no-view"], capture_output=True, text=True, timeout=120)
    finally:
        sim.terminate()
        sim.wait(30)
    clean_or_loaded(proc.returncode, proc.stdout + proc.stderr)
    assert "ft (ft300): {" in proc.stdout and "arm (dynamixel): {" in proc.stdout
    rec = read_recording(tmp_path / "r.mcap")
    counts = rec.counts()
    assert counts["wrench/ft"] >= 200 and counts["joints/arm"] >= 500, counts  # 100 Hz and ~500 Hz for 3 s
    inputs = rec.topic("monitor/input")
    assert sum(not i.tare for i in inputs) >= 150
    assert rec.metadata["monitor"]["sim"] == "False"
    # the arm holds still and nothing touches it: no contact
    assert read_events(tmp_path / "e.jsonl") == []


@pytest.mark.compute
def test_a_scene_without_an_arm_device_needs_sim():
    proc = subprocess.run([sys.executable, "-m", "ftc_hw", "monitor", "--scene", "leng2016", "--duration", "1",
                           "--no-view"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1 and "declares no arm device" in proc.stderr, proc.stderr
    truth = subprocess.run([sys.executable, "-m", "ftc_hw", "monitor", "--scene", "dxl-arm", "--truth", "t.jsonl"],
                           capture_output=True, text=True, timeout=60)
    assert truth.returncode == 2 and "--truth needs --sim" in truth.stderr


@pytest.mark.realtime
def test_monitor_reaches_emulators_placed_by_sim_address(tmp_path, clean_or_loaded):
    """``ftc sim --address arm=...`` puts the UR emulator there; ``ftc monitor --device`` points the scene at
    it and at the CAN emulator's channel: the override path, each in its own process."""
    address = free_loopback()
    sim = subprocess.Popen([sys.executable, "-m", "ftc_hw", "sim", "ur5e", "--scenario", "hold", "--duration", "600",
                            "--address", f"arm={address}"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        endpoints = {d["name"]: d for d in json.loads(sim.stdout.readline())["devices"]}
        assert endpoints["arm"]["address"] == address
        channel = endpoints["ft"]["channel"]
        proc = subprocess.run([sys.executable, "-m", "ftc_hw", "monitor", "--scene", "ur5e", "--duration", "2",
                               "--device", f"arm.address={address}", "--device", f"ft.channel={channel}",
                               "--record", str(tmp_path / "r.mcap"), "--no-view", "--readers", "thread"],
                              capture_output=True, text=True, timeout=120)
    finally:
        sim.terminate()
        sim.wait(30)
    clean_or_loaded(proc.returncode, proc.stdout + proc.stderr)
    counts = read_recording(tmp_path / "r.mcap").counts()
    # both links streamed (1 kHz and 500 Hz; the 2 s include connecting, on a loaded machine) and were paired
    assert counts["wrench/ft"] >= 100 and counts["joints/arm"] >= 100 and counts["monitor/input"] >= 100, counts
    # the readers in the monitor's threads (--readers thread): their adapters' counters, no reader process
    assert "ft (ft-can): {" in proc.stdout and "arm (ur-rtde): {" in proc.stdout
    assert "--readers thread" in proc.stdout and "readers in processes" not in proc.stdout
    assert "'final'" not in proc.stdout.split("arm (ur-rtde): ", 1)[1].split("}", 1)[0]


@pytest.mark.compute
def test_without_addresses_the_monitor_says_how_to_give_them():
    proc = subprocess.run([sys.executable, "-m", "ftc_hw", "monitor", "--scene", "ur5e", "--duration", "1",
                           "--no-view"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1, proc.stderr
    assert "no address for device 'ft' (ft-can" in proc.stderr and "and 'arm' (ur-rtde" in proc.stderr, proc.stderr
    assert "--device ft.channel=" in proc.stderr and "--device arm.address=" in proc.stderr, proc.stderr
    bad = subprocess.run([sys.executable, "-m", "ftc_hw", "monitor", "--scene", "ur5e", "--device", "ft.baud_rate=1"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 1 and "--device: ft.baud_rate:" in bad.stderr and "'bitrate'" in bad.stderr, bad.stderr
