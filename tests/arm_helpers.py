"""Shared by the arm adapter tests: waiting for device events, and the kill / restart check."""
from __future__ import annotations

import contextlib
import queue
import time
from typing import Any


def wait_event(sub: Any, kind: str, timeout: float) -> Any:
    """The next event of ``kind`` on ``sub`` (others are consumed and dropped)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            ev = sub.get(timeout=0.05)
        except queue.Empty:
            continue
        if ev.kind == kind:
            return ev
    raise AssertionError(f"no {kind!r} event within {timeout} s")


def collect_events(sub: Any, done: Any, timeout: float, seen: list | None = None) -> list:
    """Events from ``sub`` appended to ``seen`` until ``done(kinds)`` holds for the set of kinds seen."""
    seen = [] if seen is None else seen
    end = time.monotonic() + timeout
    while not done({e.kind for e in seen}):
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout} s; events: {[(e.kind, e.message) for e in seen]}")
        with contextlib.suppress(queue.Empty):
            seen.append(sub.get(timeout=0.05))
    return seen


def kill_and_restart(world: Any, adapter: Any, bus: Any, events: Any, name: str = "arm") -> dict[str, Any]:
    """SIGKILL the emulator of ``name``, wait for the adapter to notice, restart it, wait for the adapter
    to be back. Order-free: the events of each phase are collected until all of them are there.
    Returns the events of both phases and the frames published from before the kill to after the
    reconnection."""
    frames = bus.subscribe(adapter.topic, maxsize=1_000_000)
    got = [frames.get(timeout=5.0)]  # streaming before the kill
    events.drain()
    was_stale = adapter.stale  # a load-induced blip may have declared it already
    world.kill(name)
    dead = collect_events(events, lambda k: "disconnect" in k and ("stale" in k or was_stale), 10.0)
    connected_after_disconnect = adapter.connected.is_set()
    world.restart(name)
    back = collect_events(events, lambda k: {"connect", "recovered"} <= k, 10.0)
    time.sleep(0.1)  # some frames from the restarted device
    got += frames.drain()
    frames.close()
    return {"was_stale": was_stale, "dead": dead, "back": back, "frames": got,
            "connected_after_disconnect": connected_after_disconnect}


def check_kill_and_restart(r: dict[str, Any], lost_by: Any = None) -> tuple[list, list]:
    """What the acceptance asks of a killed and restarted device, checked without timing assertions
    (the latencies are measured by ``ftc bench arms``): the adapter declared the device stale (or it
    already was) and disconnected -- ``lost_by(message)`` checks what the disconnect blamed -- and was
    disconnected when it said so; it reconnected and recovered after the restart; it published no
    frame between the first failure and the reconnection. Returns the frames before and after."""
    dead, back = r["dead"], r["back"]
    kinds = [e.kind for e in dead]
    assert "stale" in kinds or r["was_stale"], kinds
    disconnect = next(e for e in dead if e.kind == "disconnect")
    if lost_by is not None:
        assert lost_by(disconnect.message), disconnect.message
    assert not r["connected_after_disconnect"]
    t_lost = min(e.t_host_ns for e in dead if e.kind in ("stale", "disconnect"))
    connect = next(e for e in back if e.kind == "connect")
    recovered = next(e for e in back if e.kind == "recovered")
    assert recovered.t_host_ns >= connect.t_host_ns > t_lost
    frames = r["frames"]
    during = [f for f in frames if t_lost < f.t_host_ns < connect.t_host_ns]
    assert not during, f"{len(during)} frames published while the device was gone"
    after = [f for f in frames if f.t_host_ns > connect.t_host_ns]
    assert after, "no frame after the reconnection"
    return [f for f in frames if f.t_host_ns <= t_lost], after
