"""What the web page (``ftc monitor --view web``) is sent, built in the monitor's process: the arm's
surfaces once (:func:`page_setup`), then a tick at most ``rate_hz`` a second (:class:`WebSampler`):
the link poses when they changed, the wrenches and the detection statistic, the new events, the
world's true contact (with ``--sim``, :class:`TruthTail`) and, once a second, the streams.

Everything is plain data (lists, floats, strings): it crosses to the page's process by pickling. The
contacts and the wrench arrow are Foxglove's well-known primitives (the recordings' own,
:mod:`ftc_hw.record.foxglove_messages`), in the base frame, so the page and a recording draw the same.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ftc_hw.bus import Bus, ContactEvent, DeviceEvent
from ftc_hw.monitor import MONITOR_INPUT
from ftc_hw.record.events import event_record
from ftc_hw.record.foxglove_messages import arrow, color, contact_entity, entity, pose, vec3, wrench_entity
from ftc_hw.record.foxglove_view import ARM_TOPIC, FoxgloveView

STREAMS_PERIOD_NS = 1_000_000_000  # the stream table's refresh (the page draws it once a second)
POSE_EPS_RAD = 1e-5  # joint angles closer than this to the last sent: no pose update (nothing to redraw)
BASE = np.eye(4)
TRUTH_RGBA = color(0.12, 0.75, 0.24)


def page_setup(view: FoxgloveView, title: str) -> dict[str, Any]:
    """The page's fixed content: the solver's primitives per link (Foxglove entities in the link's
    frame), the sensor's frame on its link, the scales of the arrows."""
    arm = next(m for m in view.start(0) if m.topic == ARM_TOPIC).data["entities"]
    pos, quat = view.sensor_tf
    return {"title": title, "links": list(view.arm.link_names), "arm": arm, "sensor_link": view.sensor_link,
            "sensor_pose": ([float(x) for x in pos], [quat["w"], quat["x"], quat["y"], quat["z"]]),
            "reach_m": view.reach, "marker_m": view.marker_m}


class TruthTail:
    """The world's newest true contact, read from the end of its growing truth file (JSON Lines, one
    line per sensor sample: only the last complete line is parsed)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._f = None
        self._rest = b""

    def latest(self) -> dict[str, Any] | None:
        if self._f is None:
            if not self.path.is_file():
                return None
            self._f = open(self.path, "rb")  # noqa: SIM115 - kept open while the world writes it
        data = self._rest + self._f.read()
        end = data.rfind(b"\n")
        if end < 0:
            self._rest = data
            return None
        start = data.rfind(b"\n", 0, end) + 1
        self._rest = data[end + 1:]
        try:
            rec = json.loads(data[start:end])
        except ValueError:
            return None
        return {"contact": bool(rec.get("contact")), "link": rec.get("link"), "point": rec.get("point"),
                "force": rec.get("force")}

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None


class WebSampler:
    """``tick(now_ns)`` -> the page's next update from the bus and the monitor's newest state (both read,
    never waited on); events come through ``add(ev)``. ``t0_ns``: the page's time zero."""

    def __init__(self, bus: Bus, monitor: Any, view: FoxgloveView, topics: list[str], *, ft_topic: str,
                 t0_ns: int, truth: TruthTail | None = None) -> None:
        self.bus, self.monitor, self.view = bus, monitor, view
        self.topics, self.ft_topic, self.t0_ns = topics, ft_topic, t0_ns
        self.truth = truth
        self._q_sent: np.ndarray | None = None
        self._events: list[dict[str, Any]] = []
        self._streams_ns = 0
        self._truth_sent: dict[str, Any] | None = None
        self._raw_sent: np.ndarray | None = None
        self._raw_eps = 0.01 / view.wrench_m_per_n * view.reach  # N (or N m): 1 % of the arrow's longest

    def add(self, ev: ContactEvent | DeviceEvent) -> None:
        if isinstance(ev, DeviceEvent):
            if ev.kind != "counters":  # a reader's counters, each second: the summary's
                self._events.append(event_record(ev))
            return
        rec = event_record(ev)
        if "no_estimate" not in ev.flags:
            rec["entity"] = contact_entity(ev, BASE, marker_m=self.view.marker_m, m_per_n=self.view.contact_m_per_n,
                                           max_m=self.view.reach, lifetime_s=self.view.contact_lifetime_s)
        self._events.append(rec)

    def tick(self, now_ns: int) -> dict[str, Any]:
        out: dict[str, Any] = {"t": (now_ns - self.t0_ns) / 1e9, "t_host_ns": now_ns}
        self._pose(out)
        self._wrench(out)
        if self._events:
            out["events"], self._events = self._events, []
        if self.truth is not None:
            truth = self.truth.latest()
            if truth is not None and truth != self._truth_sent:
                out["truth"] = self._truth_sent = truth
                out["truth_entity"] = self._truth_entity(truth)
        if now_ns - self._streams_ns >= STREAMS_PERIOD_NS:
            self._streams_ns = now_ns
            out["streams"] = self._streams(now_ns)
            out["counters"] = {k: int(v) for k, v in sorted(self.monitor.counters.items())}
            out["lost"] = sorted(self.monitor.lost)
        return out

    def _truth_entity(self, truth: dict[str, Any]) -> dict[str, Any]:
        """The world's true contact (green): its point and force, the estimate's scale."""
        if not truth["contact"] or truth["point"] is None:
            return entity(0, "world", "truth")
        p, f, v = np.asarray(truth["point"]), np.asarray(truth["force"]), self.view
        mag = float(np.linalg.norm(f))
        arrows = []
        if mag > 0:
            length = min(mag * v.contact_m_per_n, v.reach)
            arrows.append(arrow(p - f / mag * length, f / mag, length, v.marker_m / 4, TRUTH_RGBA))
        ball = {"pose": pose(p), "size": vec3(np.full(3, 0.8 * v.marker_m)), "color": TRUTH_RGBA}
        return entity(0, "world", "truth", spheres=[ball], arrows=arrows)

    def _pose(self, out: dict[str, Any]) -> None:
        frame = self.bus.latest(MONITOR_INPUT) or self.bus.latest(self.topics[1])
        if frame is None:
            return
        q = np.asarray(frame.q, dtype=float)
        if q.shape != (self.view.arm.n_joints,) or not np.isfinite(q).all():
            return
        if self._q_sent is not None and np.max(np.abs(q - self._q_sent)) < POSE_EPS_RAD:
            return
        self._q_sent = q.copy()
        xpos, xquat = self.view.arm.body_poses(q)
        out["poses"] = [(xpos[i + 1].tolist(), xquat[i + 1].tolist()) for i in range(len(self.view.arm.link_names))]

    def _wrench(self, out: dict[str, Any]) -> None:
        raw = self.bus.latest(self.ft_topic)
        if raw is not None and np.isfinite(raw.wrench).all():
            out["raw"] = [float(x) for x in raw.wrench]
        # the arrow redrawn only when it moved visibly (a page that redraws at every tick costs the host)
        if "raw" in out and (self._raw_sent is None or np.max(np.abs(raw.wrench - self._raw_sent)) > self._raw_eps):
            self._raw_sent = np.array(raw.wrench, dtype=float)
            out["raw_entity"] = wrench_entity(0, "sensor", raw.wrench, m_per_n=self.view.wrench_m_per_n,
                                              m_per_nm=self.view.wrench_m_per_nm, max_m=self.view.reach,
                                              thickness=self.view.marker_m / 4, lifetime_s=0.0)
        mf = self.monitor.latest
        if mf is not None:
            r = mf.result
            out["external"] = [float(x) for x in r.external]
            out["d2"] = float(r.detection.d2)
            out["threshold"] = float(self.monitor.pipeline.detector.on)
            out["contact"] = bool(r.detection.active)

    def _streams(self, now_ns: int) -> list[dict[str, Any]]:
        rows = []
        for topic in self.topics:
            try:
                s = self.bus.stats(topic)
            except KeyError:
                rows.append({"topic": topic, "frames": 0})
                continue
            last = self.bus.latest(topic)
            rows.append({"topic": topic, "frames": s.count, "rate_hz": s.rate_hz, "max_gap_ms": s.max_gap_s * 1e3,
                         "stale_ms": (now_ns - last.t_host_ns) / 1e6 if last is not None else None,
                         "seq_missing": s.seq_missing})
        return rows
