"""The end of a monitor run: whether it can be read as clean (``judge_degraded``: each reason a line, exit
code ``DEGRADED_EXIT``) and the summary printed (``print_summary``)."""
from __future__ import annotations

import time
from typing import Any

from rich.console import Console

from ftc_hw.bus import Bus
from ftc_hw.monitor import LiveMonitor

from .config import MonitorOptions, MonitorOutcome
from .view import evaluation_table, stream_table

DEGRADED_EXIT = 3  # the run went to its end, but was blind or dropped frames for a while (see degraded)
DROPPED_SHARE = 0.05  # above this share of F/T frames not judged (or late), a run is degraded


def judge_degraded(monitor: LiveMonitor, adapters, out: MonitorOutcome, sim: bool) -> None:
    """Why this run cannot be read as clean (lost streams, frames not judged, a host that could not
    keep up, devices that dropped): each reason a line of the summary; exit code DEGRADED_EXIT."""
    c = monitor.counters
    for stream in ("sensor", "arm"):
        spans = [(back or out.t_closed_ns) - lost for s, lost, back in monitor.losses if s == stream]
        if spans:
            what = "F/T sensor stream" if stream == "sensor" else "arm's joint stream (blind meanwhile)"
            out.degraded.append(f"{what} lost {len(spans)}x, {sum(spans) / 1e9:.2f} s in all")
    if c.get("contacts_lost"):
        out.degraded.append(f"{c['contacts_lost']} open contact(s) closed by a lost stream (offsets flagged lost)")
    frames = c.get("frames", 0)
    unjudged = {k: c.get(k, 0) for k in ("ft_frames_dropped", "no_joint_state", "blind_frames",
                                         "ft_frames_unjudged_at_stop")}
    total = frames + sum(unjudged.values())
    if total and sum(unjudged.values()) > DROPPED_SHARE * total:
        detail = ", ".join(f"{k} {v}" for k, v in unjudged.items() if v)
        out.degraded.append(f"{100 * sum(unjudged.values()) / total:.1f} % of F/T frames not judged ({detail}): "
                            "contacts may be missed, false alarms possible")
    if frames and c.get("ft_frames_backlog", 0) > DROPPED_SHARE * frames:
        out.degraded.append(f"the host could not keep up: {c['ft_frames_backlog']} F/T frames were judged over "
                            "50 ms after they arrived")
    # with emulated devices, frames late by their device clock say the simulated world ran behind real
    # time, not that the monitor did (it judged them as they came): degraded only on real devices
    if not sim and frames and c.get("ft_frames_late", 0) > DROPPED_SHARE * frames:
        out.degraded.append(f"the F/T frames came late: {c['ft_frames_late']} reached the monitor over 50 ms "
                            "after their device time")
    for a in adapters:
        drops = a.counters.get("disconnects", 0) + a.counters.get("errors", 0)
        if drops:
            out.degraded.append(f"device {a.name} ({a.kind}) dropped {drops}x and reconnected "
                                f"{a.counters.get('event_connect', 1) - 1}x")
    if out.degraded and out.exit_code == 0:
        out.exit_code = DEGRADED_EXIT


def print_summary(console: Console, cfg: MonitorOptions, served: bool, bus: Bus, topics: list[str],
                  out: MonitorOutcome, adapters, recorder) -> None:
    """The run's summary: streams, events, counters, the reflex, the recording, the evaluation, why
    it is degraded. ``served``: the devices were read by reader processes (own or ``ftc serve``'s)."""
    console.print(stream_table(bus, topics, out.t_closed_ns or time.monotonic_ns(),
                               title="streams (stale: at the end of the run)"))
    kinds = {k: sum(e["kind"] == k for e in out.events) for k in ("onset", "update", "offset")}
    console.print(f"contact events: {kinds}" + (f" -> {cfg.events}" if cfg.events else ""))
    console.print(f"monitor: {out.counters}")
    for a in adapters:
        console.print(f"{a.name} ({a.kind}): {dict(a.counters)}")
    if served:
        console.print(f"from {cfg.devices.remote or 'reader processes'} (Zenoh): {out.remote}")
    if out.web:
        console.print(web_line(out.web), highlight=False)
    if out.faults:
        console.print("faults played: " + ", ".join(f"{f} (done at t = {t:.2f} s)" for f, t in out.faults))
    for line, n in out.vendor_lines.items():
        console.print(f"{line} ({n}x)")
    if out.reflex and "retreats" in out.reflex:
        _print_retreats(console, out.reflex)
    elif out.reflex:
        stops = out.reflex["stops"]
        sent = [s["sent_after_onset_ms"] for s in stops]
        console.print(f"reflex stop: {len(stops)} sent" + (f", {min(sent):.2f}-{max(sent):.2f} ms after the onset "
                                                          "sample" if sent else "")
                      + (f"; errors: {out.reflex['errors']}" if out.reflex["errors"] else ""))
        by_reader = [r["sent_after_onset_ms"] for r in out.reflex.get("stopped_by_reader", [])]
        if served:
            console.print(f"the arm's reader process stopped it {len(by_reader)}x"
                          + (f", {min(by_reader):.2f}-{max(by_reader):.2f} ms after the onset sample" if by_reader
                             else ""))
    if recorder is not None:
        console.print(f"recorded {sum(recorder.counts.values())} messages -> {recorder.path} "
                      f"(drops {recorder.drops})")
    if out.evaluation is not None and not cfg.judged:
        onsets = sum(e["kind"] == "onset" for e in out.events)
        console.print(f"contacts not judged: a recording of free motion, {onsets} onsets of the model not yet "
                      "identified (expected)")
    elif out.evaluation is not None:
        console.print(evaluation_table(out.evaluation))
    if out.evaluation is not None and cfg.world.truth:
        console.print(f"ground truth -> {cfg.world.truth}")
    for p in out.problems:
        console.print(f"[yellow]{p}[/]")
    if out.degraded:
        console.print(f"[bold red]DEGRADED run[/] (exit code {DEGRADED_EXIT}): " + "; ".join(out.degraded))


def web_line(web: dict) -> str:
    """The live page's figures: ticks sent and dropped, how late the page drew them (ms from a tick's
    making, and from an onset's sample, to the page's sending it to the browsers)."""
    tick = web.get("tick_ms") or {}
    onsets = web.get("onset_ms") or []
    return (f"live page {web['url']}: {web['ticks']} ticks sent ({web['view_hz']:g} Hz), {web['dropped']} dropped "
            "(page behind)"
            + (f", {web['errors']} feed errors" if web.get("errors") else "")
            + (f"; slowed down {web['slowdowns']}x, {web['slowed_s']:.1f} s in all, while the monitor fell behind"
               if web.get("slowdowns") else "")
            + (f"; drawn {tick['p50']:.1f} ms (p50), {tick['p99']:.1f} (p99), {tick['max']:.1f} (max) after the tick"
               if tick else "")
            + (f"; onsets sent to the browsers {', '.join(f'{x:.0f}' for x in onsets)} ms after their sample"
               if 0 < len(onsets) <= 8 else "")
            + (f"; {len(onsets)} onsets sent to the browsers {sorted(onsets)[len(onsets) // 2]:.0f} ms (median), "
               f"{max(onsets):.0f} (max) after their sample" if len(onsets) > 8 else ""))


def _print_retreats(console: Console, reflex: dict[str, Any]) -> None:
    """One line per retreat (the figures ``ftc monitor --reflex retreat`` measured), then what was left alone."""
    at = reflex.get("at_interface") or [None] * len(reflex["retreats"])
    for r, rx in zip(reflex["retreats"], at, strict=True):
        first = r["first_setpoint_after_onset_ms"]
        console.print(f"reflex retreat: contact {r['contact_id']} on {r['link']}: first setpoint "
                      f"{first:.1f} ms after the onset sample (planned {r['plan_ms']:.1f} ms after taking it, "
                      f"{r['planning_ms']:.1f} of them planning)"
                      + (f", at the arm's interface {rx:.1f} ms" if rx is not None else "")
                      + f"; {r['setpoints']} setpoints over {r['duration_s']:.3f} s, the point moved back "
                      f"{r['moved_m'] * 1e3:.1f} mm (model), every point it may be at ({r['region_points']}) at least "
                      f"{r['least_m'] * 1e3:.1f} mm, along ({', '.join(f'{x:.3f}' for x in r['direction'])})"
                      + ("" if r["within_time_limit"] else ", OVER the time limit")
                      + (", a joint range clipped it" if r["clipped"] else "")
                      + (f" (SHORT: {r['short']})" if r["short"] else ""), highlight=False)
    if reflex["not_fought"]:
        console.print(f"reflex retreat: {len(reflex['not_fought'])} guided contact(s) not retreated from")
    if reflex["ignored"] or reflex["errors"]:
        console.print(f"reflex retreat: {reflex['ignored']} trigger(s) during a retreat ignored; "
                      f"errors: {reflex['errors']}")
