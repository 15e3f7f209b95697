"""``ftc replay FILE.csv --scene S``: a user's UR recording (UR's RTDE client or ur_rtde's file recording,
:mod:`ftc_hw.record.ur_csv`) through the monitor a live arm runs, joint-driven. What the file holds
(format, rows kept and skipped by reason, timing, the sensing its columns allow) is said first; there
are no recorded events to compare with."""
from __future__ import annotations

from dataclasses import dataclass

from rich.console import Console

from ftc_hw.bus import EVENTS_CONTACT, Bus, ContactEvent
from ftc_hw.monitor import LiveMonitor
from ftc_hw.pipeline import Corrections, PipelineSettings
from ftc_hw.record.events import event_line
from ftc_hw.record.ur_csv import URRecording, pipeline_inputs, read_ur_csv
from ftc_hw.scene import SceneError, load_scene

from .config import MonitorSetupError, ReplayOptions
from .session import load_pipeline_calibration

MCAP_MAGIC = b"\x89MCAP"
TARE_S = 0.1  # without a calibration, the flange sensor is tared on the recording's first 0.1 s


def is_mcap(path) -> bool:
    with open(path, "rb") as f:
        return f.read(len(MCAP_MAGIC)) == MCAP_MAGIC


@dataclass(frozen=True)
class CsvReplayResult:
    recording: URRecording  # or a ROS 2 bag's BagRecording (replay_bag.py)
    inputs: int
    events: list[ContactEvent]
    counters: dict[str, int]

    @property
    def onsets(self) -> int:
        return sum(e.kind == "onset" for e in self.events)


def run_csv_replay(options: ReplayOptions, console: Console) -> CsvReplayResult:
    """The recording read and said, replayed through the scene's monitor, its events written."""
    if options.scene is None:
        raise MonitorSetupError(f"{options.recording}: a UR recording holds no scene: give --scene (ur10e, ur5e, ...)")
    try:
        rec = read_ur_csv(options.recording)
        scene = load_scene(options.scene)
        if options.sensing is not None:
            scene = scene.with_sensing(options.sensing)
        elif not scene.sensing.kinds <= rec.sensing:  # what the file allows of what the scene has
            scene = scene.with_sensing(scene.available.kinds & rec.sensing)
    except (OSError, ValueError) as exc:  # URCsvError and SceneError are ValueErrors
        raise MonitorSetupError(str(exc)) from None
    corrections = load_pipeline_calibration(options.calibration, scene)[0] if options.calibration else None
    console.print(rec.summary())
    console.print(f"scene {scene.name}, sensing used: {scene.sensing.label()}"
                  + ("" if corrections else " [yellow](no --calibration: the nominal model; ftc identify first)[/]"))
    try:
        inputs = pipeline_inputs(rec, scene, tare_s=None if corrections else TARE_S)
    except (ValueError, SceneError) as exc:
        raise MonitorSetupError(str(exc)) from None
    bus = Bus()
    sub = bus.subscribe(EVENTS_CONTACT, maxsize=None)
    settings = PipelineSettings(corrections=corrections or Corrections())
    monitor = LiveMonitor(bus, scene, tare_s=None if corrections else TARE_S, publish_inputs=False,
                          settings=settings)
    for inp in inputs:
        monitor.consume(inp)
    events = [e for e in sub.drain() if isinstance(e, ContactEvent)]
    return say_replayed(CsvReplayResult(rec, len(inputs), events, dict(monitor.counters)), options, console, "rows")


def say_replayed(result: CsvReplayResult, options: ReplayOptions, console: Console, what: str) -> CsvReplayResult:
    """The replayed events written (``--events``) and counted; ``what`` the inputs were (rows, messages)."""
    events = result.events
    if options.events is not None:
        with open(options.events, "w", encoding="utf-8") as f:
            for e in events:
                f.write(event_line(e) + "\n")
    kinds = {k: sum(e.kind == k for e in events) for k in ("onset", "update", "offset")}
    errors = result.counters.get("errors", 0)
    console.print(f"replayed {result.inputs} {what}: {len(events)} contact events {kinds}"
                  + (f", [red]{errors} {what} the pipeline could not judge[/]" if errors else "")
                  + (f" -> {options.events}" if options.events else ""))
    return result
