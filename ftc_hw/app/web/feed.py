"""``--view web``: the page's process (:mod:`ftc_hw.app.web.page`, started with ``spawn``) and, in the
monitor's process, the subscriber that feeds it: a thread that at ``rate_hz`` (``--view-hz``) reads the
bus's and the monitor's newest state (never waiting on either; events through a queue subscription of
their own) and puts a tick into a bounded queue to the page; a contact's onset, first point and offset
make a tick at once, whatever the rate. A full queue drops its oldest tick (a page behind wants fresh data), counted in
``drops``: neither the bus nor the pipeline ever waits on the page.

When the monitor falls behind its input (its newest frame judged over ``BEHIND_MS`` after it arrived)
the feed halves its rate, down to ``SLOWEST_HZ``, and comes back as the monitor catches up
(:class:`RatePacer`): the view degrades before the pipeline does (a browser on the same host costs it
cores). The page and the summary say so.
"""
from __future__ import annotations

import contextlib
import multiprocessing
import queue
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ftc_hw.bus import Bus, ContactEvent, Empty, SubscriptionClosed
from ftc_hw.record.foxglove_view import FoxgloveView
from ftc_hw.scene import Scene

from . import page as web_page
from .state import TruthTail, WebSampler, page_setup

RATE_HZ = 10.0  # --view-hz's default: see docs/monitor.md for what a browser's rendering costs
QUEUE_TICKS = 32  # a second or more: a page further behind loses its oldest ticks
START_TIMEOUT_S = 60.0
BEHIND_MS = 20.0  # the monitor's newest judge lag above this: the feed halves its rate
SLOWEST_HZ = 1.0  # how far it slows down (an onset or offset still makes a tick at once)


class WebViewError(RuntimeError):
    """The page could not be served (its process failed or said nothing in time)."""


@dataclass(frozen=True)
class WebOptions:
    host: str = "127.0.0.1"  # loopback: another address only when the user says so
    port: int = 8080  # taken: the next free one (the URL says which)
    rate_hz: float = RATE_HZ  # the ticks a second (--view-hz)


class RatePacer:
    """The feed's rate: ``view_hz`` while the monitor keeps up; halved at each tick that finds it behind
    (``update(behind_ms, dt_s)``), down to ``SLOWEST_HZ``; up again by a quarter at each tick that finds
    it under half of ``BEHIND_MS``. ``slowdowns`` (from ``view_hz``) and ``slowed_s`` keep the record."""

    def __init__(self, view_hz: float) -> None:
        self.view_hz = self.hz = float(view_hz)
        self.slowest_hz = min(SLOWEST_HZ, self.view_hz)
        self.slowdowns = 0
        self.slowed_s = 0.0

    def update(self, behind_ms: float, dt_s: float) -> float:
        if self.hz < self.view_hz:
            self.slowed_s += dt_s
        if behind_ms > BEHIND_MS and self.hz > self.slowest_hz:
            self.slowdowns += self.hz == self.view_hz
            self.hz = max(self.slowest_hz, self.hz / 2)
        elif behind_ms < BEHIND_MS / 2 and self.hz < self.view_hz:
            self.hz = min(self.view_hz, self.hz * 1.25)
        return self.hz


class PageProcess:
    """The page's process: ``start()`` -> its URL; ``put(msg)`` never waits on the page (drops the oldest when
    full); ``close()``. ``timeline``: a replay's ticks, played by the page itself."""

    def __init__(self, setup: dict[str, Any], options: WebOptions,
                 timeline: list[dict[str, Any]] | None = None) -> None:
        ctx = multiprocessing.get_context("spawn")  # no fork of a process with threads and a MuJoCo model
        self.inbox = ctx.Queue(QUEUE_TICKS)
        self._outbox = ctx.Queue()
        self.options = options
        self.process = ctx.Process(target=web_page.serve, name="ftc-web-page", daemon=True,
                                   args=(self.inbox, self._outbox, setup, options.host, options.port, timeline))
        self.url = ""
        self.drops = 0
        self.stats: dict[str, Any] = {}  # from the page at its end: how late it drew the ticks (ms)
        self._closed = False

    def start(self, timeout: float = START_TIMEOUT_S) -> str:
        self.process.start()
        end = time.monotonic() + timeout
        while True:
            try:
                _, port = self._outbox.get(timeout=0.2)
                break
            except queue.Empty:
                if not self.process.is_alive():
                    raise WebViewError(f"the page's process exited (code {self.process.exitcode}) before it "
                                       f"served on {self.options.host}:{self.options.port}") from None
                if time.monotonic() > end:
                    self.close()
                    raise WebViewError(f"the page did not start within {timeout:g} s") from None
        host = self.options.host
        self.url = f"http://{'[' + host + ']' if ':' in host else host}:{port}/"
        return self.url

    def put(self, msg: Any) -> None:
        """Never waits on the page; the feed's own thread waits at most a few times 50 ms for the queue's
        own feeder thread (a full queue's oldest tick may not have reached the pipe yet)."""
        for _ in range(3):
            try:
                self.inbox.put_nowait(msg)
                return
            except queue.Full:
                with contextlib.suppress(queue.Empty):
                    self.inbox.get(timeout=0.05)
                    self.drops += 1
        self.drops += 1  # this one

    @property
    def alive(self) -> bool:
        return self.process.is_alive()

    def close(self, timeout: float = 5.0) -> None:
        if self._closed:
            return
        self._closed = True
        if self.process.is_alive():
            self.put(None)
            with contextlib.suppress(queue.Empty):
                self.stats = self._outbox.get(timeout=timeout)[1]
            self.process.join(timeout)
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(timeout)
        self.inbox.cancel_join_thread()  # a page gone takes no more: never hang on its queue at exit
        self.inbox.close()
        self._outbox.close()


class WebFeed:
    """The run's page: ``serve()`` -> its URL (early: the page loads while the world starts), then
    ``feed(...)`` starts the ticks, one every 1/``rate_hz`` s until ``close()``."""

    def __init__(self, scene: Scene, title: str, options: WebOptions) -> None:
        self.view = FoxgloveView(scene)  # the recordings' scene description: the page draws the same
        self.page = PageProcess(page_setup(self.view, title), options)
        self.pacer = RatePacer(options.rate_hz)
        self.monitor: Any = None
        self.ticks = 0
        self.errors = 0
        self.last_error = ""
        self.sampler: WebSampler | None = None
        self._truth: TruthTail | None = None
        self._events = None
        self._placed: set[int] = set()  # the contacts whose first point has been sent
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="ftc-web-feed", daemon=True)

    @property
    def url(self) -> str:
        return self.page.url

    @property
    def drops(self) -> int:
        return self.page.drops

    def serve(self) -> str:
        return self.page.start()

    def feed(self, bus: Bus, monitor: Any, topics: list[str], *, ft_topic: str,
             truth_path: Path | None = None) -> None:
        self._truth = TruthTail(truth_path) if truth_path is not None else None
        self.sampler = WebSampler(bus, monitor, self.view, topics, ft_topic=ft_topic, t0_ns=time.monotonic_ns(),
                                  truth=self._truth)
        self.monitor = monitor
        self._events = bus.subscribe("events/", maxsize=4096)
        self._thread.start()

    def _run(self) -> None:
        next_t = last_t = time.monotonic()
        while not self._stop.is_set():
            urgent = self._wait(next_t)
            now = time.monotonic()
            try:
                if not urgent:
                    self.pacer.update(getattr(self.monitor, "lag_ns", 0) / 1e6, now - last_t)
                    last_t = now
                tick = self.sampler.tick(time.monotonic_ns())
                tick.update(drops=self.page.drops, rate_hz=self.pacer.hz, view_hz=self.pacer.view_hz)
                self.page.put(tick)
                self.ticks += 1
            except Exception as exc:  # noqa: BLE001 - the page shows less, the monitor goes on; counted
                self.errors += 1
                self.last_error = f"{type(exc).__name__}: {exc}"
            if not urgent:
                next_t = max(next_t + 1.0 / self.pacer.hz, time.monotonic())

    def _wait(self, until: float) -> bool:
        """The events until ``until`` (monotonic s) to the sampler; True at once on an onset or offset."""
        while not self._stop.is_set():
            remaining = until - time.monotonic()
            if remaining <= 0:
                return False
            try:
                ev = self._events.get(timeout=remaining)
            except Empty:
                return False
            except SubscriptionClosed:
                self._stop.wait(remaining)
                return False
            self.sampler.add(ev)
            if self._urgent(ev):
                for more in self._events.drain():
                    self.sampler.add(more)
                return True
        return False

    def _urgent(self, ev: Any) -> bool:
        """An onset, an offset, or a contact's first point (an onset may come before its first estimate)."""
        if not isinstance(ev, ContactEvent):
            return False
        first_point = "no_estimate" not in ev.flags and ev.contact_id not in self._placed
        if first_point:
            self._placed.add(ev.contact_id)
        return first_point or ev.kind != "update"

    @property
    def summary(self) -> dict[str, Any]:
        """For the run's summary: ticks sent and dropped, the rate asked, how often and long it slowed down."""
        return {"url": self.url, "ticks": self.ticks, "dropped": self.drops, "errors": self.errors,
                "view_hz": self.pacer.view_hz, "slowdowns": self.pacer.slowdowns,
                "slowed_s": round(self.pacer.slowed_s, 1), **self.page.stats}

    def close(self) -> None:
        if self._stop.is_set():
            return
        self._stop.set()
        if self._events is not None:
            self._events.close()  # wakes the feed's thread
        if self._thread.is_alive():
            self._thread.join(2.0)
        if self._truth is not None:
            self._truth.close()
        self.page.close()
