"""The web page of ``--view web`` (viser), in a process of its own: the arm at its pose with the
solver's primitives and the sensor's frame, the sensor's force and torque arrows, each contact (its
link highlighted, point, 95 % ellipsoid, force arrow, label with its flags) for ``CONTACT_KEEP_S``
after its last event, with ``--sim`` the world's true contact in green; beside it the current contact,
the last events, rolling plots of the external wrench and the detection statistic against its
threshold, and the streams. It draws what :mod:`ftc_hw.app.web.state` sends (ticks); the scene is
redrawn only when a tick changed it (the browser renders on demand), the panel beside it once a second
(an onset or offset at once), all of a tick in one message.

Scene names the tests read back (``window.__viserMutable.nodeRefFromName``): ``/contacts/<id>/sphere0``
is a contact's point (base frame: the root's children are in the base frame), ``/truth/sphere0`` the true one.
"""
from __future__ import annotations

import contextlib
import multiprocessing
import os
import queue
import signal
import sys
import time
from collections import deque
from typing import Any

import numpy as np
import viser

from ftc_hw.bus import STREAM_EVENT_KINDS

from .player import Player
from .scene import DrawnEntity

CONTACT_KEEP_S = 3.0  # a contact stays drawn this long after its last event (Foxglove's lifetime too)
EVENTS_KEEP_S = 5.0  # the events list: the last few seconds
PLOT_S = 10.0  # the plots' window
# The panel beside the scene (plots, contact text, streams) redrawn at most this often, an onset or
# offset at once. Each change of the page's text or plots costs a browser that renders in software a
# re-raster of the page (about a third of a core for every 2-4 changes a second, measured): the panel's
# changes are few and made together, with the scene's, in one message.
PANEL_PERIOD_S = 1.0
D2_FLOOR = 0.1  # the statistic's plot is logarithmic
HIGHLIGHT = (230, 40, 25)


def _fmt_mm(v) -> str:
    return " ".join(f"{1e3 * float(x):.1f}" for x in v)



def _hidden_shapes(size_m: float) -> dict[str, Any]:
    """A contact entity's shapes at the base's origin, ``size_m`` across (the base's sphere hides them)."""
    at = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"w": 1.0, "x": 0.0, "y": 0.0, "z": 0.0}}
    rgba = {"r": 0.9, "g": 0.2, "b": 0.1}
    return {"spheres": [{"pose": at, "size": {"x": size_m, "y": size_m, "z": size_m}, "color": {**rgba, "a": 0.3}}],
            "arrows": [{"pose": at, "shaft_length": size_m / 2, "shaft_diameter": size_m / 8,
                        "head_length": size_m / 4, "head_diameter": size_m / 4, "color": {**rgba, "a": 1.0}}]}


def _limits_md(c: dict[str, Any] | None) -> str:
    """An event's margin to its body region's limit (docs/limits.md), or nothing."""
    if not c:
        return ""
    return (f", {c['region']} {c['limit_kind'].replace('_', '-')} limit {c['limit_n']:.0f} N, "
            f"margin **{c['margin_n']:+.1f} N**")
BATCH_TICKS = 64  # at most this many waiting ticks drawn as one update


class Page:
    """The page's state; ``apply(tick)`` draws one tick, ``reset()`` forgets what time made (a seek)."""

    def __init__(self, server: viser.ViserServer, setup: dict[str, Any]) -> None:
        self.server, self.setup = server, setup
        scene, gui = server.scene, server.gui
        gui.configure_theme(control_layout="fixed", control_width="medium", show_share_button=False)
        scene.set_up_direction("+z")
        # no shadow maps, no environment map: most of a frame's cost where the browser renders in software
        scene.configure_default_lights(cast_shadow=False)
        scene.configure_environment_map(hdri=None)
        reach = float(setup["reach_m"])
        server.initial_camera.position = (0.75 * reach, -0.9 * reach, 0.6 * reach)
        server.initial_camera.look_at = (0.0, 0.0, 0.3 * reach)
        self.links: dict[str, Any] = {}
        self.colors: dict[str, list[tuple[Any, tuple[int, int, int]]]] = {}
        for ent in setup["arm"]:
            link = ent["frame_id"]
            self.links[link] = scene.add_frame(f"/arm/{link}", show_axes=False)
            drawn = DrawnEntity(scene, f"/arm/{link}")
            drawn.draw(ent)
            self.colors[link] = [(h, tuple(h.color)) for h in drawn.handles.values() if hasattr(h, "color")]
        for link in setup["links"]:
            if link not in self.links:
                self.links[link] = scene.add_frame(f"/arm/{link}", show_axes=False)
        pos, wxyz = setup["sensor_pose"]
        self.sensor = scene.add_frame(f"/arm/{setup['sensor_link']}/sensor", axes_length=0.12 * reach,
                                      axes_radius=0.006 * reach, position=pos, wxyz=wxyz)
        # named, and drawn as a contact is (an opaque sphere, a label): a browser has compiled those
        # shaders and loaded the labels' font before the first contact comes
        scene.add_label(f"/arm/{setup['sensor_link']}/sensor/label", "sensor", anchor="bottom-center")
        scene.add_icosphere("/base", radius=0.01 * reach, color=(90, 90, 90), subdivisions=2, flat_shading=True,
                            cast_shadow=False, receive_shadow=False)
        # and a contact's other shapes (its see-through ellipsoid, its force arrow), drawn once inside that sphere:
        # a browser that renders in software compiles their shaders in seconds (a CI run's first contact showed
        # 3.4 s after its onset, the next ones 0.15-0.45 s), at load rather than when the first contact comes
        DrawnEntity(scene, "/base/shapes").draw(_hidden_shapes(0.004 * reach))
        self.status = gui.add_markdown(f"**{setup['title']}**")
        self.contact_md = gui.add_markdown("contact: none yet")
        self.events_md = gui.add_markdown("")
        self._plots(gui)
        self.streams_md = gui.add_markdown("")
        self.reset()

    def _plots(self, gui: Any) -> None:
        empty = (np.zeros(1),) * 4
        x = {"x": {"time": False}}  # seconds, not dates
        self.force_plot = gui.add_uplot(empty, ({"label": "t"}, {"label": "fx N", "stroke": "red"},
                                                {"label": "fy N", "stroke": "green"},
                                                {"label": "fz N", "stroke": "blue"}),
                                        title="external force (sensor frame)", aspect=2.0, scales=x,
                                        axes=({"label": "t s"}, {"label": "N"}))
        self.torque_plot = gui.add_uplot(empty, ({"label": "t"}, {"label": "tx Nm", "stroke": "red"},
                                                 {"label": "ty Nm", "stroke": "green"},
                                                 {"label": "tz Nm", "stroke": "blue"}),
                                         title="external torque (sensor frame)", aspect=2.0, scales=x,
                                         axes=({"label": "t s"}, {"label": "N m"}))
        self.d2_plot = gui.add_uplot((np.zeros(1),) * 3, ({"label": "t"}, {"label": "d2", "stroke": "black"},
                                                          {"label": "onset above", "stroke": "orange", "dash": [6, 4]}),
                                     title="detection statistic (log)", aspect=2.0,
                                     scales={**x, "y": {"distr": 3}}, axes=({"label": "t s"}, {"label": "d2"}))

    def reset(self) -> None:
        if not hasattr(self, "contacts"):  # the first time
            self.contacts: dict[int, dict[str, Any]] = {}
            self.highlighted: set[str] = set()
            self.wrench = DrawnEntity(self.server.scene, f"/arm/{self.setup['sensor_link']}/sensor/wrench")
            self.truth = DrawnEntity(self.server.scene, "/truth")
            self.drops = 0
        for c in self.contacts.values():
            c["drawn"].remove()
        self.contacts = {}
        self._highlight()
        self.truth.remove()
        self.events: deque[tuple[float, str]] = deque(maxlen=40)
        self.device_events: deque[tuple[float, str]] = deque(maxlen=6)
        self.series: deque[tuple[float, ...]] = deque(maxlen=int(PLOT_S * 60))
        self._panel_t = -1e9
        self._streams: dict[str, Any] | None = None  # the newest streams not drawn yet
        self._truth: dict[str, Any] | None = None
        self._t = 0.0
        self.rate_note = ""  # the feed's rate when it slowed down (the monitor fell behind)

    def apply(self, *ticks: dict[str, Any]) -> None:
        """Draw ``ticks`` (oldest first) as one update: each one's events listed and samples plotted, the
        newest poses, truth and panels drawn (a page that fell behind catches up in one step, not tick by tick)."""
        last = ticks[-1]
        t = self._t = float(last["t"])
        with self.server.atomic():
            if (posed := _newest(ticks, "poses")) is not None:
                for link, (pos, wxyz) in zip(self.setup["links"], posed["poses"], strict=True):
                    h = self.links[link]
                    h.position, h.wxyz = pos, wxyz
            if (raw := _newest(ticks, "raw_entity")) is not None:
                self.wrench.draw({**raw["raw_entity"], "texts": []})
            newest = {}  # a contact drawn once an update: at its newest event (the others only listed)
            for tick in ticks:
                for ev in tick.get("events", ()):
                    self._event(float(tick["t"]), ev)
                    if "entity" in ev:
                        newest[ev["contact_id"]] = (float(tick["t"]), ev)
            for t_ev, ev in newest.values():
                self._draw_contact(t_ev, ev)
            if (truth := _newest(ticks, "truth")) is not None:
                self._truth = truth["truth"]
                self.truth.draw(truth["truth_entity"])
            self._expire(t)
            self.series.extend((float(k["t"]), *k["external"], k["d2"], k["threshold"]) for k in ticks
                               if "external" in k)
            if (streams := _newest(ticks, "streams")) is not None:
                self._streams = streams
            if (rate := _newest(ticks, "rate_hz")) is not None:
                self._rate(rate)
            news = any(ev.get("kind") != "update" for k in ticks for ev in k.get("events", ()))
            if t - self._panel_t >= PANEL_PERIOD_S or t < self._panel_t:
                self._panel_t = t
                self._draw_text(last)
                self._draw_plots()
                if self._streams is not None:
                    self._draw_streams(self._streams)
                    self._streams = None
            elif news:
                self._draw_text(last)  # an onset or offset at once

    def _event(self, t: float, ev: dict[str, Any]) -> None:
        if "contact_id" not in ev:  # a stream lost or back (with the contacts), or a device's own (with the streams)
            line = (t, f"{t:7.2f} s {ev['source']}: **{ev['kind']}** {ev['message']}")
            (self.events if ev["kind"] in STREAM_EVENT_KINDS else self.device_events).appendleft(line)
            return
        flags = ",".join(ev["flags"])
        force = float(np.linalg.norm(ev["force"]))
        if ev["kind"] != "update":
            self.events.appendleft((t, f"{t:7.2f} s #{ev['contact_id']} **{ev['kind']}** `{ev['link'] or '-'}` "
                                       f"{force:.1f} N, ± {_fmt_mm(ev['point_std'])} mm"
                                       + (f" [{flags}]" if flags else "") + _limits_md(ev.get("limits"))))

    def _draw_contact(self, t: float, ev: dict[str, Any]) -> None:
        cid = int(ev["contact_id"])
        c = self.contacts.setdefault(cid, {"drawn": DrawnEntity(self.server.scene, f"/contacts/{cid}")})
        c["drawn"].draw(ev["entity"])
        c["t"], c["ev"] = t, ev
        self._highlight()

    def _highlight(self) -> None:
        touched = {c["ev"]["link"] for c in self.contacts.values() if c["ev"]["kind"] != "offset"}
        for link in self.highlighted ^ touched:
            for h, base in self.colors.get(link, ()):
                h.color = HIGHLIGHT if link in touched else base
        self.highlighted = touched

    def _expire(self, t: float) -> None:
        for cid in [c for c, v in self.contacts.items() if t - v["t"] > CONTACT_KEEP_S]:
            self.contacts.pop(cid)["drawn"].remove()
            self._highlight()
        while self.events and t - self.events[-1][0] > EVENTS_KEEP_S:
            self.events.pop()

    def _draw_plots(self) -> None:
        if not self.series:
            return
        a = np.array(self.series)
        a = a[a[:, 0] >= self._t - PLOT_S]
        if len(a) < 2:
            return
        x = a[:, 0]
        self.force_plot.data = (x, a[:, 1], a[:, 2], a[:, 3])
        self.torque_plot.data = (x, a[:, 4], a[:, 5], a[:, 6])
        self.d2_plot.data = (x, np.maximum(a[:, 7], D2_FLOOR), a[:, 8])

    def _rate(self, tick: dict[str, Any]) -> None:
        hz, asked = tick["rate_hz"], tick.get("view_hz", tick["rate_hz"])
        self.rate_note = "" if hz >= asked else (f"  \n**view slowed to {hz:.1f} Hz** (of {asked:g}): "
                                                 "the monitor fell behind")

    def show_time(self, t: float) -> None:
        self.status.content = f"**{self.setup['title']}**  t {t:.1f} s{self.rate_note}"

    def _draw_text(self, tick: dict[str, Any]) -> None:
        self.show_time(self._t)
        open_ = [c["ev"] for c in self.contacts.values() if c["ev"]["kind"] != "offset"]
        if open_:
            lines = []
            for ev in open_:
                flags = ",".join(ev["flags"]) or "none"
                lines.append(f"**CONTACT #{ev['contact_id']}** on `{ev['link']}`  \n"
                             f"point {_fmt_mm(ev['point'])} mm (± {_fmt_mm(ev['point_std'])} mm, 1σ)  \n"
                             f"force {float(np.linalg.norm(ev['force'])):.1f} N, flags: {flags}")
            text = "\n\n".join(lines)
        else:
            text = "contact: **free**" if not tick.get("contact") else "contact: **detected**, no estimate yet"
        truth = self._truth
        if truth is not None:
            text += ("\n\ntrue contact (world, green): " + (f"`{truth['link']}`, point {_fmt_mm(truth['point'])} mm"
                                                          if truth.get("contact") else "none"))
        self.contact_md.content = text
        self.events_md.content = f"**events** (last {EVENTS_KEEP_S:g} s)  \n" + (
            "  \n".join(line for _, line in self.events) or "none")

    def _draw_streams(self, tick: dict[str, Any]) -> None:
        rows = ["| stream | frames | Hz | stale ms | max gap ms | seq missing |", "|---|--:|--:|--:|--:|--:|"]
        for r in tick["streams"]:
            stale = "-" if r.get("stale_ms") is None else f"{r['stale_ms']:.0f}"
            rows.append(f"| `{r['topic']}` | {r['frames']} | {r.get('rate_hz', 0):.0f} | {stale} | "
                        f"{r.get('max_gap_ms', 0):.1f} | {r.get('seq_missing', 0)} |")
        lost = tick.get("lost") or []
        counters = ", ".join(f"{k} {v}" for k, v in tick.get("counters", {}).items())
        devices = "  \n".join(line for _, line in self.device_events) or "none"
        self.streams_md.content = ("\n".join(rows) + ("\n\n**LOST: " + ", ".join(lost) + "**" if lost else "")
                                   + f"\n\n**device events** (the last {self.device_events.maxlen})  \n{devices}"
                                   + f"\n\nmonitor: {counters}; page updates dropped {self.drops}")


def serve(inbox: Any, outbox: Any, setup: dict[str, Any], host: str, port: int,
          timeline: list[dict[str, Any]] | None = None) -> None:
    """The page process's entry: serve, say the port on ``outbox``, then draw the ticks from ``inbox``
    (``None`` ends), or play ``timeline`` (a replay) until ``inbox`` says stop."""
    sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - viser prints its own banner: the monitor says the URL
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the monitor's: it closes the page
    server = viser.ViserServer(host=host, port=port, verbose=False)
    try:
        page = Page(server, setup)
        outbox.put(("ready", server.get_port()))
        if timeline is None:
            _live(page, inbox, outbox)
        else:
            Player(page, timeline).run(inbox, orphaned)
    finally:
        server.stop()


def _live(page: Page, inbox: Any, outbox: Any) -> None:
    """Draw the ticks until ``None``; then say on ``outbox`` how late they were drawn (ms from the tick's
    making, and from an onset's sample, to the page's sending it to the browsers)."""
    tick_ms: deque[float] = deque(maxlen=100_000)  # the last hour's at 30 Hz: a long run's memory stays flat
    onset_ms: deque[float] = deque(maxlen=1000)
    ticks = 0
    while True:
        try:
            msg = inbox.get(timeout=1.0)
        except queue.Empty:
            if orphaned():
                break
            continue
        if msg is None:
            break
        batch = [msg]  # the ticks that waited meanwhile: drawn as one update
        with contextlib.suppress(queue.Empty):
            while len(batch) < BATCH_TICKS and (msg := inbox.get_nowait()) is not None:
                batch.append(msg)
        page.drops = batch[-1].get("drops", page.drops)
        page.apply(*batch)
        ticks += len(batch)
        now = time.monotonic_ns()
        tick_ms.extend((now - m["t_host_ns"]) / 1e6 for m in batch)
        onset_ms.extend((now - ev["t_host_ns"]) / 1e6 for m in batch for ev in m.get("events", ())
                        if ev["kind"] == "onset")
        if msg is None:
            break
    outbox.put(("stats", {"ticks": ticks, "tick_ms": _quantiles(tick_ms), "onset_ms": list(onset_ms)}))


def _newest(ticks: tuple[dict[str, Any], ...], key: str) -> dict[str, Any] | None:
    return next((k for k in reversed(ticks) if key in k), None)


def orphaned() -> bool:
    """The monitor that started this page is gone (killed: it could not say so)."""
    parent = multiprocessing.parent_process()
    return parent is not None and not parent.is_alive()


def _quantiles(values: deque[float]) -> dict[str, float]:
    if not values:
        return {}
    a = np.asarray(values)
    return {"p50": float(np.percentile(a, 50)), "p99": float(np.percentile(a, 99)), "max": float(a.max())}
