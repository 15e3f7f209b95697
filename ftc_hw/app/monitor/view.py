"""The monitor's live view (rich): streams, wrenches, contact status, event log; and the summary tables."""
from __future__ import annotations

import sys
import time
from collections import deque
from collections.abc import Callable

import numpy as np
from rich import box
from rich.console import Console, Group
from rich.table import Table
from rich.text import Text

from ftc_hw.bus import Bus, ContactEvent, DeviceEvent

from .evaluate import Evaluation


def make_console() -> Console:
    """The terminal's console; 150 columns when the output is a file or pipe (the tables stay readable)."""
    return Console() if sys.stdout.isatty() else Console(width=150)


def stream_table(bus: Bus, topics: list[str], now_ns: int, title: str = "streams") -> Table:
    t = Table(title=title, title_justify="left", expand=False)
    for col in ("topic", "frames", "rate Hz", "jitter ms", "stale ms", "max gap ms", "seq missing"):
        t.add_column(col, justify="left" if col == "topic" else "right")
    for topic in topics:
        try:
            s = bus.stats(topic)
        except KeyError:
            t.add_row(topic, "0", "-", "-", "[red]no data[/]", "-", "-")
            continue
        last = bus.latest(topic)
        stale = (now_ns - last.t_host_ns) / 1e6 if last is not None else float("nan")
        style = "red" if stale > 100 else ""
        t.add_row(topic, str(s.count), f"{s.rate_hz:.1f}", f"{s.jitter_s * 1e3:.3f}",
                  Text(f"{stale:.1f}", style=style), f"{s.max_gap_s * 1e3:.2f}", str(s.seq_missing))
    return t


def _fmt(v, scale: float = 1.0, width: int = 8, prec: int = 2) -> list[str]:
    return [f"{x * scale:{width}.{prec}f}" for x in v]


def wrench_table(raw, external, d2: float | None, threshold: float | None) -> Table:
    t = Table(title="wrench (sensor frame)", title_justify="left", expand=False)
    t.add_column("")
    for c in ("fx N", "fy N", "fz N", "tx Nm", "ty Nm", "tz Nm"):
        t.add_column(c, justify="right")
    t.add_row("raw", *(_fmt(raw) if raw is not None else ["-"] * 6))
    t.add_row("external", *(_fmt(external) if external is not None else ["-"] * 6))
    if d2 is not None:
        t.caption = f"detection d2 {d2:.1f} (onset above {threshold:.1f})" if threshold else f"d2 {d2:.1f}"
    return t


LOST_STATUS = {"sensor": "[bold red]SENSOR LOST[/]: no F/T frames, no contact can be judged",
               "arm": "[bold red]BLIND[/]: joint stream lost, F/T frames dropped unjudged"}


def contact_table(result, fused: ContactEvent | None = None, lost: frozenset[str] | set[str] = frozenset()) -> Table:
    """The newest frame's estimate and, while in contact, the newest event's point (fused over the
    contact's frames); a lost stream instead of either (the newest frame is old news then)."""
    t = Table(title="contact (base frame)", title_justify="left", expand=False)
    for c in ("status", "link", "x mm", "y mm", "z mm", "|F| N", "force N", "+- mm (1 sigma)", "flags"):
        t.add_column(c, justify="left" if c in ("status", "link", "flags", "force N") else "right")
    e = None if result is None else result.estimate
    if lost:
        for stream in sorted(lost):
            t.add_row(LOST_STATUS[stream], "", "", "", "", "", "", "", "")
        return t
    if result is None:
        t.add_row("waiting", "", "", "", "", "", "", "", "")
    elif result.detection.active and e is not None and e.contact:
        t.add_row("[bold red]CONTACT[/]", e.link, *_fmt(e.point, 1e3, 7, 1), f"{np.linalg.norm(e.force):6.1f}",
                  " ".join(_fmt(e.force, 1.0, 6, 1)), " ".join(_fmt(e.point_std, 1e3, 4, 1)), ",".join(e.flags))
    elif result.detection.active:
        t.add_row("[bold red]CONTACT[/]", "?", "", "", "", "", "", "", ",".join(e.flags) if e else "no estimate")
    else:
        t.add_row("[green]free[/]", "", "", "", "", "", "", "", "")
    if result is not None and result.detection.active and fused is not None and fused.kind != "offset":
        t.add_row("  fused", fused.link, *_fmt(fused.point, 1e3, 7, 1), "", "",
                  " ".join(_fmt(fused.point_std, 1e3, 4, 1)), "(newest event)")
    return t


def event_text(ev, t0_ns: int) -> str:
    t = (ev.t_host_ns - t0_ns) / 1e9
    if isinstance(ev, ContactEvent):
        text = (f"{t:8.3f} s  {ev.kind:6s} {ev.link or '-':14s} point {np.round(np.asarray(ev.point) * 1e3, 1)} mm  "
                f"|F| {np.linalg.norm(ev.force):5.1f} N  +-{np.linalg.norm(ev.point_std) * 1e3:.1f} mm  "
                f"{class_text(ev)}{','.join(ev.flags)}")
        return text + limits_text(ev)
    if isinstance(ev, DeviceEvent):
        return f"{t:8.3f} s  device {ev.source}: {ev.kind} {ev.message}"
    return f"{t:8.3f} s  {ev!r}"


def limits_text(ev: ContactEvent) -> str:
    """The event against its body region's limit (docs/limits.md): the margin, the effective mass, the onset
    speed against the permissible (``?``: no class, quasi-static assumed); an exceedance marked ``!!``."""
    c = ev.limits
    if c is None:
        return ""
    kind = c.limit_kind.replace("_", "-") + ("?" if c.class_assumed else "")
    text = (f"  {c.region} {kind} {c.limit_n:.0f} N margin {c.margin_n:+.1f} N  m_R {c.effective_mass_kg:.3g} kg  "
            f"v {c.speed_mps:.2f}/{c.permissible_speed_mps:.2f} m/s")
    return f"  !!{text}" if ev.kind == "exceedance" else text


def class_text(ev: ContactEvent) -> str:
    """The contact's class so far: ``transient 0.97 / impact 0.99  `` (each value with its probability;
    ``final`` at the offset), empty for an event with none."""
    if not ev.contact_class:
        return ""
    p_cls = ev.p_quasi_static if ev.contact_class != "transient" else 1.0 - ev.p_quasi_static
    p_int = ev.p_guidance if ev.intent != "impact" else 1.0 - ev.p_guidance
    final = " final" if ev.kind == "offset" else ""
    return f"{ev.contact_class} {p_cls:.2f} / {ev.intent} {p_int:.2f}{final}  "


class LiveView:
    """Renders the monitor's state; ``add`` events as they come, ``render()`` at the refresh rate."""

    def __init__(self, bus: Bus, monitor, topics: list[str], *, ft_topic: str, title: str,
                 now_ns: Callable[[], int] = time.monotonic_ns, log_lines: int = 8) -> None:
        self.bus = bus
        self.monitor = monitor
        self.topics = topics
        self.ft_topic = ft_topic
        self.title = title
        self.now_ns = now_ns
        self.t0_ns = now_ns()
        self.log: deque[str] = deque(maxlen=log_lines)
        self.status = ""
        self.fused: ContactEvent | None = None

    def add(self, ev) -> None:
        self.log.append(event_text(ev, self.t0_ns))
        if isinstance(ev, ContactEvent):
            self.fused = ev

    def render(self) -> Group:
        mf = self.monitor.latest
        result = mf.result if mf is not None else None
        raw = self.bus.latest(self.ft_topic)
        threshold = float(self.monitor.pipeline.detector.on)
        header = Text.assemble((self.title, "bold"), "  ", self.status)
        counters = ", ".join(f"{k} {v}" for k, v in sorted(self.monitor.counters.items()))
        return Group(header, stream_table(self.bus, self.topics, self.now_ns()),
                     wrench_table(raw.wrench if raw is not None else None,
                                  result.external if result is not None else None,
                                  float(result.detection.d2) if result is not None else None,
                                  threshold),
                     contact_table(result, self.fused, set(self.monitor.lost)), Text("events", style="bold"),
                     Text("\n".join(self.log) or "(no events yet)"), Text(f"monitor: {counters}\n", style="dim"))


def _class_caption(ev: Evaluation) -> str:
    """The scripted contacts' kinds against their final classes (docs/contacts.md), where the truth says kinds."""
    scored = [c for c in ev.contacts if c.true_class]
    if not scored:
        return ""
    rows = ", ".join(f"#{c.index} {c.true_class}: {c.classified or 'not reported'}" for c in scored)
    return f" Classified right: {sum(bool(c.class_right) for c in scored)} of {len(scored)} ({rows})."


def evaluation_table(ev: Evaluation, title: str = "contacts: detected against ground truth") -> Group:
    """Two tables, each whole at 100 columns and in a file (no cell cut): when and on which link each
    contact was detected, then how far its estimates were from the truth; the legend under them."""
    def table(title: str, columns: tuple[str, ...]) -> Table:
        # two spaces between columns, no outer border: 8 and 11 columns fit in 100 with 4-digit values
        t = Table(title=title, title_justify="left", box=box.SIMPLE_HEAD, show_edge=False, collapse_padding=True,
                  pad_edge=False)
        for c in columns:
            text = c in ("true link", "detected", "est. link")
            # a link name is never wrapped, and nothing is ever cut to an ellipsis (folded at worst)
            t.add_column(c, justify="left" if text else "right", no_wrap=c.endswith("link"), overflow="fold")
        return t

    def f(x, fmt="{:.1f}"):
        return "-" if x is None else fmt.format(x)

    counted = any(c.onset_samples is not None for c in ev.contacts)  # evaluated with the judged samples' times
    when = table(title, ("#", "start s", "true link", "detected", "delay ms", "from due")
                 + (("samples",) if counted else ()) + ("est. link", "link ok"))
    where = table("contacts: point errors against ground truth (mm)",
                  ("#", "err mm med", "rms", "CRLB rms", "err/CRLB", "err/solver", "err/std", "max", "rms all",
                   "|dF| N", "estimates"))
    for c in ev.contacts:
        det = ("yes" if c.delay_ok else "[yellow]late[/]") if c.detected else "[red]no[/]"
        start = f"{c.start_s:.3f}" + (" cut" if c.cut else "")
        when.add_row(str(c.index), start, c.link, det, f(c.onset_delay_ms, "{:.2f}"), f(c.onset_delay_due_ms, "{:.2f}"),
                     *((f(c.onset_samples, "{}"),) if counted else ()), c.est_link, f"{c.link_right * 100:.0f} %")
        where.add_row(str(c.index), f(c.err_median_mm), f(c.err_rms_mm), f(c.crlb_rms_mm),
                      f(c.err_over_crlb_rms, "{:.2f}"), f(c.err_over_solver, "{:.2f}"), f(c.err_over_std_rms, "{:.2f}"),
                      f(c.err_max_mm), f(c.err_rms_all_mm), f(c.force_err_median_n, "{:.2f}"),
                      f"{c.trusted}/{c.estimates}")
    when.caption = (f"{len(ev.contacts)} true contacts, {ev.detected} detected, "
                    f"{sum(c.detected and c.delay_ok for c in ev.contacts)} within {ev.delay_limit_ms:g} ms "
                    f"(late: after that), false alarms {len(ev.false_alarms)}"
                    + (f" at {ev.false_alarms} s" if ev.false_alarms else "") + f", split detections {ev.splits}. "
                    "Delay: from the first contact sample's publication (from due: from when it was due)"
                    + ("; samples: the onset's among the judged samples since then (one before the contact can "
                       "count). " if counted else ". ")
                    + "Link ok: the estimates on the true link. Cut: the run ended during the contact."
                    + _class_caption(ev))
    where.caption = ("Over the estimates without a solver flag (rms all: with the flagged ones); "
                     "CRLB rms: the Cramer-Rao bound of the same samples (what the sensor noise allows); "
                     "err/CRLB: RMS of each estimate's error over its own bound (about 1 at the limit); "
                     "err/solver: RMS error over the solver's own from one frame of the same samples' true wrench "
                     "plus sensor noise (the events' points are fused over the contact's frames: below 1 by what "
                     "that gains); err/std: RMS of each error over the uncertainty the event reports (about 1 when "
                     "honest); |dF| N: the median force error; estimates: unflagged/all.")
    for t in (when, where):
        t.caption_justify = "left"
    return Group(when, Text(""), where)
