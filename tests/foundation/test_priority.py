"""Process priority for the device-facing processes: raised only where the OS allows, restored after."""
from __future__ import annotations

import os

import pytest

from ftc_hw.priority import DEVICE_NICE, prefer_cpu, preferred_cpu

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
    before = os.getpriority(os.PRIO_PROCESS, 0)
    with preferred_cpu(DEVICE_NICE - 5) as raised:
        if not raised:
            pytest.skip("no privilege to raise the priority here")
        assert prefer_cpu(DEVICE_NICE, exact=True)
        assert os.getpriority(os.PRIO_PROCESS, 0) == DEVICE_NICE
    assert os.getpriority(os.PRIO_PROCESS, 0) == before
