"""An emulator process ends cleanly however often it is asked to (the runner asks every emulator first and then
waits for each, and a signal that arrives while the process runs its exit handlers must not print there)."""
from __future__ import annotations

import subprocess
import sys

import pytest

from ftc_hw.sim_devices.launch import EmulatorProcess

pytestmark = pytest.mark.compute  # a process signalled, a process object faked: no clock

SIGNALLED_TWICE = """
import atexit, os, signal, time
from ftc_hw.sim_devices.emulator import _raise_exit
signal.signal(signal.SIGTERM, _raise_exit)
def exiting():
    os.kill(os.getpid(), signal.SIGTERM)  # the second SIGTERM, while the exit handlers run
    time.sleep(0.2)
atexit.register(exiting)
try:
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(5)
    print("not ended")
except SystemExit:
    print("ended")
"""


def test_a_second_sigterm_while_the_emulator_exits_is_ignored():
    proc = subprocess.run([sys.executable, "-c", SIGNALLED_TWICE], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip() == "ended", (proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr, proc.stderr


class _Process:
    def __init__(self) -> None:
        self.terminated = 0
        self.alive = True

    def is_alive(self) -> bool:
        return self.alive

    def terminate(self) -> None:
        self.terminated += 1

    def join(self, timeout: float | None = None) -> None:
        self.alive = False

    def kill(self) -> None:
        raise AssertionError("killed")


def test_an_emulator_asked_to_stop_then_stopped_gets_one_sigterm():
    proc = _Process()
    emulator = EmulatorProcess(None, proc)
    emulator.ask_to_stop()
    emulator.stop()
    assert proc.terminated == 1
