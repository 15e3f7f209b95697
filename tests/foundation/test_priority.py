"""Process priority for the device-facing processes: raised only where the OS allows, restored after."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from ftc_hw.priority import DEVICE_NICE, preferred_cpu

pytestmark = pytest.mark.skipif(not hasattr(os, "getpriority"), reason="no process priorities on this OS")


def test_the_priority_is_raised_inside_the_block_when_allowed_and_restored_after():
    before = os.getpriority(os.PRIO_PROCESS, 0)
    with preferred_cpu() as raised:
        inside = os.getpriority(os.PRIO_PROCESS, 0)
        if raised:
            assert inside <= DEVICE_NICE
        else:  # no privilege: nothing changed
            assert inside == before
    assert os.getpriority(os.PRIO_PROCESS, 0) == before


def test_a_process_already_ahead_is_not_lowered():
    before = os.getpriority(os.PRIO_PROCESS, 0)
    with preferred_cpu(nice=before + 5) as raised:
        assert raised and os.getpriority(os.PRIO_PROCESS, 0) == before
    assert os.getpriority(os.PRIO_PROCESS, 0) == before


def test_a_tier_started_by_a_higher_one_takes_its_own_level():
    """In a foreground process (nice 0: run-tests' computing leg runs at 19, so a child is brought back)."""
    code = ("import os; from ftc_hw.priority import DEVICE_NICE, prefer_cpu; "
            "print(os.getpriority(os.PRIO_PROCESS, 0), prefer_cpu(DEVICE_NICE - 5), "
            "prefer_cpu(DEVICE_NICE, exact=True), os.getpriority(os.PRIO_PROCESS, 0))")
    base = os.getpriority(os.PRIO_PROCESS, 0)
    out = subprocess.run(["nice", "-n", str(-base), sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    if out[0] != "0" or out[1] != "True":
        pytest.skip("no privilege to raise the priority here")
    assert out[2:] == ["True", str(DEVICE_NICE)]


def test_a_process_put_in_the_background_stays_there():
    """``nice -n 10``: a world or emulator started in it does not raise itself ahead of the foreground's."""
    code = ("import os; from ftc_hw.priority import prefer_cpu; "
            "print(prefer_cpu(-15), prefer_cpu(-10, exact=True), os.getpriority(os.PRIO_PROCESS, 0))")
    out = subprocess.run(["nice", "-n", "10", sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    base = os.getpriority(os.PRIO_PROCESS, 0)
    assert out == ["False", "False", str(min(19, base + 10))]
