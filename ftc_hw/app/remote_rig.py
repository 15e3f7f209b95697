"""The rig of a monitor whose devices are served elsewhere (``ftc serve``): the frames of ``ftc/<rig>/...``
taken from Zenoh into the monitor's bus, and its contact events published back. It stands where
:class:`~ftc_hw.app.rig.Rig` stands for local adapters: ``open()``, ``wait()``, ``close()``,
``adapters`` (none here: the readers' counters are in their own processes)."""
from __future__ import annotations

import contextlib
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import zenoh

from ftc_hw.bus import EVENTS_CONTACT, Bus, ContactEvent
from ftc_hw.bus.remote import RemoteError, RemotePublisher, RemoteSubscriber, connect_session, stop_key
from ftc_hw.bus.wire import encode

from .rig import RigError


class RemoteRig:
    """Frames from ``endpoint`` (a client of the ``ftc serve`` router there) for ``topics`` of ``rig``."""

    def __init__(self, bus: Bus, endpoint: str, rig: str, topics: Sequence[str], timeout: float = 20.0,
                 zenoh_config: Path | None = None) -> None:
        self.bus, self.endpoint, self.rig, self.topics, self.timeout = bus, endpoint, rig, tuple(topics), timeout
        self.zenoh_config = zenoh_config
        self.arm_name = topics[1].split("/", 1)[1] if len(topics) > 1 else "arm"
        self._stop_pub: Any = None
        self.adapters: tuple[Any, ...] = ()
        self.arm = None
        self._session: Any = None
        self._sub: RemoteSubscriber | None = None
        self._pub: RemotePublisher | None = None
        self._final: dict[str, Any] = {}

    def open(self) -> RemoteRig:
        if self._session is None:
            try:
                self._session = connect_session(self.endpoint, self.timeout, config_file=self.zenoh_config)
            except RemoteError as exc:
                raise RigError(f"{exc} (for {self.timeout:g} s: is ftc serve listening there, and do the "
                               "credentials of --zenoh-config match its?)") from None
        if self._sub is None:
            self._sub = RemoteSubscriber(self._session, self.bus, self.rig)
            self._pub = RemotePublisher(self._session, self.bus, self.rig, prefixes=(EVENTS_CONTACT,))
        return self

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
        stops the arm and says so (a ``stopped`` event with its latency from the onset sample)."""
        if self._stop_pub is None:
            if self._session is None:
                raise RigError("not connected")
            self._stop_pub = self._session.declare_publisher(stop_key(self.rig, self.arm_name), express=True,
                                                             congestion_control=zenoh.CongestionControl.BLOCK)
        self._stop_pub.put(encode(onset))

    @property
    def counts(self) -> dict[str, Any]:
        """What was taken and dropped (after close: at close)."""
        if self._sub is None:
            return self._final
        return self._sub.counts.summary() | {"events_sent": self._pub.sent if self._pub else 0}

    def close(self) -> None:
        """Idempotent: stops taking frames and publishing events, closes the session."""
        if self._sub is not None:
            self._final = self.counts
        if self._stop_pub is not None:
            with contextlib.suppress(zenoh.ZError):
                self._stop_pub.undeclare()
            self._stop_pub = None
        for part in (self._pub, self._sub):
            if part is not None:
                part.close()
        if self._session is not None:
            self._session.close()
        self._session = self._sub = self._pub = None
