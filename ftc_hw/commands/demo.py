"""``ftc demo``: a scene's world on the bus, the contact monitor live, then contacts against ground truth."""
from __future__ import annotations

import time

import numpy as np
from rich.console import Console, Group
from rich.live import Live
from rich.table import Table

from .common import scene_or_exit


def _stream_table(bus, topics) -> Table:
    t = Table(title="streams", expand=False)
    for col in ("topic", "frames", "rate Hz", "jitter ms", "max gap ms", "seq missing"):
        t.add_column(col, justify="right" if col != "topic" else "left")
    for topic in topics:
        try:
            s = bus.stats(topic)
        except KeyError:
            t.add_row(topic, "0", "-", "-", "-", "-")
            continue
        t.add_row(topic, str(s.count), f"{s.rate_hz:.1f}", f"{s.jitter_s * 1e3:.3f}", f"{s.max_gap_s * 1e3:.2f}",
                  str(s.seq_missing))
    return t


def _contact_table(monitor, truth) -> Table:
    t = Table(title="contact: estimate (monitor) and ground truth (world)", expand=False)
    t.add_column("")
    for c in ("link", "x mm", "y mm", "z mm", "|F| N", "+-mm", "flags"):
        t.add_column(c, justify="right" if c not in ("link", "flags") else "left")
    mf = monitor.latest
    if mf is not None:
        r = mf.result
        t.add_row("raw -> external wrench", f"d2 {r.detection.d2:9.1f}", *(f"{v:7.2f}" for v in r.external[:3]),
                  "", "", "")
        e = r.estimate
        if r.detection.active and e is not None:
            t.add_row("[bold green]estimate[/]", e.link or "-", *(f"{v * 1e3:7.1f}" for v in e.point),
                      f"{np.linalg.norm(e.force):6.1f}", f"{np.linalg.norm(e.point_std) * 1e3:5.1f}", ",".join(e.flags))
        else:
            t.add_row("estimate", "no contact", "", "", "", "", "", "")
    if truth is not None and truth.contacts:
        c = max(truth.contacts, key=lambda c: float(np.linalg.norm(c.force)))
        t.add_row("[bold]truth[/]", c.link, *(f"{v * 1e3:7.1f}" for v in c.point), f"{np.linalg.norm(c.force):6.1f}",
                  "", "")
    else:
        t.add_row("truth", "no contact", "", "", "", "", "", "")
    return t


def run_demo(scene_name: str, scenario: str, duration: float, seed: int) -> int:
    from sim_devices.world import World, build_scenario
    from sim_devices.world.bus_feeder import WorldFeeder

    from ..bus import Bus, Watchdog, joints_topic, wrench_topic
    from ..model import ArmModel
    from ..monitor import LiveMonitor

    console = Console()
    scene = scene_or_exit(scene_name)
    setup = build_scenario(scenario, scene, ArmModel(scene), seed, duration)
    world = World(scene, setup, seed=seed)
    bus = Bus()
    topics = [wrench_topic("ft"), joints_topic("arm")]
    events = bus.subscribe("events/", maxsize=1000)
    truth: dict[str, object] = {}
    samples: list[tuple[float, tuple]] = []

    def on_state(state):
        truth["s"] = state
        if world.steps % world.steps_per_sample == 0:
            samples.append((int(round(state.t * 1e9)), state.contacts))

    feeder = WorldFeeder(world, bus, duration=duration, on_state=on_state)
    monitor = LiveMonitor(bus, scene, keep_frames=True)
    log: list[str] = []
    console.print(f"[bold]ftc demo[/]: scene [cyan]{scene.name}[/], scenario [cyan]{scenario}[/], {duration:g} s: "
                  "world -> bus -> compensation, detection, localization")
    t_start = time.monotonic_ns()
    with Watchdog(bus, {t: 0.1 for t in topics}), monitor, feeder, \
            Live(console=console, refresh_per_second=8, transient=False) as live:
        while not feeder.done:
            for ev in events.drain():
                log.append(_event_line(ev, t_start))
            live.update(Group(_stream_table(bus, topics), _contact_table(monitor, truth.get("s")),
                              "\n".join(log[-6:]) or "(no events yet)"))
            time.sleep(0.1)
        time.sleep(0.2)  # let the monitor drain its queue
    return _summary(console, bus, topics, feeder, monitor, samples)


def _event_line(ev, t_start: int) -> str:
    t = (ev.t_host_ns - t_start) / 1e9
    if hasattr(ev, "link"):
        return (f"{t:7.3f} s  contact {ev.kind:6s} {ev.link or '-':12s} "
                f"point {np.round(np.asarray(ev.point) * 1e3, 1)} mm  |F| {np.linalg.norm(ev.force):.1f} N  "
                f"{','.join(ev.flags)}")
    return f"{t:7.3f} s  {ev.source}: {ev.kind} {ev.message}"


def _episodes(samples) -> list[tuple[float, float]]:
    out: list[list[float]] = []
    for t_ns, contacts in samples:
        t = t_ns / 1e9
        if not contacts:
            continue
        if out and t - out[-1][1] <= 0.02:
            out[-1][1] = t
        else:
            out.append([t, t])
    return [(a, b) for a, b in out]


def _summary(console, bus, topics, feeder, monitor, samples) -> int:
    table = _stream_table(bus, topics)
    table.title = f"streams: {feeder.world.t:.2f} s simulated"
    console.print(table)
    truth_at = dict(samples)
    frames = [f for f in monitor.frames if f.t_device_ns is not None]
    rows = Table(title="contacts: detected against ground truth")
    for c in ("#", "start s", "truth link", "detected", "delay ms", "estimated link", "pos err mm (median)",
              "force err N (median)"):
        rows.add_column(c, justify="right" if c not in ("truth link", "estimated link", "detected") else "left")
    detected = 0
    episodes = _episodes(samples)
    for k, (start, end) in enumerate(episodes, 1):
        inside = [f for f in frames if start - 1e-9 <= f.t_device_ns / 1e9 <= end + 1e-9]
        active = [f for f in inside if f.result.detection.active and f.result.estimate is not None]
        onset = next((f for f in inside if any(e.kind == "onset" for e in f.result.events)), None)
        prev = next((f for f in frames if f.t_device_ns / 1e9 < start and f.result.detection.active), None)
        hit = onset is not None or (prev is not None and bool(active))
        detected += hit
        errs, ferrs, links = [], [], []
        for f in active:
            contacts = truth_at.get(f.t_device_ns)
            if not contacts:
                continue
            c = max(contacts, key=lambda c: float(np.linalg.norm(c.force)))
            errs.append(np.linalg.norm(f.result.estimate.point - c.point) * 1e3)
            ferrs.append(np.linalg.norm(f.result.estimate.force - c.force))
            links.append(f.result.estimate.link)
        true_link = max(samples_links(samples, start, end), key=lambda x: x[1])[0]
        est_link = max(set(links), key=links.count) if links else "-"
        delay = (onset.t_device_ns / 1e9 - start) * 1e3 if onset is not None else float("nan")
        rows.add_row(str(k), f"{start:.3f}", true_link, "yes" if hit else "[red]no[/]", f"{delay:.1f}", est_link,
                     f"{np.median(errs):.1f}" if errs else "-", f"{np.median(ferrs):.2f}" if ferrs else "-")
    console.print(rows)
    false_onsets = sum(1 for f in frames for e in f.result.events if e.kind == "onset"
                       and not any(s - 0.001 <= f.t_device_ns / 1e9 <= e_ + 0.02 for s, e_ in episodes))
    console.print(f"true contacts {len(episodes)}, detected {detected}, false alarms {false_onsets}; "
                  f"monitor: {dict(monitor.counters)}")
    if feeder.error is not None:
        console.print(f"[red]the world stopped with an error: {feeder.error!r}[/]")
        return 1
    return 0


def samples_links(samples, start, end) -> list[tuple[str, int]]:
    counts: dict[str, int] = {}
    for t_ns, contacts in samples:
        if start <= t_ns / 1e9 <= end and contacts:
            c = max(contacts, key=lambda c: float(np.linalg.norm(c.force)))
            counts[c.link] = counts.get(c.link, 0) + 1
    return list(counts.items()) or [("-", 0)]
