"""A second process for tests/foundation/test_bus_remote.py: a Zenoh peer listening on ENDPOINT that
publishes, from its own bus through a RemotePublisher, wrench frames of a known sequence at RATE Hz
(each frame's values from its seq: the other side checks them bit for bit), and, every 100 frames,
a foreign payload and a corrupt one on the rig's key expressions. It runs until killed.

    python -m tests.foundation.remote_peer ENDPOINT RIG RATE
"""
from __future__ import annotations

import sys
import time

import numpy as np

from ftc_hw.bus import Bus, WrenchFrame
from ftc_hw.bus.remote import RemotePublisher, key_expr, open_session
from ftc_hw.bus.wire import encode


def frame(seq: int, t_host_ns: int) -> WrenchFrame:
    return WrenchFrame.make(t_host_ns, np.sin(seq + np.arange(6.0)) * 10.0, source="ft", seq=seq,
                            t_device_ns=seq * 1_000_000)


def main(endpoint: str, rig: str, rate: float) -> None:
    session = open_session(listen=[endpoint])
    bus = Bus()
    RemotePublisher(session, bus, rig)
    junk = session.declare_publisher(key_expr(rig, "wrench/ft"))
    print("ready", flush=True)
    period = 1.0 / rate
    seq, t0 = 0, time.monotonic()
    while True:
        bus.publish("wrench/ft", frame(seq, time.monotonic_ns()))
        if seq % 100 == 99:
            junk.put(b'{"wrench": [1, 2, 3, 4, 5, 6]}')  # another program's JSON
            junk.put(encode(frame(seq, 1))[:-3])  # a truncated frame of ours
        seq += 1
        time.sleep(max(0.0, t0 + seq * period - time.monotonic()))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], float(sys.argv[3]))
