"""Staleness watchdog: reports topics that stopped receiving frames.

For every watched topic, once no frame has been received for longer than its timeout (judged on the
newest frame's ``t_host_ns``, or on the watchdog's start for a topic that never received one), one
``DeviceEvent(kind="stale")`` is published on ``events/device``; when a newer frame arrives, one
``DeviceEvent(kind="recovered")``. The event's ``source`` is the topic's part after the first ``/``
(``"ft0"`` for ``"wrench/ft0"``), its counters hold ``age_s`` and ``timeout_s``.

:meth:`Watchdog.check` holds the whole logic and takes the current time as an argument, so it can be
driven deterministically; :meth:`Watchdog.start` runs it every ``period`` s in a daemon thread.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping

from .bus import EVENTS_DEVICE, Bus
from .frames import DeviceEvent

__all__ = ["Watchdog"]

log = logging.getLogger(__name__)


class Watchdog:
    """Watches ``timeouts`` (topic -> seconds) on ``bus``; ``clock`` returns host time in ns."""

    def __init__(
        self,
        bus: Bus,
        timeouts: Mapping[str, float],
        period: float = 0.05,
        *,
        clock: Callable[[], int] = time.monotonic_ns,
    ) -> None:
        if period <= 0 or any(t <= 0 for t in timeouts.values()):
            raise ValueError("period and timeouts must be > 0 s")
        self.bus = bus
        self.period = period
        self.clock = clock
        self._timeouts_ns = {topic: int(t * 1e9) for topic, t in timeouts.items()}
        self._since_ns: int | None = None  # baseline for topics that never received a frame
        self._stale: dict[str, int | None] = {}  # stale topic -> newest t_host_ns when declared stale
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    @property
    def stale_topics(self) -> frozenset[str]:
        """Topics currently declared stale."""
        return frozenset(self._stale)

    def check(self, now_ns: int) -> list[DeviceEvent]:
        """Compare every watched topic with ``now_ns``; publish and return the resulting events."""
        with self._lock:
            if self._since_ns is None:
                self._since_ns = now_ns
            events: list[DeviceEvent] = []
            for topic, timeout_ns in self._timeouts_ns.items():
                frame = self.bus.latest(topic)
                last = None if frame is None else frame.t_host_ns
                age = now_ns - (self._since_ns if last is None else last)
                if topic not in self._stale:
                    if age > timeout_ns:
                        self._stale[topic] = last
                        events.append(self._event(now_ns, topic, "stale", age, timeout_ns))
                elif self._is_new(last, self._stale[topic]) and age <= timeout_ns:  # fresh, not just late
                    del self._stale[topic]
                    events.append(self._event(now_ns, topic, "recovered", age, timeout_ns))
        for ev in events:
            self.bus.publish(EVENTS_DEVICE, ev)
        return events

    @staticmethod
    def _is_new(last: int | None, at_stale: int | None) -> bool:
        return last is not None and (at_stale is None or last > at_stale)

    @staticmethod
    def _event(now_ns: int, topic: str, kind: str, age_ns: int, timeout_ns: int) -> DeviceEvent:
        if kind == "stale":
            message = f"no frame on {topic} for {age_ns / 1e9:.3f} s (timeout {timeout_ns / 1e9:.3f} s)"
        else:
            message = f"frames on {topic} resumed"
        source = topic.split("/", 1)[-1] or topic
        counters = {"age_s": age_ns / 1e9, "timeout_s": timeout_ns / 1e9}
        return DeviceEvent.make(now_ns, source, kind, message, counters)  # type: ignore[arg-type]

    # -- thread -----------------------------------------------------------------------------------
    @property
    def running(self) -> bool:
        return self._thread is not None

    def start(self) -> Watchdog:
        """Start checking in a daemon thread (no-op if running)."""
        if self._thread is None:
            with self._lock:
                if self._since_ns is None:
                    self._since_ns = self.clock()
            self._stop = threading.Event()
            self._thread = threading.Thread(
                target=self._run, args=(self._stop,), name="bus-watchdog", daemon=True
            )
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and wait for it (no-op if not running)."""
        thread, self._thread = self._thread, None
        if thread is not None:
            self._stop.set()
            thread.join()

    def _run(self, stop: threading.Event) -> None:
        while not stop.wait(self.period):
            try:
                self.check(self.clock())
            except Exception:  # keep watching: one failed check must not end the watchdog
                log.exception("watchdog check failed")

    def __enter__(self) -> Watchdog:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
