"""``ftc sim`` stopped by Ctrl-C or SIGTERM: a clean end, and no process of its left behind."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.realtime  # a real-time world and its emulators

ROOT = Path(__file__).resolve().parents[2]


def _alive_in_group(pgid: int) -> list[str]:
    """The processes of process group ``pgid`` that still run (zombies have ended: init reaps them)."""
    out = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            if os.getpgid(int(pid)) != pgid:
                continue
            status = Path(f"/proc/{pid}/status").read_text()
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except (OSError, ProcessLookupError):
            continue
        if "\nState:\tZ" not in status:
            out.append(f"{pid}: {cmdline}")
    return out


@pytest.mark.parametrize(("signum", "whole_group"), [(signal.SIGINT, True), (signal.SIGTERM, False)],
                         ids=["ctrl-c", "sigterm"])
def test_ftc_sim_stopped_by_a_signal_ends_cleanly_and_leaves_nothing_running(tmp_path, signum, whole_group):
    truth = tmp_path / "truth.jsonl"
    # a session of its own: Ctrl-C in a terminal reaches every process of the foreground group
    proc = subprocess.Popen([sys.executable, "-m", "ftc_hw", "sim", "leng2016", "--scenario", "static-pokes",
                             "--duration", "60", "--truth", str(truth)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        first = json.loads(proc.stdout.readline())
        (device,) = first["devices"]
        assert os.path.islink(device["endpoint"])  # the emulator's pty
        time.sleep(0.5)
        if whole_group:
            os.killpg(proc.pid, signum)
        else:
            proc.send_signal(signum)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)
    name = signal.Signals(signum).name
    assert proc.returncode == 128 + signum, err
    assert "error" not in err and "Traceback" not in err, err
    assert err.strip().splitlines()[-1].startswith(f"interrupted ({name}) after "), err
    assert "the world and its emulators are stopped" in err and out == ""
    assert not os.path.lexists(device["endpoint"])  # the emulator closed its endpoint
    lines = truth.read_text().splitlines()  # the truth up to the stop, whole lines
    assert len(lines) > 100 and json.loads(lines[-1])["t"] > 0.4
    deadline = time.monotonic() + 10.0
    while (left := _alive_in_group(proc.pid)) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not left, left


@pytest.mark.parametrize(("args", "bus_time", "baud"), [([], True, 1_000_000),
                                                         (["--device", "arm.bus_time=false", "--device",
                                                           "arm.baudrate=57600"], False, 57_600)],
                         ids=["default", "bus-time-off"])
def test_ftc_sim_dynamixel_bus_time_on_by_default_and_off_by_a_device_param(args, bus_time, baud):
    done = subprocess.run([sys.executable, "-m", "ftc_hw", "sim", "dxl-arm", "--duration", "0.5", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    arm = next(d for d in json.loads(done.stdout.splitlines()[0])["devices"] if d["kind"] == "dynamixel")
    assert (arm["bus_time"], arm["baudrate"]) == (bus_time, baud)
