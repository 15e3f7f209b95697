"""``ftc report RUN.mcap``: one HTML page of a recorded run's contacts against the cell's body limits
(docs/limits.md), readable offline: its figures are SVG drawn by matplotlib into the page, no script, no
stylesheet or font from elsewhere.

Per contact: its force over time against the limit that applies (by its class), its margin, the arm's
effective mass at the contact and its speed there at the onset against the region's permissible speed, and
where on the arm (the arm's links at the onset, side and top, with the point). A summary table first.
The events are the recorded ones where they carry their limits; else (or with ``--limits``) the recording
is replayed through the same pipeline and judged against the built-in or given limits.
"""
from __future__ import annotations

import html
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ftc_hw.bus import EVENTS_CONTACT, ContactEvent
from ftc_hw.model import ArmModel
from ftc_hw.monitor import MONITOR_INPUT
from ftc_hw.record.reader import Recording, RecordingError, read_recording
from ftc_hw.record.replay import ReplayError, recorded_scene, replay
from ftc_hw.scene import Scene
from ftc_hw.scene.limits import LimitsError, builtin_limits, load_limits

LIMIT_COLOUR, FORCE_COLOUR, OVER_COLOUR = "#c62828", "#1565c0", "#c62828"


class ReportError(Exception):
    """The recording cannot be read or judged (the message says why)."""


@dataclass
class ContactRecord:
    """One contact's events (onset, updates, offset, exceedances) in order."""

    contact_id: int
    events: list[ContactEvent] = field(default_factory=list)

    @property
    def judged(self) -> list[ContactEvent]:
        return [e for e in self.events if e.limits is not None and e.kind != "exceedance"]

    @property
    def exceeded(self) -> bool:
        return any(e.kind == "exceedance" for e in self.events)


def write_report(recording: Path, out: Path | None = None, limits: Path | None = None) -> Path:
    """The page of ``recording`` written to ``out`` (default: beside it, ``.html``); ReportError."""
    try:
        rec = read_recording(recording)
        scene = recorded_scene(rec)
        events = _events(rec, limits)
    except (RecordingError, ReplayError, LimitsError, OSError) as exc:
        raise ReportError(str(exc)) from None
    out = out or recording.with_suffix(".html")
    out.write_text(render(rec, scene, events), encoding="utf-8")
    return out


def _events(rec: Recording, limits: Path | None) -> list[ContactEvent]:
    recorded = [m.frame for m in rec.messages if m.topic == EVENTS_CONTACT]
    if limits is None and any(e.limits is not None for e in recorded):
        return recorded
    cell = load_limits(limits) if limits is not None else builtin_limits()
    return [e for e in replay(rec, limits=cell).events if isinstance(e, ContactEvent)]


def contacts_of(events: list[ContactEvent]) -> list[ContactRecord]:
    by_id: dict[int, ContactRecord] = {}
    for e in events:
        by_id.setdefault(e.contact_id, ContactRecord(e.contact_id)).events.append(e)
    return [c for c in by_id.values() if c.judged]


def render(rec: Recording, scene: Scene, events: list[ContactEvent]) -> str:
    """The page's HTML (one string, everything inline)."""
    t0 = rec.messages[0].log_time if rec.messages else 0
    contacts = contacts_of(events)
    inputs = [m.frame for m in rec.messages if m.topic == MONITOR_INPUT]
    arm = ArmModel(scene)
    sections = [_section(c, t0, _pose_at(inputs, c.judged[0].t_host_ns), arm) for c in contacts]
    title = f"ftc report: {html.escape(rec.path.name)}"
    over = sum(c.exceeded for c in contacts)
    return (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{title}</title>"
            f"<style>{_CSS}</style></head><body><h1>{title}</h1>"
            f"<p>scene <b>{html.escape(scene.name)}</b>, {len(contacts)} contacts judged against the body limits, "
            f"<b class='{'over' if over else 'ok'}'>{over} exceeded</b> (ISO/TS 15066 power and force limiting; "
            f"what each column means: docs/limits.md).</p>{_summary(contacts, t0)}{''.join(sections)}</body></html>")


def _summary(contacts: list[ContactRecord], t0: int) -> str:
    head = ("#", "onset s", "link", "region", "class", "peak N", "limit N", "least margin N", "m_R kg",
            "speed m/s", "permissible m/s", "exceeded")
    rows = []
    for c in contacts:
        j = c.judged
        first, least = j[0].limits, min(j, key=lambda e: e.limits.margin_n).limits
        peak = max(float(np.linalg.norm(e.force)) for e in j)
        cls = first.limit_kind.replace("_", "-") + (" (assumed)" if first.class_assumed else "")
        cells = (f"<a href='#c{c.contact_id}'>{c.contact_id}</a>", f"{(c.events[0].t_host_ns - t0) / 1e9:.3f}",
                 html.escape(j[0].link), html.escape(least.region), cls, f"{peak:.1f}", f"{least.limit_n:.0f}",
                 f"{least.margin_n:+.1f}", f"{np.median([e.limits.effective_mass_kg for e in j]):.3g}",
                 f"{first.speed_mps:.3f}", f"{first.permissible_speed_mps:.3f}",
                 "<b class='over'>yes</b>" if c.exceeded else "no")
        rows.append("<tr>" + "".join(f"<td>{x}</td>" for x in cells) + "</tr>")
    return ("<table><thead><tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr></thead><tbody>"
            + "".join(rows) + "</tbody></table>")


def _section(c: ContactRecord, t0: int, q: np.ndarray | None, arm: ArmModel) -> str:
    j = c.judged
    first = j[0].limits
    return (f"<h2 id='c{c.contact_id}'>contact {c.contact_id}: {html.escape(j[0].link)}, "
            f"{html.escape(first.region)} ({html.escape(first.region_from)})</h2>"
            f"{_svg(_figure(c, t0, q, arm))}")


def _figure(c: ContactRecord, t0: int, q: np.ndarray | None, arm: ArmModel):
    from matplotlib.figure import Figure  # lazy: matplotlib only for the report's figures

    fig = Figure(figsize=(11.0, 2.6), layout="constrained")
    force_ax, speed_ax, side_ax, top_ax = fig.subplots(1, 4, width_ratios=(3.0, 1.0, 1.4, 1.4))
    j = c.judged
    t = np.array([(e.t_host_ns - t0) / 1e9 for e in j])
    force_ax.plot(t, [np.linalg.norm(e.force) for e in j], ".-", color=FORCE_COLOUR, label="|F| N")
    force_ax.step(t, [e.limits.limit_n for e in j], where="post", color=LIMIT_COLOUR, label="limit N")
    for e in c.events:
        if e.kind == "exceedance":
            force_ax.plot((e.t_host_ns - t0) / 1e9, np.linalg.norm(e.force), "x", color=OVER_COLOUR, ms=10,
                          label="exceedance")
    force_ax.set(xlabel="t s", ylabel="N", title=f"force against the {j[-1].limits.limit_kind.replace('_', '-')} "
                 f"limit; least margin {min(e.limits.margin_n for e in j):+.1f} N")
    force_ax.legend(fontsize="small", loc="best")
    lim = j[0].limits
    speed_ax.bar(["speed", "permissible"], [lim.speed_mps, lim.permissible_speed_mps],
                 color=[OVER_COLOUR if lim.speed_mps > lim.permissible_speed_mps else FORCE_COLOUR, "#9e9e9e"])
    speed_ax.set(ylabel="m/s", title=f"onset, m_R {lim.effective_mass_kg:.3g} kg")
    if q is not None:
        _draw_arm(side_ax, top_ax, arm, q, np.asarray(j[0].point))
    return fig


def _draw_arm(side_ax, top_ax, arm: ArmModel, q: np.ndarray, point: np.ndarray) -> None:
    """The links' frames at q (the contact's first judged event's) joined in the model's order (base to tip), side
    (x-z) and top (x-y), and that event's point."""
    origins = np.array([p[:3, 3] for p in arm.kinematics(q).values()])
    for ax, (a, b), name in ((side_ax, (0, 2), "side (x-z)"), (top_ax, (0, 1), "top (x-y)")):
        ax.plot(origins[:, a], origins[:, b], "o-", color="#616161", ms=3)
        ax.plot(point[a], point[b], "o", color=OVER_COLOUR, ms=8)
        ax.set(title=f"arm at onset, {name}", aspect="equal")
        ax.tick_params(labelsize="small")


def _pose_at(inputs: list, t_ns: int) -> np.ndarray | None:
    """The joint angles the pipeline had at host time t_ns (the nearest recorded input), or None."""
    if not inputs:
        return None
    times = np.array([i.t_host_ns for i in inputs])
    return np.asarray(inputs[int(np.argmin(np.abs(times - t_ns)))].q, dtype=float)


def _svg(fig) -> str:
    buf = io.StringIO()
    fig.savefig(buf, format="svg")
    text = buf.getvalue()
    return text[text.index("<svg"):]  # the XML prologue and DOCTYPE do not belong inside HTML


_CSS = ("body{font-family:sans-serif;margin:1.5em;color:#212121}table{border-collapse:collapse}"
        "td,th{border:1px solid #bdbdbd;padding:2px 8px;text-align:right}th{background:#eeeeee}"
        ".over{color:#c62828}.ok{color:#2e7d32}svg{max-width:100%;height:auto}")
