"""Shared by the F/T device tests: a world link fed with known samples, emulator start-up, waiting."""
from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ftc_hw.bus import EVENTS_DEVICE, Bus
from ftc_hw.scene import DeviceSpec, load_scene
from ftc_hw.sim_devices.link import WorldLink
from ftc_hw.sim_devices.runner import EmulatorProcess


def wrench_of(k: int) -> np.ndarray:
    """Sample k: distinct on every axis, a multiple of 0.01 N and 0.001 N m (exact in every format)."""
    f = [((k * 7 + 3 * a) % 2001 - 1000) * 0.01 for a in range(3)]
    t = [((k * 11 + 5 * a) % 2001 - 1000) * 0.001 for a in range(3)]
    return np.round(np.array(f + t), 3)


class SyntheticWorld:
    """A :class:`WorldLink` fed at ``rate_hz`` from a thread: sample k at t = k / rate, wrench ``fn(k)``."""

    def __init__(self, rate_hz: float, n_joints: int = 3, fn: Callable[[int], np.ndarray] = wrench_of,
                 saturated: Callable[[int], np.ndarray] | None = None) -> None:
        self.rate_hz = rate_hz
        self.link = WorldLink(n_joints)
        self.fn = fn
        self.saturated = saturated or (lambda k: np.zeros(6, dtype=bool))
        self.k = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        z = np.zeros(n_joints)
        self.link.publish_joints(0.0, z, z, z, z, z)

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
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self.link.close()

    def __enter__(self) -> SyntheticWorld:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def device(scene_name: str, kind: str, transport: str | None = None, **params) -> tuple:
    """The scene and the scene's device of ``kind`` (params and transport overridden)."""
    scene = load_scene(scene_name)
    d = next(d for d in scene.devices if d.kind == kind)
    spec = DeviceSpec(d.name, d.kind, transport or d.transport, d.address, {**d.params, **params})
    return scene, spec


def start_emulator(spec: DeviceSpec, scene, world: SyntheticWorld, tmp_path: Path, **options) -> EmulatorProcess:
    options.setdefault("path", str(tmp_path / f"{spec.name}.tty"))
    options.setdefault("stats_path", str(tmp_path / f"{spec.name}-stats.json"))
    return EmulatorProcess.start(spec, scene, world.link.info, options)


def read_stats(emu: EmulatorProcess, tmp_path: Path) -> dict:
    p = tmp_path / f"{emu.device.name}-stats.json"
    return json.loads(p.read_text()) if p.exists() else {}


def wait_for(cond: Callable[[], bool], timeout: float, step: float = 0.01) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(step)
    return cond()


def wait_done(emu: EmulatorProcess, tmp_path: Path, timeout: float = 20.0) -> dict:
    """Until the emulator sent its ``max_frames`` (stats say done), then its final stats."""
    assert wait_for(lambda: read_stats(emu, tmp_path).get("done", False), timeout), read_stats(emu, tmp_path)
    time.sleep(0.25)  # the stats file is rewritten at most every 0.1 s; frames in flight arrive
    return read_stats(emu, tmp_path)


def settle(adapter, quiet_s: float = 0.3, timeout: float = 10.0) -> None:
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


def device_events(bus: Bus):
    return bus.subscribe(EVENTS_DEVICE, maxsize=None)
