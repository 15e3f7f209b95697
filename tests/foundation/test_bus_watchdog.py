"""Staleness watchdog, driven with fake time."""

import numpy as np
import pytest

from ftc_hw.bus import EVENTS_DEVICE, Bus, DeviceEvent, Watchdog, WrenchFrame

_W = np.zeros(6)
_W.flags.writeable = False
S = 1_000_000_000


def wf(t: int) -> WrenchFrame:
    return WrenchFrame(t, None, 0, "ft0", _W)


def kinds(events: list[DeviceEvent]) -> list[tuple[str, str]]:
    return [(e.kind, e.source) for e in events]


def test_stale_once_then_recovered_once():
    bus = Bus()
    published = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    wd = Watchdog(bus, {"wrench/ft0": 0.1})
    bus.publish("wrench/ft0", wf(10 * S))
    assert wd.check(10 * S + S // 10) == []  # exactly the timeout: not yet stale
    ev = wd.check(10 * S + S // 10 + 1)
    assert kinds(ev) == [("stale", "ft0")]
    assert ev[0].counters["timeout_s"] == pytest.approx(0.1) and "wrench/ft0" in ev[0].message
    assert wd.stale_topics == {"wrench/ft0"}
    for k in range(2, 50):  # still stale: no repeated reports
        assert wd.check(10 * S + k * S) == []
    bus.publish("wrench/ft0", wf(60 * S))
    assert kinds(wd.check(60 * S + 1)) == [("recovered", "ft0")]
    assert wd.check(60 * S + 2) == [] and wd.stale_topics == frozenset()
    assert kinds(wd.check(61 * S)) == [("stale", "ft0")]  # a new episode
    assert kinds(published.drain()) == [("stale", "ft0"), ("recovered", "ft0"), ("stale", "ft0")]


def test_topic_that_never_received_is_stale_after_timeout_from_first_check():
    bus = Bus()
    wd = Watchdog(bus, {"joints/arm": 0.5, "wrench/ft0": 2.0})
    assert wd.check(100 * S) == []
    assert kinds(wd.check(100 * S + S // 2 + 1)) == [("stale", "arm")]
    assert kinds(wd.check(102 * S + 1)) == [("stale", "ft0")]


def test_late_frame_does_not_recover():
    bus = Bus()
    wd = Watchdog(bus, {"wrench/ft0": 0.1})
    bus.publish("wrench/ft0", wf(0))
    assert kinds(wd.check(S)) == [("stale", "ft0")]
    bus.publish("wrench/ft0", wf(S // 2))  # newer than before, but already older than the timeout
    assert wd.check(S) == []
    bus.publish("wrench/ft0", wf(S))
    assert kinds(wd.check(S)) == [("recovered", "ft0")]


def test_thread_start_stop_idempotent_and_context_manager():
    bus = Bus()
    events = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    now = [0]
    wd = Watchdog(bus, {"wrench/ft0": 1.0}, period=0.001, clock=lambda: now[0])
    with wd:
        assert wd.running
        wd.start()  # no-op
        now[0] = 2 * S
        first = events.get(timeout=30)
        assert (first.kind, first.source) == ("stale", "ft0")
        bus.publish("wrench/ft0", wf(2 * S))
        second = events.get(timeout=30)
        assert (second.kind, second.source) == ("recovered", "ft0")
    assert not wd.running
    wd.stop()  # no-op
    assert events.drain() == []


def test_invalid_timeouts():
    with pytest.raises(ValueError):
        Watchdog(Bus(), {"wrench/ft0": 0})
    with pytest.raises(ValueError):
        Watchdog(Bus(), {"wrench/ft0": 1}, period=0)
