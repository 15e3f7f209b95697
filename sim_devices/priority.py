"""CPU priority of the simulated devices' processes.

The world and the protocol emulators stand in for real-time controllers: a device answers within its
cycle. On a small shared machine an ordinary process can wait a few milliseconds for a core, longer
than a control period, so they ask the OS to run them ahead of ordinary processes when it allows
(root or CAP_SYS_NICE). Without the privilege nothing changes; the benches report the tail either way.
"""
from __future__ import annotations

import os

DEVICE_NICE = -10  # ahead of ordinary processes (0), well short of the real-time classes


def prefer_cpu(nice: int = DEVICE_NICE) -> bool:
    """Raise this process's priority to ``nice`` if allowed and not already higher; True if it is."""
    if not hasattr(os, "setpriority"):
        return False
    try:
        if os.getpriority(os.PRIO_PROCESS, 0) > nice:
            os.setpriority(os.PRIO_PROCESS, 0, nice)
        return True
    except OSError:  # no privilege: run as an ordinary process
        return False
