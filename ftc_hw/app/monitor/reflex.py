"""The monitor's stop reflex: every contact onset stops the arm (``ftc monitor --reflex stop``)."""
from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from ftc_hw.bus import EVENTS_CONTACT, Bus, ContactEvent


class StopReflex:
    """On every contact onset, ``stop(onset)``: the local arm adapter's ``stop()`` from a thread of its own
    (it waits for the device: never in the pipeline's thread), or, ``inline``, a command to the arm's
    reader process (:meth:`~ftc_hw.app.serving.remote_rig.RemoteRig.stop_arm`: a Zenoh put that does not wait)
    at once in the thread that published the onset (a hand-over cost 0.2-0.3 ms, ftc bench reflex).
    It gets the onset before any other subscriber of the monitor's bus."""

    def __init__(self, bus: Bus, stop: Callable[[ContactEvent], None], inline: bool = False) -> None:
        self.stop, self.inline = stop, inline
        self.stops: list[dict[str, Any]] = []
        self.errors: list[str] = []
        self._pending: list[ContactEvent] = []
        self._wake = threading.Event()
        self._quit = False
        # first: the onset must not wait for the event's recording or its forwarding to Zenoh
        self._sub = bus.subscribe(EVENTS_CONTACT, callback=self._on_event, first=True)
        self._thread = threading.Thread(target=self._run, name="stop-reflex", daemon=True)
        self._thread.start()

    def _on_event(self, ev: ContactEvent) -> None:
        if ev.kind != "onset":
            return
        if self.inline:
            self._send(ev)
        else:
            self._pending.append(ev)
            self._wake.set()

    def _send(self, ev: ContactEvent) -> None:
        t0 = time.monotonic_ns()
        try:
            self.stop(ev)
            self.stops.append({"onset_t_host_ns": ev.t_host_ns, "sent_after_onset_ms": (t0 - ev.t_host_ns) / 1e6,
                               "stop_call_ms": (time.monotonic_ns() - t0) / 1e6})
        except Exception as exc:  # noqa: BLE001 - reported, the monitor goes on
            self.errors.append(f"{type(exc).__name__}: {exc}")

    def _run(self) -> None:
        while not self._quit:
            self._wake.wait(0.5)
            self._wake.clear()
            while self._pending:
                self._send(self._pending.pop(0))

    def close(self) -> None:
        self._sub.close()
        self._quit = True
        self._wake.set()
        self._thread.join(5.0)
