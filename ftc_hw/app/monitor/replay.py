"""``ftc replay``: a recording's pipeline inputs through the same pipeline; the events against the recorded ones."""
from __future__ import annotations

from rich.console import Console
from rich.live import Live

from ftc_hw.app.web.replay import ReplayTimeline, serve_until_interrupted
from ftc_hw.bus import Bus, ContactEvent, joints_topic, wrench_topic
from ftc_hw.monitor import MONITOR_INPUT
from ftc_hw.record.events import event_line
from ftc_hw.record.reader import RecordingError, read_recording
from ftc_hw.record.replay import ReplayError, ReplayResult, recorded_scene, recorded_settings, replay
from ftc_hw.scene.limits import LimitsError, load_limits

from .config import MonitorSetupError, ReplayOptions
from .session import load_pipeline_calibration
from .view import LiveView


def run_replay(options: ReplayOptions, console: Console) -> ReplayResult:
    """The replay, its live view, its events written, the comparison said; then, with ``--view web``, the
    page over it until Ctrl-C. Raises ``MonitorSetupError`` when the recording or the calibration cannot
    be read, ``ReplayError`` when the replay cannot go on."""
    path, speed, events_path, calibration = options.recording, options.speed, options.events, options.calibration
    view = options.view.kind
    try:
        rec = read_recording(path)
        scene = recorded_scene(rec)
        settings = recorded_settings(rec)
        if calibration:  # the recorded settings with this calibration's corrections
            settings = settings.replace(corrections=load_pipeline_calibration(calibration, scene)[0])
        limits = load_limits(options.limits) if options.limits is not None else None
    except (RecordingError, ReplayError, LimitsError, OSError) as exc:
        raise MonitorSetupError(str(exc)) from None
    counts = rec.counts()
    console.print(f"{path}: {sum(counts.values())} messages on {len(counts)} topics "
                  f"({', '.join(f'{k} {v}' for k, v in sorted(counts.items()))}), scene {scene.name}"
                  + ("" if rec.complete else f" [yellow](cut short: {rec.error}; read up to its last chunk)[/]"))
    meta = rec.metadata.get("monitor", {})
    bus = Bus()
    topics = [wrench_topic(meta.get("ft_source", "ft")), joints_topic(meta.get("arm_source", "arm")), MONITOR_INPUT]
    show = view == "terminal" and speed > 0
    page = options.view.page
    timeline = ReplayTimeline(bus, scene, topics, t0_ns=rec.messages[0].log_time, rate_hz=page.rate_hz) \
        if view == "web" and rec.messages else None
    state: dict = {}
    last_ns = [rec.messages[0].log_time if rec.messages else 0]

    def ready(monitor) -> None:
        if timeline is not None:
            timeline.ready(monitor)
        state["view"] = LiveView(bus, monitor, topics, ft_topic=topics[0], title=f"ftc replay {path.name}",
                                 now_ns=lambda: last_ns[0])
        state["view"].t0_ns = last_ns[0]

    sub = bus.subscribe("events/", maxsize=None)
    live = Live(console=console, refresh_per_second=4, auto_refresh=False) if show else None
    step = {"n": 0}

    def on_message(monitor) -> None:
        if timeline is not None:
            timeline.on_message(monitor)
        step["n"] += 1
        if live is None or step["n"] % 200:
            return
        v = state["view"]
        last_ns[0] = max(last_ns[0], (bus.latest(topics[0]).t_host_ns if bus.latest(topics[0]) else last_ns[0]))
        for ev in sub.drain():
            v.add(ev)
        live.update(v.render(), refresh=True)

    try:
        if live is not None:
            live.start()
        result = replay(rec, scene=scene, settings=settings, speed=0.0 if timeline else speed, bus=bus,
                        on_message=on_message,
                        monitor_ready=ready, limits=limits)
    finally:
        if live is not None:
            live.stop()
    if events_path is not None:
        with open(events_path, "w", encoding="utf-8") as f:
            for e in result.events:
                f.write(event_line(e) + "\n")
    contacts = [e for e in result.events if isinstance(e, ContactEvent)]
    kinds = {k: sum(e.kind == k for e in contacts) for k in ("onset", "update", "offset", "exceedance")}
    lost = len(result.events) - len(contacts)
    console.print(f"replayed {result.inputs} pipeline inputs: {len(contacts)} contact events {kinds}"
                  + (f", {lost} stream lost/back events (recorded)" if lost else "")
                  + (f" -> {events_path}" if events_path else ""))
    if result.identical:
        console.print(f"[green]identical[/] to the {len(result.recorded)} recorded events")
    else:
        diff = result.first_difference()
        console.print(f"[yellow]differs[/] from the {len(result.recorded)} recorded events; first difference at "
                      f"#{diff[0]}:\n  replayed: {diff[1]}\n  recorded: {diff[2]}")
    if timeline is not None:
        timeline.finish()
        serve_until_interrupted(timeline.page(f"ftc replay {path.name}", page), console)
    return result
