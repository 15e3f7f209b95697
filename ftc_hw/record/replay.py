"""Replay: a recording's pipeline inputs (``monitor/input``) through a fresh :class:`~ftc_hw.monitor.LiveMonitor`
with the recorded scene, calibration and monitor settings. With nothing changed the events are the
recorded ones, bit for bit; the recorded device streams are published on the replay's bus too (for
the live view's stream statistics, on their recorded host times).
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from ftc_hw.bus import EVENTS_CONTACT, EVENTS_DEVICE, STREAM_EVENT_KINDS, Bus, ContactEvent, DeviceEvent
from ftc_hw.monitor import MONITOR_INPUT, LiveMonitor
from ftc_hw.pipeline import PipelineSettings, SettingsError
from ftc_hw.record.events import event_record
from ftc_hw.scene import Scene, SceneError, load_scene
from ftc_hw.scene.limits import CellLimits, LimitsError

from .reader import Recording


class ReplayError(Exception):
    pass


def recorded_scene(rec: Recording) -> Scene:
    """The scene the recording was made with, using the sensing it used (``--sensing``; recordings made
    before it was recorded: the scene's own)."""
    meta = rec.metadata.get("scene")
    if meta is None:
        raise ReplayError(f"{rec.path}: no scene metadata; give --scene")
    for ref in (meta.get("path"), meta.get("name")):
        if not ref:
            continue
        try:
            scene = load_scene(ref)
        except (SceneError, OSError):
            continue
        sensing = meta.get("sensing")
        try:
            return scene.with_sensing(sensing.split(",")) if sensing else scene
        except SceneError as exc:
            raise ReplayError(f"{rec.path}: the recorded sensing: {exc}") from None
    raise ReplayError(f"{rec.path}: scene {meta.get('name')!r} ({meta.get('path')}) not found; give --scene")


def recorded_settings(rec: Recording) -> PipelineSettings:
    """The pipeline's settings the recording was made with (any version's form; ReplayError if unreadable)."""
    try:
        return PipelineSettings.from_json(rec.metadata.get("monitor", {}).get("pipeline", "{}"))
    except SettingsError as exc:
        raise ReplayError(f"{rec.path}: {exc}") from None


def recorded_limits(rec: Recording) -> CellLimits | None:
    """The body limits the recording was made with (None: recorded before them, or without; ReplayError if
    unreadable)."""
    text = rec.metadata.get("monitor", {}).get("limits")
    if not text:
        return None
    try:
        return CellLimits.from_json(text)
    except (LimitsError, ValueError, KeyError, TypeError) as exc:
        raise ReplayError(f"{rec.path}: the recorded limits: {exc}") from None


CLASS_KEYS = ("contact_class", "p_quasi_static", "intent", "p_guidance", "class_features")


@dataclass
class ReplayResult:
    inputs: int
    events: list[ContactEvent | DeviceEvent]  # contact events and the streams' lost/back events, in order
    recorded: list[ContactEvent | DeviceEvent]
    monitor: LiveMonitor

    def records(self) -> tuple[list[dict], list[dict]]:
        """The replayed and the recorded events' records; where a recorded contact event has no class (a
        recording made before contacts were classified), the replayed one's class is left out beside it."""
        a, b = [event_record(e) for e in self.events], [event_record(e) for e in self.recorded]
        for x, y in zip(a, b, strict=False):
            if y.get("contact_class") == "" and "contact_class" in x:
                for k in CLASS_KEYS:
                    x.pop(k, None)
                    y.pop(k, None)
        return a, b

    @property
    def identical(self) -> bool:
        a, b = self.records()
        return a == b

    def first_difference(self) -> tuple[int, dict | None, dict | None] | None:
        a, b = self.records()
        for i in range(max(len(a), len(b))):
            x = a[i] if i < len(a) else None
            y = b[i] if i < len(b) else None
            if x != y:
                return i, x, y
        return None


def replay(rec: Recording, *, scene: Scene | None = None, settings: PipelineSettings | None = None,
           speed: float = 0.0, bus: Bus | None = None, on_message: Callable[[LiveMonitor], None] | None = None,
           monitor_ready: Callable[[LiveMonitor], None] | None = None,
           limits: CellLimits | None = None) -> ReplayResult:
    """``speed``: 0 as fast as possible, else the recording's pace times ``speed``. ``settings``:
    instead of the recorded ones (e.g. another calibration). ``on_message``: called after each message.
    ``limits``: the body limits instead of the recorded ones (recorded none: the events are not judged)."""
    scene = scene or recorded_scene(rec)
    meta = rec.metadata.get("monitor", {})
    settings = recorded_settings(rec) if settings is None else settings
    limits = recorded_limits(rec) if limits is None else limits
    tare = meta.get("tare_s", "0.1")
    inputs = [m for m in rec.messages if m.topic == MONITOR_INPUT]
    if not inputs:
        raise ReplayError(f"{rec.path}: no {MONITOR_INPUT} messages (not recorded by ftc monitor)")
    bus = bus or Bus()
    try:
        monitor = LiveMonitor(bus, scene, ft_source=meta.get("ft_source", "ft"),
                              arm_source=meta.get("arm_source", "arm"),
                              tare_s=None if tare in ("", "None") else float(tare), publish_inputs=False,
                              settings=settings, limits=limits)
    except LimitsError as exc:
        raise ReplayError(str(exc)) from None
    if monitor_ready is not None:
        monitor_ready(monitor)
    sub = bus.subscribe("events/", maxsize=None)
    recorded: list[ContactEvent | DeviceEvent] = []
    t0 = rec.messages[0].log_time
    wall0 = time.monotonic()
    for m in rec.messages:
        if speed > 0:
            ahead = (m.log_time - t0) / 1e9 / speed - (time.monotonic() - wall0)
            if ahead > 0.001:
                time.sleep(ahead)
        if m.topic == MONITOR_INPUT:
            monitor.consume(m.frame)
        elif m.topic == EVENTS_CONTACT:
            recorded.append(m.frame)
        else:
            bus.publish(m.topic, m.frame)
            if m.topic == EVENTS_DEVICE and m.frame.kind in STREAM_EVENT_KINDS:
                recorded.append(m.frame)
                monitor.apply_stream_event(m.frame)  # a lost stream closed a contact live: here too
        if on_message is not None:
            on_message(monitor)
    events = [e for e in sub.drain() if isinstance(e, ContactEvent) or e.kind in STREAM_EVENT_KINDS]
    sub.close()
    if not rec.complete:
        # a cut recording: its last chunk may have lost the events of inputs it kept
        last = inputs[-1].frame.t_host_ns
        events = [e for e in events if e.t_host_ns <= last]
        recorded = [e for e in recorded if e.t_host_ns <= last]
    return ReplayResult(len(inputs), events, recorded, monitor)
