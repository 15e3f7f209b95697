"""``--view web``: the page's process (:mod:`ftc_hw.app.web_page`, started with ``spawn``) and, in the
monitor's process, the subscriber that feeds it: a thread that at ``rate_hz`` reads the bus's and the
monitor's newest state (never waiting on either; events through a queue subscription of their own)
and puts a tick into a bounded queue to the page. A full queue drops its oldest tick (a page behind
wants fresh data), counted in ``drops``: neither the bus nor the pipeline ever waits on the page.
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

from ftc_hw.bus import Bus
from ftc_hw.record.foxglove_view import FoxgloveView
from ftc_hw.scene import Scene

from . import web_page
from .web_state import TruthTail, WebSampler, page_setup

RATE_HZ = 30.0
QUEUE_TICKS = 32  # about a second at 30 Hz: a page further behind loses its oldest ticks
START_TIMEOUT_S = 60.0


class WebViewError(RuntimeError):
    """The page could not be served (its process failed or said nothing in time)."""


@dataclass(frozen=True)
class WebOptions:
    host: str = "127.0.0.1"  # loopback: another address only when the user says so
    port: int = 8080  # taken: the next free one (the URL says which)


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

    def __init__(self, scene: Scene, title: str, options: WebOptions, rate_hz: float = RATE_HZ) -> None:
        self.view = FoxgloveView(scene)  # the recordings' scene description: the page draws the same
        self.page = PageProcess(page_setup(self.view, title), options)
        self.period_s = 1.0 / rate_hz
        self.ticks = 0
        self.errors = 0
        self.last_error = ""
        self.sampler: WebSampler | None = None
        self._truth: TruthTail | None = None
        self._events = None
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
        self._events = bus.subscribe("events/", maxsize=4096)
        self._thread.start()

    def _run(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            try:
                for ev in self._events.drain():
                    self.sampler.add(ev)
                tick = self.sampler.tick(time.monotonic_ns())
                tick["drops"] = self.page.drops
                self.page.put(tick)
                self.ticks += 1
            except Exception as exc:  # noqa: BLE001 - the page shows less, the monitor goes on; counted
                self.errors += 1
                self.last_error = f"{type(exc).__name__}: {exc}"
            next_t = max(next_t + self.period_s, time.monotonic())
            self._stop.wait(next_t - time.monotonic())

    def close(self) -> None:
        if self._stop.is_set():
            return
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        if self._events is not None:
            self._events.close()
        if self._truth is not None:
            self._truth.close()
        self.page.close()
