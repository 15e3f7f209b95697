"""What a monitor run is asked to do (``MonitorConfig``: ``ftc monitor``'s and ``ftc demo``'s options) and
what it gives back (``MonitorOutcome``); ``MonitorSetupError`` when it cannot start."""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ftc_hw.compensation import Drift

from .evaluate import Evaluation


class MonitorSetupError(Exception):
    """The run could not start: scene, devices, calibration or emulators (the message says which)."""


@dataclass
class MonitorConfig:
    scene: str
    sim: bool = False
    scenario: str = "sweep-with-collision"
    seed: int = 0
    duration: float | None = None  # simulated seconds with sim, else wall-clock seconds (None: until Ctrl-C)
    calibration: Path | None = None
    record: Path | None = None
    reflex: str | None = None  # "stop"
    resume_after_s: float | None = None  # with sim and a UR arm: its emulated operator plays again after a stop
    events: Path | None = None
    truth: Path | None = None
    noise: bool = True
    view: bool = True  # the live view in the terminal
    web: Any = None  # a WebOptions (ftc_hw.app.web.feed): the live page in the browser (--view web)
    level: str | None = "dynamics"  # compensation level; None: the scene's
    title: str = "ftc monitor"
    connect_timeout_s: float = 20.0
    faults: tuple[str, ...] = ()  # with sim: a fault plan (ftc_hw.app.monitor.faults), e.g. ("ft:kill@onset+0.1",)
    device_overrides: tuple[str, ...] = ()  # NAME.KEY=VALUE (--device), applied after the rig file
    rig: Path | None = None  # a rig file (--rig): a table of keys per device name
    reality: str = "ideal"  # with sim: how the world's arm differs from the model (ideal, typical, harsh)
    refine: bool = False  # keep refining the calibration's identified model while the arm moves free
    remote: str | None = None  # a Zenoh endpoint: the devices' frames from ftc serve there, not adapters here
    remote_rig: str | None = None  # the rig's name in ftc/<rig>/... (default: the scene's name)
    zenoh_config: Path | None = None  # with remote: a Zenoh JSON5 file (TLS, credentials), docs/bus.md
    readers: str = "auto"  # without remote: "process" (each reader in its own, as ftc serve), "thread", "auto"
    judged: bool = True  # with sim: the summary judges the events against the truth (not for a run that records
    # free motion for identification, where the model not yet identified raises alarms that mean nothing)


@dataclass
class MonitorOutcome:
    exit_code: int
    events: list[dict[str, Any]] = field(default_factory=list)
    evaluation: Evaluation | None = None
    counters: dict[str, int] = field(default_factory=dict)
    reflex: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    t_closed_ns: int = 0  # when the adapters were closed
    drift: Drift | None = None  # with refine: how far the refined model moved from the calibration's
    stream_events: list[dict[str, Any]] = field(default_factory=list)  # sensor_lost, arm_back, ...
    faults: list[tuple[str, float]] = field(default_factory=list)  # (fault, scenario time s when done)
    vendor_lines: Counter[str] = field(default_factory=Counter)  # vendor library lines, as rewritten
    degraded: list[str] = field(default_factory=list)  # why the run cannot be read as clean
    remote: dict[str, Any] = field(default_factory=dict)  # with remote: frames taken, dropped, events sent
    device_counters: dict[str, dict[str, int]] = field(default_factory=dict)  # per device: its adapter's counters
    web: dict[str, Any] = field(default_factory=dict)  # with the page: its URL, ticks sent, dropped
