"""``ftc replay FILE.mcap --view web``: the page over a recording's ticks (made beforehand by the
same pipeline, :mod:`ftc_hw.app.web.replay`), played in the page's process with a play/pause button,
a time slider (seek) and a speed. A seek redraws from a clean page: the ticks of the few seconds before
the target are applied again (contacts, events and plots are what those seconds left)."""
from __future__ import annotations

import bisect
import queue
import time
from collections.abc import Callable
from typing import Any

REPLAY_CONTEXT_S = 10.0  # a seek replays this much before the target (the plots' window)
SLIDER_STEP_S = 1.0  # the time slider follows the play in steps (each move re-rasters a software browser's page)


class Player:
    """Plays ``timeline`` (ticks with ``t`` in s, ascending) into ``page``; the GUI controls it."""

    def __init__(self, page: Any, timeline: list[dict[str, Any]]) -> None:
        self.page, self.timeline = page, timeline
        self.times = [float(t["t"]) for t in timeline]
        end = self.times[-1] if self.times else 0.0
        gui = page.server.gui
        with gui.add_folder("replay", order=-1):
            self.play = gui.add_button("play")
            self.slider = gui.add_slider("t s", min=0.0, max=max(end, 0.1), step=0.05, initial_value=0.0)
            self.speed = gui.add_slider("speed", min=0.1, max=4.0, step=0.1, initial_value=1.0)
        self.playing = False  # until the first browser connects: a recording is watched from its start
        self.index = 0
        self._seek_to: float | None = None
        self._slider_set = 0.0  # what the player itself last put on the slider
        self.play.on_click(lambda _e: self._toggle())
        self.slider.on_update(lambda _e: self._on_slider())
        self._started = False
        page.server.on_client_connect(lambda _client: self._first_viewer())

    def _first_viewer(self) -> None:
        if not self._started:
            self._started = True
            self._toggle()

    def _toggle(self) -> None:
        self.playing = not self.playing
        if self.playing and self.index >= len(self.timeline):  # at the end: from the start again
            self._seek_to = 0.0
        self.play.label = "pause" if self.playing else "play"

    def _on_slider(self) -> None:
        value = float(self.slider.value)
        if abs(value - self._slider_set) > 1e-6:  # a user's move, not the player's own
            self._seek_to = value

    def seek(self, t: float) -> None:
        """Redraw the page as it was at ``t``."""
        self.page.reset()
        start = bisect.bisect_left(self.times, t - REPLAY_CONTEXT_S)
        stop = bisect.bisect_right(self.times, t)
        poses = None
        for tick in self.timeline[start:stop]:  # the newest pose is enough; events and plots from all
            poses = tick.get("poses", poses)
            self.page.apply({k: v for k, v in tick.items() if k != "poses"})
        if poses is not None and stop > start:
            self.page.apply({"t": self.times[stop - 1], "poses": poses})
        self.page.show_time(t)
        self.index = stop

    def run(self, inbox: Any, orphaned: Callable[[], bool]) -> None:
        """Until ``inbox`` gives ``None`` or ``orphaned()`` (the replay that started it is gone)."""
        t_wall, t_rec = time.monotonic(), 0.0
        checked = t_wall
        while True:
            try:
                if inbox.get(timeout=0.02) is None:
                    return
            except queue.Empty:
                pass
            if time.monotonic() - checked > 1.0:
                checked = time.monotonic()
                if orphaned():
                    return
            if self._seek_to is not None:
                t_rec, self._seek_to = self._seek_to, None
                self.seek(t_rec)
                t_wall = time.monotonic()
            if self.playing and self.index >= len(self.timeline):
                self._toggle()  # the end: paused there
            if not self.playing:
                t_wall = time.monotonic()
                continue
            now = time.monotonic()
            t_rec += (now - t_wall) * float(self.speed.value)
            t_wall = now
            while self.index < len(self.timeline) and self.times[self.index] <= t_rec:
                self.page.apply(self.timeline[self.index])
                self.index += 1
            if abs(self._slider_set - t_rec) >= SLIDER_STEP_S:
                self._slider_set = round(t_rec, 2)
                self.slider.value = self._slider_set
