"""``ftc demo``: a scene's world on the bus with a live view, then a summary. Ends by itself."""
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


def _wrench_table(frame, truth) -> Table:
    t = Table(title="sensor and ground truth", expand=False)
    t.add_column("")
    for c in ("fx N", "fy N", "fz N", "tx N m", "ty N m", "tz N m"):
        t.add_column(c, justify="right")
    if frame is not None:
        t.add_row("raw wrench", *(f"{v:8.2f}" for v in frame.wrench))
    if truth is not None and truth.contacts:
        c = max(truth.contacts, key=lambda c: float(np.linalg.norm(c.force)))
        t.add_row(f"contact on {c.link}", *(f"{v:8.2f}" for v in c.force), "", "", "")
        t.add_row("  at point (mm)", *(f"{v * 1e3:8.1f}" for v in c.point), "", "", "")
    else:
        t.add_row("contact", "none", "", "", "", "", "")
    return t


def run_demo(scene_name: str, scenario: str, duration: float, seed: int) -> int:
    from sim_devices.world import World, build_scenario
    from sim_devices.world.bus_feeder import WorldFeeder

    from ..bus import Bus, Watchdog, joints_topic, wrench_topic
    from ..model import ArmModel

    console = Console()
    scene = scene_or_exit(scene_name)
    setup = build_scenario(scenario, scene, ArmModel(scene), seed, duration)
    world = World(scene, setup, seed=seed)
    bus = Bus()
    topics = [wrench_topic("ft"), joints_topic("arm")]
    events = bus.subscribe("events/", maxsize=1000)
    latest_truth = {}
    contact_steps = {"n": 0, "episodes": 0, "prev": False}

    def on_state(state):
        latest_truth["s"] = state
        now = bool(state.contacts)
        contact_steps["episodes"] += now and not contact_steps["prev"]
        contact_steps["prev"] = now

    feeder = WorldFeeder(world, bus, duration=duration, on_state=on_state)
    log: list[str] = []
    console.print(f"[bold]ftc demo[/]: scene [cyan]{scene.name}[/], scenario [cyan]{scenario}[/], {duration:g} s "
                  "(world -> bus; protocol emulators come with the device adapters)")
    t_start = time.monotonic()
    with Watchdog(bus, {t: 0.1 for t in topics}), feeder, Live(console=console, refresh_per_second=8) as live:
        while not feeder.done:
            for ev in events.drain():
                log.append(f"{(ev.t_host_ns / 1e9 - t_start) % 1e6:8.3f} s  {ev.source}: {ev.kind} {ev.message}")
            live.update(Group(_stream_table(bus, topics), _wrench_table(bus.latest(topics[0]), latest_truth.get("s")),
                              "\n".join(log[-5:]) or "(no events)"))
            time.sleep(0.1)
    for ev in events.drain():
        log.append(f"{ev.source}: {ev.kind} {ev.message}")
    return _summary(console, bus, topics, feeder, contact_steps["episodes"], time.monotonic() - t_start)


def _summary(console, bus, topics, feeder, episodes: int, wall: float) -> int:
    from ..bus import StaleDataError

    table = _stream_table(bus, topics)
    table.title = f"summary: {feeder.world.t:.2f} s simulated in {wall:.2f} s wall"
    console.print(table)
    # joint state at every F/T timestamp: the bus's interpolation at work
    ok = stale = 0
    for frame in bus.window(topics[0], 0, 2**63 - 1):
        try:
            bus.sample_at(topics[1], frame.t_host_ns)
            ok += 1
        except StaleDataError:
            stale += 1
    console.print(f"contact episodes in the ground truth: {episodes}; joint state interpolated at "
                  f"{ok} F/T timestamps ({stale} refused as stale)")
    if feeder.error is not None:
        console.print(f"[red]the world stopped with an error: {feeder.error!r}[/]")
        return 1
    return 0
