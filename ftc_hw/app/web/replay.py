"""``ftc replay --view web``: a recording's page ticks, made while the same pipeline replays it (at
``rate_hz`` of recording time, as the live page gets them), then played by the page's own player
(:mod:`ftc_hw.app.web.player`: pause, seek, speed)."""
from __future__ import annotations

import signal
from typing import Any

from ftc_hw.bus import Bus
from ftc_hw.record.foxglove_view import FoxgloveView
from ftc_hw.scene import Scene

from .feed import RATE_HZ, PageProcess, WebOptions
from .state import WebSampler, page_setup


class ReplayTimeline:
    """``ready(monitor)`` and ``on_message(monitor)`` are :func:`ftc_hw.record.replay.replay`'s hooks;
    ``ticks`` the page's timeline after it."""

    def __init__(self, bus: Bus, scene: Scene, topics: list[str], *, t0_ns: int, rate_hz: float = RATE_HZ) -> None:
        self.bus, self.topics, self.t0_ns = bus, topics, t0_ns
        self.view = FoxgloveView(scene)
        self.period_ns = round(1e9 / rate_hz)
        self.ticks: list[dict[str, Any]] = []
        self._sampler: WebSampler | None = None
        self._events = bus.subscribe("events/", maxsize=None)
        self._next_ns = t0_ns

    def ready(self, monitor: Any) -> None:
        self._sampler = WebSampler(self.bus, monitor, self.view, self.topics, ft_topic=self.topics[0],
                                   t0_ns=self.t0_ns)

    def on_message(self, monitor: Any) -> None:
        frame = self.bus.latest(self.topics[0])
        if frame is None or frame.t_host_ns < self._next_ns:
            return
        self.tick(frame.t_host_ns)
        self._next_ns = frame.t_host_ns + self.period_ns

    def tick(self, now_ns: int) -> None:
        for ev in self._events.drain():
            self._sampler.add(ev)
        self.ticks.append(self._sampler.tick(now_ns))

    def finish(self) -> list[dict[str, Any]]:
        """The timeline, its last tick with the events after the last frame."""
        if self._sampler is not None and self.ticks:
            self.tick(self.ticks[-1]["t_host_ns"] + 1)
        self._events.close()
        return self.ticks

    def page(self, title: str, options: WebOptions) -> PageProcess:
        return PageProcess(page_setup(self.view, title), options, timeline=self.ticks)


def serve_until_interrupted(page: PageProcess, console: Any) -> None:
    """Serve the replay's page until Ctrl-C (or SIGTERM), its URL printed; then close it."""
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        url = page.start()
        console.print(f"the replay's page: [bold cyan]{url}[/] (play/pause, time slider); Ctrl-C ends it",
                      highlight=False)
        while page.alive:
            page.process.join(0.5)
        console.print(f"[yellow]the page's process ended (code {page.process.exitcode})[/]")
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        page.close()


def _interrupt(*_: Any) -> None:
    raise KeyboardInterrupt
