"""An emulator's own process: its entry point and the world's handle on it.

Kept apart from the runner so that an emulator process (``spawn`` imports the module of its entry
point) loads only the link and its protocol, never the world, MuJoCo's world loop or numba's kernels:
seconds of start-up per emulator on a loaded machine. Emulators are launched together and waited
for together; each one's start-up time is kept (``EmulatorProcess.started_s``).
"""
from __future__ import annotations

import contextlib
import importlib
import multiprocessing as mp
import queue
import sys
import time
from dataclasses import dataclass, field
from typing import Any

from ftc_hw.priority import DEVICE_NICE, end_process, name_process, prefer_cpu
from ftc_hw.scene import DeviceSpec, Scene

from .link import LinkInfo
from .registry import EMULATORS

EMULATOR_SWITCH_INTERVAL_S = 0.0002


class EmulatorStartError(RuntimeError):
    pass


def _entry(kind: str):
    target = EMULATORS.get(kind)
    if target is None:
        raise EmulatorStartError(f"no emulator for device kind {kind!r} (known: {', '.join(EMULATORS)})")
    module, func = target.split(":")
    return getattr(importlib.import_module(module), func)


def _serve(kind: str, device: DeviceSpec, scene: Scene, link: LinkInfo, ready, options: dict) -> None:
    """Entry point of an emulator process."""
    name_process(f"ftc-emu-{device.name}")
    # A device answers from its own threads (a dashboard reader beside the RTDE stream, a serial
    # reader beside the pacing loop): at Python's default 5 ms switch interval a thread ready to
    # answer can wait that long for the GIL, longer than a control period.
    sys.setswitchinterval(EMULATOR_SWITCH_INTERVAL_S)
    prefer_cpu(DEVICE_NICE, exact=True)  # below the world's tier even when the world started it
    try:
        serve = _entry(kind)
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which raises
        ready.put({"error": f"{type(exc).__name__}: {exc}"})
        return
    with contextlib.suppress(SystemExit):  # SIGTERM (the runner's stop), or the world's process gone
        serve(device, scene, link, ready, options)
    ready.close()
    ready.join_thread()  # what it put (its endpoint, or why it could not bind) is in the pipe
    end_process()


@dataclass
class Launched:
    """An emulator process started and not yet ready: :meth:`wait` for its endpoint."""

    device: DeviceSpec
    process: Any
    ready: Any
    t0: float

    def wait(self, timeout: float = 30.0) -> EmulatorProcess:
        try:
            endpoint = self.ready.get(timeout=max(0.0, self.t0 + timeout - time.monotonic()))
        except queue.Empty:
            self.process.terminate()
            raise EmulatorStartError(f"emulator for {self.device.name!r} ({self.device.kind}) did not start "
                                     f"within {timeout:g} s") from None
        if "error" in endpoint:
            self.process.join(timeout=5)
            raise EmulatorStartError(f"emulator for {self.device.name!r} ({self.device.kind}): {endpoint['error']}")
        return EmulatorProcess(self.device, self.process, endpoint, time.monotonic() - self.t0)

    def cancel(self) -> None:
        """Stop it (another emulator failed to start)."""
        self.process.terminate()
        self.process.join(5.0)


@dataclass
class EmulatorProcess:
    device: DeviceSpec
    process: Any
    endpoint: dict[str, Any] = field(default_factory=dict)
    started_s: float = 0.0  # from launch to ready
    asked_to_stop: bool = False

    @staticmethod
    def launch(device: DeviceSpec, scene: Scene, link: LinkInfo, options: dict | None = None) -> Launched:
        ctx = mp.get_context("spawn")
        ready = ctx.Queue()
        proc = ctx.Process(target=_serve, args=(device.kind, device, scene, link, ready, options or {}),
                           name=f"emulator:{device.name}", daemon=True)
        t0 = time.monotonic()
        proc.start()
        return Launched(device, proc, ready, t0)

    @classmethod
    def start(cls, device: DeviceSpec, scene: Scene, link: LinkInfo, options: dict | None = None,
              timeout: float = 30.0) -> EmulatorProcess:
        return cls.launch(device, scene, link, options).wait(timeout)

    @property
    def alive(self) -> bool:
        return self.process.is_alive()

    def ask_to_stop(self) -> None:
        """SIGTERM once, not waited for (:meth:`stop` waits)."""
        if not self.asked_to_stop and self.process.is_alive():
            self.process.terminate()
            self.asked_to_stop = True

    def stop(self, timeout: float = 5.0) -> None:
        self.ask_to_stop()
        self.process.join(timeout)
        if self.process.is_alive():
            self.process.kill()
            self.process.join(timeout)

    def kill(self) -> None:
        """Die like a pulled plug (tests use it): no clean shutdown."""
        self.process.kill()
        self.process.join(5.0)
