"""The rig of a monitor whose devices are served by reader processes (``ftc serve`` elsewhere, or the
monitor's own :class:`~ftc_hw.app.serving.serve.ServedReaders`): the frames of ``ftc/<rig>/...`` taken from Zenoh
into the monitor's bus, and its contact events published back. It stands where
:class:`~ftc_hw.app.setup.rig.Rig` stands for local adapters: ``open()``, ``wait()``, ``close()``, ``adapters``
(here each reader's counters as it last said them, ``counters`` device events; plus local ones ``add``-ed,
such as a simulated world's joint source)."""
from __future__ import annotations

import contextlib
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh

from ftc_hw.app.setup.rig import RigError
from ftc_hw.bus import EVENTS_CONTACT, EVENTS_DEVICE, Bus, ContactEvent, DeviceEvent
from ftc_hw.bus.remote import RemoteError, RemotePublisher, RemoteSubscriber, connect_session, stop_key
from ftc_hw.bus.wire import encode

from .serve import ServedReaders

FINAL_COUNTERS_WAIT_S = 2.0


@dataclass
class ServedAdapter:
    """A reader process's adapter as the monitor knows it: its name, kind and last counters."""

    name: str
    kind: str
    counters: dict[str, float] = field(default_factory=dict)

    @property
    def final(self) -> bool:
        return bool(self.counters.get("final"))


class RemoteRig:
    """Frames from ``endpoint`` (a client of the router there) for ``topics`` of ``rig``. With ``readers``
    (not started), the rig starts them on open and stops them on close, first, so that their final
    counters arrive."""

    def __init__(self, bus: Bus, endpoint: str, rig: str, topics: Sequence[str], timeout: float = 20.0,
                 zenoh_config: Path | None = None, readers: ServedReaders | None = None) -> None:
        self.bus, self.endpoint, self.rig, self.topics, self.timeout = bus, endpoint, rig, tuple(topics), timeout
        self.zenoh_config, self.readers = zenoh_config, readers
        self.arm_name = next((t.split("/", 1)[1] for t in topics if t.startswith("joints/")), "arm")
        self._stop_pub: Any = None
        self.served: dict[str, ServedAdapter] = {}
        self.local: list[Any] = []
        self.arm = None
        self._counters_sub = bus.subscribe(EVENTS_DEVICE, callback=self._on_device_event)
        self._supervisor_sub: Any = None
        self._session: Any = None
        self._sub: RemoteSubscriber | None = None
        self._pub: RemotePublisher | None = None
        self._final: dict[str, Any] = {}

    def _on_device_event(self, ev: DeviceEvent) -> None:
        if ev.kind == "counters":
            self.served[ev.source] = ServedAdapter(ev.source, ev.message, dict(ev.counters))

    @property
    def adapters(self) -> list[Any]:
        """The served readers' adapters (their counters as last said), then the local ones."""
        return [*self.served.values(), *self.local]

    def add(self, adapter: Any) -> Any:
        """A local adapter (opened and closed with the rig)."""
        self.local.append(adapter)
        return adapter

    def open(self) -> RemoteRig:
        if self.readers is not None and self._session is None:
            self.readers.start()
            self._session = self.readers.session  # the router itself: one hop to the readers, not two
            # the supervisor's word (a reader exited, restarted) is this process's: not over Zenoh
            self._supervisor_sub = self.readers.bus.subscribe(
                EVENTS_DEVICE, callback=lambda ev: self.bus.publish(EVENTS_DEVICE, ev))
        for a in self.local:
            a.open()
        if self._session is None:
            try:
                self._session = connect_session(self.endpoint, self.timeout, config_file=self.zenoh_config)
            except RemoteError as exc:
                raise RigError(f"{exc} (for {self.timeout:g} s: is ftc serve listening there, and do the "
                               "credentials of --zenoh-config match its?)") from None
        if self._sub is None:
            self._sub = RemoteSubscriber(self._session, self.bus, self.rig)
            self._pub = RemotePublisher(self._session, self.bus, self.rig, prefixes=(EVENTS_CONTACT,))
        if self._stop_pub is None and self._local_arm() is None:  # declared now: the first stop must not wait
            self._stop_pub = self._session.declare_publisher(stop_key(self.rig, self.arm_name), express=True,
                                                             congestion_control=zenoh.CongestionControl.BLOCK)
        return self

    def _local_arm(self) -> Any:
        return next((a for a in self.local if getattr(a, "role", None) == "arm"), None)

    def wait(self, timeout: float | None = None) -> None:
        """Until every topic has had a frame; RigError naming the silent ones and what did arrive."""
        end = time.monotonic() + (self.timeout if timeout is None else timeout)
        while time.monotonic() < end:
            if all(self.bus.latest(t) is not None for t in self.topics):
                return
            time.sleep(0.02)
        silent = [t for t in self.topics if self.bus.latest(t) is None]
        counts = self._sub.counts if self._sub is not None else None
        raise RigError(f"no frames on {', '.join(f'ftc/{self.rig}/{t}' for t in silent)} from {self.endpoint} "
                       f"within {self.timeout:g} s (is ftc serve --scene ... running there, with --name "
                       f"{self.rig}?); received {counts}")

    def stop_arm(self, onset: ContactEvent) -> None:
        """The reflex across the process boundary: the onset to the arm's reader (``ftc serve``), which
        stops the arm and says so (a ``stopped`` event with its latency from the onset sample); a local
        arm (a simulated world's joint source) is stopped here."""
        local_arm = self._local_arm()
        if local_arm is not None:
            local_arm.stop()
            return
        if self._stop_pub is None:
            raise RigError("not connected")
        self._stop_pub.put(encode(onset))

    @property
    def counts(self) -> dict[str, Any]:
        """What was taken and dropped (after close: at close)."""
        if self._sub is None:
            return self._final
        return self._sub.counts.summary() | {"events_sent": self._pub.sent if self._pub else 0}

    def close(self) -> None:
        """Idempotent: stops the readers it started (waiting for their final counters), stops taking
        frames and publishing events, closes the session."""
        for a in self.local:
            a.close()
        if self.readers is not None:
            self.readers.stop_readers()
            end = time.monotonic() + FINAL_COUNTERS_WAIT_S
            names = [s.name for s in self.readers.specs]
            while time.monotonic() < end and not all(n in self.served and self.served[n].final for n in names):
                time.sleep(0.02)
        self._counters_sub.close()
        if self._supervisor_sub is not None:
            self._supervisor_sub.close()
        if self._sub is not None:
            self._final = self.counts
        if self._stop_pub is not None:
            with contextlib.suppress(zenoh.ZError):
                self._stop_pub.undeclare()
            self._stop_pub = None
        for part in (self._pub, self._sub):
            if part is not None:
                part.close()
        if self.readers is not None:
            self.readers.stop()  # and its router, our session
        elif self._session is not None:
            self._session.close()
        self._session = self._sub = self._pub = None
