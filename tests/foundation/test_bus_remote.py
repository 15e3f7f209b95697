"""The bus across processes on real Zenoh sessions (ftc_hw.bus.remote): another process publishes wrench
frames from its bus; here they arrive in a local bus with their times, sequence numbers and values
bit for bit, so sample_at, stats and the watchdog work on them; foreign and corrupt payloads on our key
expressions are counted and dropped; the publisher killed is a stale event; nothing loops back."""
from __future__ import annotations

import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from ftc_hw.bus import EVENTS_DEVICE, Bus, ContactEvent, Watchdog, WrenchFlag
from ftc_hw.bus.remote import RemoteError, RemotePublisher, RemoteSubscriber, key_expr, open_session, topic_of
from tests.foundation.remote_peer import frame

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(60)]


def free_endpoint() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


def wait_for(cond, timeout: float = 10.0, what: str = "") -> None:
    end = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.01)


def test_frames_cross_processes_bit_for_bit_and_the_bus_works_on_them():
    endpoint = free_endpoint()
    peer = subprocess.Popen([sys.executable, "-m", "tests.foundation.remote_peer", endpoint, "cell1", "1000"],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert peer.stdout.readline().strip() == "ready"
        session = open_session(connect=[endpoint])
        bus = Bus()
        with RemoteSubscriber(session, bus, "cell1") as sub:
            wait_for(lambda: sub.counts.received >= 600, what="600 frames")
            frames = bus.history("wrench/ft")
            for f in frames:  # what the other process published, bit for bit
                want = frame(f.seq, f.t_host_ns)
                assert f.wrench.tobytes() == want.wrench.tobytes() and f.t_device_ns == want.t_device_ns
                assert f.source == "ft" and f.flags == WrenchFlag.NONE
            # reliable once the subscription is known at the publisher (the first few frames may race it)
            seqs = np.array([f.seq for f in frames[20:]])
            assert np.all(np.diff(seqs) == 1), "reliable: no frame lost or reordered"
            assert sub.counts.foreign >= 1 and sub.counts.corrupt >= 1  # the peer's junk, counted
            assert sub.counts.received >= len(frames) and sub.counts.version == 0  # still arriving
            stats = bus.stats("wrench/ft")
            assert stats.seq_missing == 0 and 600 <= stats.rate_hz <= 1400, stats
            a, b = frames[100], frames[101]
            mid = bus.sample_at("wrench/ft", (a.t_host_ns + b.t_host_ns) // 2)
            assert np.allclose(mid.wrench, (a.wrench + b.wrench) / 2, atol=1e-9 + 0.01 * np.abs(b.wrench - a.wrench))
            with Watchdog(bus, {"wrench/ft": 0.1}, period=0.01) as dog:
                dog.start()
                time.sleep(0.2)
                assert not dog.stale_topics
                peer.kill()
                t_kill = time.monotonic_ns()
                wait_for(lambda: any(e.kind == "stale" for e in bus.history(EVENTS_DEVICE)), 2.0, "the stale event")
                stale = [e for e in bus.history(EVENTS_DEVICE) if e.kind == "stale"]
                assert stale and stale[0].t_host_ns - t_kill < 300_000_000  # 0.1 s timeout, 10 ms period
                # the peer restarted on its endpoint (a router or peer restart): this session reconnects by
                # itself and the frames flow on into the same bus
                peer = subprocess.Popen([sys.executable, "-m", "tests.foundation.remote_peer", endpoint, "cell1",
                                         "1000"], stdout=subprocess.PIPE, text=True)
                assert peer.stdout.readline().strip() == "ready"
                t_back = time.monotonic_ns()
                wait_for(lambda: any(e.kind == "recovered" and e.t_host_ns > t_back
                                     for e in bus.history(EVENTS_DEVICE)), 10.0, "frames after the restart")
                assert any(e.kind == "recovered" and e.t_host_ns > t_back for e in bus.history(EVENTS_DEVICE))
                assert bus.latest("wrench/ft").t_host_ns > t_back
        session.close()
    finally:
        peer.kill()
        peer.wait(5)


def test_a_process_that_publishes_and_subscribes_sends_nothing_back():
    """The monitor takes the devices' frames and publishes its events: a remote frame put into the bus
    is not sent out again by the same bus's publisher (no echo between two such processes)."""
    endpoint = free_endpoint()
    a_session, b_session = open_session(listen=[endpoint]), open_session(connect=[endpoint])
    a_bus, b_bus = Bus(), Bus()
    try:
        with RemotePublisher(a_session, a_bus, "c") as a_pub, RemoteSubscriber(a_session, a_bus, "c") as a_sub, \
                RemotePublisher(b_session, b_bus, "c") as b_pub, RemoteSubscriber(b_session, b_bus, "c") as b_sub:
            time.sleep(0.3)
            for k in range(50):
                a_bus.publish("wrench/ft", frame(k, time.monotonic_ns()))
            wait_for(lambda: b_sub.counts.received >= 50, what="a's frames at b")
            event = ContactEvent.make(time.monotonic_ns(), "onset", "link3", [0.1, 0.2, 0.3], [1.0, 0.0, 0.0])
            b_bus.publish("events/contact", event)
            wait_for(lambda: a_sub.counts.received >= 1, what="b's event at a")
            time.sleep(0.3)
            assert a_pub.sent == 50 and b_pub.sent == 1  # neither sent back what it took in
            assert b_sub.counts.received == 50 and a_sub.counts.received == 1
            assert len(a_bus.history("wrench/ft")) == 50 and len(b_bus.history("events/contact")) == 1
    finally:
        a_session.close()
        b_session.close()


def test_key_expressions_and_bad_endpoints():
    assert key_expr("cell1", "wrench/ft") == "ftc/cell1/wrench/ft"
    assert topic_of("ftc/cell1/events/contact") == ("cell1", "events/contact")
    assert topic_of("other/cell1/x") is None and topic_of("ftc/cell1") is None
    for bad in ("", "a/b", "c*"):
        with pytest.raises(RemoteError, match="rig name"):
            key_expr(bad, "wrench/ft")
    with pytest.raises(RemoteError, match="cannot open a Zenoh session"):
        open_session(listen=["tcp/203.0.113.7:7447"])  # not an address of this machine
