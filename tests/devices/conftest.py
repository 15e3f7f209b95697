"""Fixtures of the device tests.

F/T adapters: ``ft_sim`` starts synthetic worlds (a :class:`WorldLink` fed known samples from a
thread) and emulator processes for one test, their stats files in ``tmp_path``, and stops every one
at teardown, even when the test fails; ``wrench_of`` is the samples those worlds send; ``wait_for``
waits for a condition.
Arm adapters: ``wait_event`` and ``collect_events`` read device events; ``kill_and_restart`` and
``check_kill_and_restart`` are the pulled-plug check of an emulator run by a world host.
"""
from __future__ import annotations

import contextlib
import json
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from ftc_hw.bus import EVENTS_DEVICE, Bus
from ftc_hw.devices.registry import make_adapter
from ftc_hw.scene import DeviceSpec, Scene, load_scene
from ftc_hw.sim_devices.launch import EmulatorProcess
from ftc_hw.sim_devices.link import WorldLink

# -- F/T adapters against their emulators ------------------------------------------------------------


def _wrench_of(k: int) -> np.ndarray:
    """Sample k: distinct on every axis, a multiple of 0.01 N and 0.001 N m (exact in every format)."""
    f = [((k * 7 + 3 * a) % 2001 - 1000) * 0.01 for a in range(3)]
    t = [((k * 11 + 5 * a) % 2001 - 1000) * 0.001 for a in range(3)]
    return np.round(np.array(f + t), 3)


def _wait_for(cond: Callable[[], bool], timeout: float, step: float = 0.01) -> bool:
    """Whether ``cond()`` held within ``timeout`` s (polled every ``step`` s)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(step)
    return cond()


def _settle(adapter: Any, quiet_s: float = 0.3, timeout: float = 10.0) -> None:
    """Until the adapter's counters stop changing: it has read what was sent (slow on a loaded machine)."""
    last, since = None, time.monotonic()
    end = since + timeout
    while time.monotonic() < end:
        now = dict(adapter.counters)
        if now != last:
            last, since = now, time.monotonic()
        elif time.monotonic() - since > quiet_s:
            return
        time.sleep(0.02)


class SyntheticWorld:
    """A :class:`WorldLink` fed at ``rate_hz`` from a thread: sample k at t = k / rate, wrench ``fn(k)``."""

    def __init__(self, rate_hz: float, n_joints: int = 3, fn: Callable[[int], np.ndarray] = _wrench_of,
                 saturated: Callable[[int], np.ndarray] | None = None) -> None:
        self.rate_hz = rate_hz
        self.link = WorldLink(n_joints)
        self.fn = fn
        self.saturated = saturated or (lambda k: np.zeros(6, dtype=bool))
        self.k = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._closed = False
        z = np.zeros(n_joints)
        self.link.publish_joints(0.0, z, z, z, z, z, z)

    def start(self) -> SyntheticWorld:
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        period = 1.0 / self.rate_hz
        t0 = time.monotonic()
        while not self._stop.is_set():
            k = self.k
            self.link.publish_ft(k * period, self.fn(k), self.saturated(k))
            self.k = k + 1
            delay = t0 + (k + 1) * period - time.monotonic()
            if delay > 0:
                time.sleep(delay)

    def stop(self) -> None:
        """Stops the thread and closes the link; a second call does nothing."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self.link.close()


class FTSim:
    """The synthetic worlds and emulator processes of one test, their stats files in ``tmp_path``."""

    def __init__(self, tmp_path: Path) -> None:
        self.tmp_path = tmp_path
        self.worlds: list[SyntheticWorld] = []
        self.emulators: list[EmulatorProcess] = []

    @staticmethod
    def device(scene_name: str, kind: str, transport: str | None = None, **params: Any) -> tuple[Scene, DeviceSpec]:
        """The scene and the scene's device of ``kind`` (params and transport overridden)."""
        scene = load_scene(scene_name)
        d = next(d for d in scene.devices if d.kind == kind)
        spec = DeviceSpec(d.name, d.kind, transport or d.transport, d.address, {**d.params, **params})
        return scene, spec

    def world(self, rate_hz: float, n_joints: int = 3, fn: Callable[[int], np.ndarray] = _wrench_of,
              saturated: Callable[[int], np.ndarray] | None = None) -> SyntheticWorld:
        """A started :class:`SyntheticWorld`, stopped by :meth:`stop`."""
        world = SyntheticWorld(rate_hz, n_joints, fn, saturated)
        self.worlds.append(world)
        return world.start()

    def start_emulator(self, spec: DeviceSpec, scene: Scene, world: SyntheticWorld, **options: Any) -> EmulatorProcess:
        """The emulator of ``spec`` fed by ``world`` (its pty and stats file in tmp_path), stopped by :meth:`stop`."""
        options.setdefault("path", str(self.tmp_path / f"{spec.name}.tty"))
        options.setdefault("stats_path", str(self.tmp_path / f"{spec.name}-stats.json"))
        emu = EmulatorProcess.start(spec, scene, world.link.info, options)
        self.emulators.append(emu)
        return emu

    def read_stats(self, emu: EmulatorProcess) -> dict:
        """The emulator's last stats file ({} before its first)."""
        p = self.tmp_path / f"{emu.device.name}-stats.json"
        return json.loads(p.read_text()) if p.exists() else {}

    def wait_done(self, emu: EmulatorProcess, timeout: float = 20.0) -> dict:
        """Until the emulator sent its ``max_frames`` (stats say done), then its final stats."""
        assert _wait_for(lambda: self.read_stats(emu).get("done", False), timeout), self.read_stats(emu)
        time.sleep(0.25)  # the stats file is rewritten at most every 0.1 s; frames in flight arrive
        return self.read_stats(emu)

    def run_until_done(self, scene_name: str, kind: str, rate_hz: float, n_joints: int, frames: int, *,
                       saturated: Callable[[int], np.ndarray] | None = None, **options: Any) -> tuple:
        """The scene's ``kind`` adapter against its emulator until the emulator sent ``frames`` samples and the
        adapter read them, then everything stopped: the adapter, its frames, the final stats, the device events."""
        scene, spec = self.device(scene_name, kind)
        world = self.world(rate_hz, n_joints=n_joints, saturated=saturated)
        emu = self.start_emulator(spec, scene, world, max_frames=frames, **options)
        bus = Bus()
        events = bus.subscribe(EVENTS_DEVICE, maxsize=None)
        adapter = make_adapter(spec, bus, emu.endpoint, scene=scene)
        with adapter:
            assert adapter.wait_connected(5.0)
            stats = self.wait_done(emu)
            _settle(adapter)
        self.stop()
        return adapter, bus.history(adapter.topic), stats, events.drain()

    def stop(self) -> None:
        """Stops every emulator (killed ones too), then every world; each once."""
        while self.emulators:
            self.emulators.pop().stop()
        while self.worlds:
            self.worlds.pop().stop()


@pytest.fixture
def ft_sim(tmp_path):
    """Starts synthetic worlds and F/T emulators in tmp_path for one test; stops every one at teardown."""
    sim = FTSim(tmp_path)
    try:
        yield sim
    finally:
        sim.stop()


@pytest.fixture(scope="session")
def wrench_of():
    """The wrench of a synthetic world's sample k: distinct on every axis, exact in every format."""
    return _wrench_of


@pytest.fixture(scope="session")
def wait_for():
    """``wait_for(cond, timeout)``: whether the condition held within the timeout."""
    return _wait_for


# -- arm adapters against a world host ---------------------------------------------------------------


def _wait_event(sub: Any, kind: str, timeout: float) -> Any:
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


def _collect_events(sub: Any, done: Any, timeout: float, seen: list | None = None) -> list:
    """Events from ``sub`` appended to ``seen`` until ``done(kinds)`` holds for the set of kinds seen."""
    seen = [] if seen is None else seen
    end = time.monotonic() + timeout
    while not done({e.kind for e in seen}):
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout} s; events: {[(e.kind, e.message) for e in seen]}")
        with contextlib.suppress(queue.Empty):
            seen.append(sub.get(timeout=0.05))
    return seen


def _kill_and_restart(world: Any, adapter: Any, bus: Any, events: Any, name: str = "arm") -> dict[str, Any]:
    """SIGKILL the emulator of ``name``, wait for the adapter to notice, restart it, wait for the adapter
    to be back. Order-free: the events of each phase are collected until all of them are there.
    Returns the events of both phases and the frames published from before the kill to after the
    reconnection."""
    frames = bus.subscribe(adapter.topic, maxsize=1_000_000)
    got = [frames.get(timeout=5.0)]  # streaming before the kill
    events.drain()
    was_stale = adapter.stale  # a load-induced blip may have declared it already
    world.kill(name)
    dead = _collect_events(events, lambda k: "disconnect" in k and ("stale" in k or was_stale), 10.0)
    connected_after_disconnect = adapter.connected.is_set()
    world.restart(name)
    back = _collect_events(events, lambda k: {"connect", "recovered"} <= k, 10.0)
    time.sleep(0.1)  # some frames from the restarted device
    got += frames.drain()
    frames.close()
    return {"was_stale": was_stale, "dead": dead, "back": back, "frames": got,
            "connected_after_disconnect": connected_after_disconnect}


def _check_kill_and_restart(r: dict[str, Any], lost_by: Any = None) -> tuple[list, list]:
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


@pytest.fixture(scope="session")
def wait_event():
    """``wait_event(sub, kind, timeout)``: the next event of that kind (others dropped); fails on timeout."""
    return _wait_event


@pytest.fixture(scope="session")
def collect_events():
    """``collect_events(sub, done, timeout)``: events until ``done(kinds seen)`` holds; fails on timeout."""
    return _collect_events


@pytest.fixture(scope="session")
def kill_and_restart():
    """``kill_and_restart(world, adapter, bus, events)``: kills and restarts an emulator; the events and frames."""
    return _kill_and_restart


@pytest.fixture(scope="session")
def check_kill_and_restart():
    """``check_kill_and_restart(r)``: asserts what the acceptance asks of a killed and restarted device."""
    return _check_kill_and_restart
