"""The device adapter base: explicit lifecycle, a reader thread that owns the I/O loop, reconnect with
backoff, counters, and events on the bus instead of silent deaths.

Subclasses implement ``_connect()`` (open the transport, raise on failure), ``_read_once()`` (block
for at most ``poll_timeout`` s, publish what arrived, return normally; raise ``DeviceIOError`` when
the link is broken) and ``_disconnect()`` (close, never raise). Everything else is here.
"""
from __future__ import annotations

import gc
import sys
import threading
import time
from abc import ABC, abstractmethod
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from ftc_hw.bus import EVENTS_DEVICE, Bus, DeviceEvent
from ftc_hw.priority import READER_NICE, preferred_cpu

NOTE_EVERY_S = 10.0  # while a device stays unreachable, its reconnecting event is repeated this often


def one_line(exc: BaseException) -> str:
    """An exception as one line: vendor libraries' messages can span lines (and carry C++ type names)."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 200 else text[:197] + "..."


class DeviceError(Exception):
    """A device-level failure the caller should see (bad configuration, refused command)."""


class DeviceIOError(DeviceError):
    """The link to the device is broken: the reader reconnects."""


class Adapter(ABC):
    """One device on the bus. ``open``/``close`` are idempotent; use it as a context manager."""

    kind = "device"
    role = ""  # "ft" (publishes WrenchFrames) or "arm" (JointFrames)
    topic = ""  # the bus topic it publishes its frames on

    def __init__(self, name: str, bus: Bus, *, reconnect_backoff: tuple[float, float] = (0.05, 1.0),
                 poll_timeout: float = 0.05) -> None:
        self.name = name
        self.bus = bus
        self.counters: Counter[str] = Counter()
        self.backoff_min, self.backoff_max = reconnect_backoff
        self.poll_timeout = poll_timeout
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self.connected = threading.Event()

    # -- lifecycle -----------------------------------------------------------------------------------
    def open(self) -> Adapter:
        with self._lock:
            if self._thread is not None:
                return self
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name=f"{self.kind}:{self.name}", daemon=True)
            self._thread.start()
        return self

    def close(self) -> None:
        with self._lock:
            thread, self._thread = self._thread, None
        if thread is None:
            return
        self._stop.set()
        thread.join(timeout=5.0)
        self._safe_disconnect()
        self.connected.clear()

    def __enter__(self) -> Adapter:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def roles(self) -> frozenset[str]:
        """The rig roles it fills: its ``role``; an arm that also reads its own F/T sensor says both."""
        return frozenset({self.role}) if self.role else frozenset()

    @property
    def topics(self) -> tuple[str, ...]:
        """The bus topics it publishes frames on (one per kind of frame)."""
        return (self.topic,)

    def wait_connected(self, timeout: float) -> bool:
        return self.connected.wait(timeout)

    # -- events ----------------------------------------------------------------------------------------
    def event(self, kind: str, message: str = "") -> None:
        self.counters[f"event_{kind}"] += 1
        self.bus.publish(EVENTS_DEVICE, DeviceEvent.make(time.monotonic_ns(), self.name, kind, message,
                                                         dict(self.counters)))

    # -- the reader loop -------------------------------------------------------------------------------
    def _run(self) -> None:
        backoff = self.backoff_min
        attempts = 0  # failed connects of this outage
        next_note = 0.0
        while not self._stop.is_set():
            try:
                self._connect()
            except Exception as exc:  # noqa: BLE001 - any failure to connect is retried
                self._safe_disconnect()  # a half-open transport would hold the port (exclusive lock) for good
                self.counters["connect_failures"] += 1
                attempts += 1
                if time.monotonic() >= next_note:  # once per outage, then a reminder every NOTE_EVERY_S
                    self.event("reconnecting", f"connect failed ({one_line(exc)}); retrying every "
                               f"{self.backoff_min:g}-{self.backoff_max:g} s, attempt {attempts} "
                               "(connect_failures counts them)")
                    next_note = time.monotonic() + NOTE_EVERY_S
                if self._stop.wait(backoff):
                    break
                backoff = min(self.backoff_max, backoff * 2)
                continue
            backoff = self.backoff_min
            self.connected.set()
            self.event("connect", self.describe() + (f" (after {attempts} failed attempts)" if attempts else ""))
            attempts, next_note = 0, 0.0
            try:
                while not self._stop.is_set():
                    self._read_once()
            except DeviceIOError as exc:
                self.connected.clear()  # before the event: whoever sees it sees the adapter disconnected
                self.counters["disconnects"] += 1
                self.event("disconnect", one_line(exc))
            except Exception as exc:  # noqa: BLE001 - the reader never dies silently
                self.connected.clear()
                self.counters["errors"] += 1
                self.event("error", f"{type(exc).__name__}: {one_line(exc)}")
            finally:
                self.connected.clear()
                self._safe_disconnect()

    def _safe_disconnect(self) -> None:
        try:
            self._disconnect()
        except Exception:  # noqa: BLE001 - closing a broken link may fail; nothing to do about it
            self.counters["close_errors"] += 1

    def describe(self) -> str:
        return self.kind

    @abstractmethod
    def _connect(self) -> None: ...

    @abstractmethod
    def _read_once(self) -> None: ...

    @abstractmethod
    def _disconnect(self) -> None: ...

    def status(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "connected": self.connected.is_set(), **self.counters}


READER_SWITCH_INTERVAL_S = 0.0005


@contextmanager
def frozen_heap() -> Iterator[None]:
    """Every object alive now (modules, MuJoCo models, compiled kernels, the pipeline, the adapters)
    out of the cyclic garbage collector's reach while the block runs. A full collection otherwise
    walks all of them (~200 000 in the monitor) with the interpreter held: measured 59-111 ms pauses
    in a 30 s ur5e run, in which no reader ran (RTDE lost its packets, the F/T stream stalled 90 ms,
    its frames then had no joint state). Enter it once set up, before the streams matter. No
    collection first: that is itself such a pause (whatever garbage is frozen is freed at the exit)."""
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


@contextmanager
def responsive_readers(interval_s: float = READER_SWITCH_INTERVAL_S) -> Iterator[None]:
    """Run with a short interpreter switch interval and, when the OS allows, ahead of ordinary
    processes (ftc_hw.priority): device readers poll (ur_rtde keeps only its newest packet) and a
    reflex must go out while the pipeline computes; at Python's default 5 ms a thread that wakes can
    wait that long for the interpreter, and an ordinary process as long for a core on a busy host,
    longer than a 2 ms control period."""
    switch = sys.getswitchinterval()
    sys.setswitchinterval(min(switch, interval_s))
    try:
        with preferred_cpu(READER_NICE):
            yield
    finally:
        sys.setswitchinterval(switch)
