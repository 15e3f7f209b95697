"""A fault plan for a simulated run (``ftc monitor --sim --fault ...``): emulators killed, restarted or
stalled at given moments, so a cell's behaviour under faults can be rehearsed (and tested) through the
same adapters and client libraries as a clean run.

A fault is ``DEVICE:ACTION@WHEN``. ``ACTION``: ``kill`` (SIGKILL: a pulled plug), ``restart`` (start
the killed emulator again), ``stall:S`` (SIGSTOP for S seconds, then SIGCONT: a hung device).
``WHEN``: ``T`` (the scenario's time, s, as in the ground truth), ``+S`` (S s of wall time after the previous fault), or
``onset+S`` (S s after the next contact onset the monitor reports). Faults run one after another, in
the order given.
"""
from __future__ import annotations

import re
import threading
import time
from dataclasses import dataclass
from typing import Literal

from ftc_hw.bus import EVENTS_CONTACT, Bus
from ftc_hw.sim_devices.host import WorldHost

FAULT_RE = re.compile(r"^(?P<device>[\w-]+):(?P<action>kill|restart|stall:(?P<stall>[\d.]+))"
                      r"@(?P<when>onset\+[\d.]+|\+[\d.]+|[\d.]+)$")


class FaultError(ValueError):
    """A fault that cannot be parsed or applied (the message names it)."""


@dataclass(frozen=True)
class Fault:
    device: str
    action: Literal["kill", "restart", "stall"]
    trigger: Literal["time", "after", "onset"]
    delay_s: float  # scenario time (time), s after the previous fault (after) or after the onset (onset)
    stall_s: float = 0.0
    text: str = ""

    @classmethod
    def parse(cls, text: str) -> Fault:
        m = FAULT_RE.match(text.strip())
        if m is None:
            raise FaultError(f"fault {text!r}: expected DEVICE:ACTION@WHEN, ACTION kill, restart or stall:S, "
                             "WHEN a scenario time T, +S after the previous fault, or onset+S (e.g. ft:kill@onset+0.1)")
        when = m["when"]
        trigger = "onset" if when.startswith("onset") else "after" if when.startswith("+") else "time"
        action = "stall" if m["stall"] else m["action"]
        try:
            delay = float(when.split("+")[-1])
            stall = float(m["stall"]) if m["stall"] else 0.0
        except ValueError:
            raise FaultError(f"fault {text!r}: not a number of seconds") from None
        return cls(m["device"], action, trigger, delay, stall, text.strip())


class FaultPlan:
    """Runs the faults on their own thread against a world host; ``done`` lists what was applied
    (``(fault text, scenario time s when it was done)``), ``error`` what stopped the plan."""

    def __init__(self, faults: list[Fault], world: WorldHost, bus: Bus) -> None:
        unknown = sorted({f.device for f in faults} - set(world.endpoints))
        if unknown:
            raise FaultError(f"fault on {', '.join(unknown)}: no such emulated device "
                             f"(emulated: {', '.join(world.endpoints)})")
        self.faults = faults
        self.world = world
        self.done: list[tuple[str, float]] = []
        self.error: str | None = None
        self._onsets = bus.subscribe(EVENTS_CONTACT, maxsize=None)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fault-plan", daemon=True)

    def start(self) -> FaultPlan:
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the plan (a stalled emulator is resumed first); idempotent, harmless if never started."""
        self._stop.set()
        if self._thread.ident is not None:
            self._thread.join(10.0)
        self._onsets.close()

    def _run(self) -> None:
        last = time.monotonic()
        try:
            for fault in self.faults:
                if not self._wait(fault, last):
                    return
                self._apply(fault)
                last = time.monotonic()
                self.done.append((fault.text, self.world.scenario_time() or 0.0))
        except Exception as exc:  # noqa: BLE001 - reported in the run's summary
            self.error = f"{type(exc).__name__}: {exc}"

    def _wait(self, fault: Fault, last: float) -> bool:
        if fault.trigger == "onset":
            self._onsets.drain()
            while not any(e.kind == "onset" for e in self._onsets.drain()):
                if self._stop.wait(0.005):
                    return False
            return not self._stop.wait(fault.delay_s)
        if fault.trigger == "after":
            return not self._stop.wait(max(0.0, last + fault.delay_s - time.monotonic()))
        while (self.world.scenario_time() or 0.0) < fault.delay_s:
            if self._stop.wait(0.01) or self.world.done:
                return False
        return True

    def _apply(self, fault: Fault) -> None:
        if fault.action == "kill":
            self.world.kill(fault.device)
        elif fault.action == "restart":
            self.world.restart(fault.device)
        else:
            self.world.suspend(fault.device)
            try:
                self._stop.wait(fault.stall_s)
            finally:
                self.world.resume(fault.device)
