"""``ftc monitor --readers process`` (the default but with a simulated world on a host of fewer than 4
cores) runs each device's reader in a process of its own, as ``ftc serve`` does, its frames over Zenoh
on loopback: the readers' counters reach the summary, a killed reader is restarted and the run says
so, a killed monitor takes its readers with it, and ``auto`` says which it chose (``--readers
thread``: tests/app/test_monitor_hardware_path.py). dxl-arm, ideal world (the pipeline's own model):
these tests are about the processes, not the model."""
from __future__ import annotations

import ast
import os
import re
import signal
import subprocess
import sys
import time

import pytest

from ftc_hw.app.monitor.config import DeviceOptions, MonitorOptions
from ftc_hw.app.monitor.report import DEGRADED_EXIT
from ftc_hw.app.monitor.session import readers_mode

pytestmark = pytest.mark.timeout(120)
READERS = re.compile(r"readers in processes of their own: (.*), over Zenoh on (tcp/127\.0\.0\.1:\d+)")


def _monitor(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "ftc_hw", "monitor", "--scene", "dxl-arm", "--sim", "--no-view",
                             "--readers", "process", *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


def _reader_pids(proc: subprocess.Popen, lines: list[str]) -> tuple[dict[str, int], str]:
    """Reads the monitor's output up to the line naming its readers: ``({device: pid}, endpoint)``."""
    while True:
        line = proc.stdout.readline()
        assert line, "".join(lines)
        lines.append(line)
        said = READERS.search(line)
        if said:
            pids = {name: int(pid) for name, pid in re.findall(r"(\w+) \([\w-]+, pid (\d+)\)", said.group(1))}
            return pids, said.group(2)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:  # a zombie is gone, only not yet reaped
        return f.read().rsplit(")", 1)[1].split()[0] != "Z"


def _counters(out: str, device: str) -> dict[str, float]:
    said = re.search(rf"^{device} \([\w-]+\): (\{{.*?\}})$", out, re.M | re.S)
    assert said, out[-3000:]
    return ast.literal_eval(said.group(1).replace("\n", ""))


@pytest.mark.realtime
def test_a_killed_reader_process_is_restarted_and_the_run_says_so():
    proc = _monitor("--duration", "6")
    lines: list[str] = []
    try:
        pids, endpoint = _reader_pids(proc, lines)
        assert set(pids) == {"ft", "arm"} and all(_alive(p) for p in pids.values()) and os.getpid() not in pids.values()
        while "the world plays" not in lines[-1] and "waiting for the first frames" not in lines[-1]:
            lines.append(proc.stdout.readline())
            assert lines[-1], "".join(lines)
        time.sleep(1.5)
        os.kill(pids["ft"], signal.SIGKILL)
        rest, _ = proc.communicate(timeout=90)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
    out = "".join(lines) + rest
    assert proc.returncode == DEGRADED_EXIT and "reader processes restarted 1x" in out, out[-3000:]
    # each reader's last counters, from its own process: the restarted ft reader's since its restart
    arm, ft = _counters(out, "arm"), _counters(out, "ft")
    assert arm["final"] == 1 and arm["frames"] > 6 * 300 and arm.get("disconnects", 0) == 0, arm
    assert ft["final"] == 1 and 0 < ft["frames"] < 6 * 100, ft
    received = re.search(r"from reader processes \(Zenoh\): \{'received': (\d+), 'foreign': 0, 'corrupt': 0", out)
    assert received and int(received.group(1)) > arm["frames"], out[-2000:]
    assert not any(_alive(p) for p in pids.values())


@pytest.mark.compute
def test_a_killed_monitor_takes_its_readers_with_it():
    proc = _monitor("--duration", "60")
    lines: list[str] = []
    try:
        pids, _ = _reader_pids(proc, lines)
        proc.kill()  # SIGKILL: nothing of the monitor runs any more
        proc.wait(5)
        end = time.monotonic() + 5.0
        while any(_alive(p) for p in pids.values()) and time.monotonic() < end:
            time.sleep(0.05)
        assert not any(_alive(p) for p in pids.values()), pids
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)


@pytest.mark.compute
def test_auto_says_where_the_readers_run_and_why():
    cpus = os.cpu_count() or 1
    mode, why = readers_mode(MonitorOptions("dxl-arm", sim=True))
    assert (mode, str(cpus) in why) == (("thread", True) if cpus < 4 else ("process", False)), why
    assert readers_mode(MonitorOptions("dxl-arm"))[0] == "process"  # real devices: always their own processes
    assert readers_mode(MonitorOptions("dxl-arm", sim=True, devices=DeviceOptions(readers="process")))[0] == "process"

