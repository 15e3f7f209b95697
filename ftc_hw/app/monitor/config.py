"""What a monitor run is asked to do and what it gives back: the options of ``ftc monitor``, ``ftc demo``
and ``ftc replay`` (``MonitorOptions``, ``DemoOptions``, ``ReplayOptions``: small frozen objects, passed
whole, their parts shared: where the view goes, the simulated world, where the devices are), the run's
``MonitorOutcome``; ``MonitorSetupError`` when it cannot start."""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ftc_hw.app.web.feed import WebOptions
from ftc_hw.compensation import Drift

from .evaluate import Evaluation


class MonitorSetupError(Exception):
    """The run could not start: scene, devices, calibration or emulators (the message says which)."""


VIEWS = ("terminal", "web", "none")
RECORD_FORMATS = ("ftc", "ros2", "both")


@dataclass(frozen=True)
class ViewOptions:
    """Where the live view goes (``--view``): ``terminal`` (a table), ``web`` (the 3-D page, served as
    ``page`` says: ``--host``, ``--port``, ``--view-hz``) or ``none``."""

    kind: str = "terminal"
    page: WebOptions = WebOptions()

    def __post_init__(self) -> None:
        if self.kind not in VIEWS:
            raise ValueError(f"view {self.kind!r}: one of {', '.join(VIEWS)}")

    @property
    def terminal(self) -> bool:
        return self.kind == "terminal"

    @property
    def web(self) -> WebOptions | None:
        """The page's options with ``--view web``, else None."""
        return self.page if self.kind == "web" else None


@dataclass(frozen=True)
class SimOptions:
    """The simulated world of a run with ``sim`` (``--sim``; ``ftc demo`` always) and what is played on it."""

    scenario: str = "sweep-with-collision"
    seed: int = 0
    reality: str = "ideal"  # how the world's arm differs from the model (ideal, typical, harsh)
    noise: bool = True
    truth: Path | None = None  # the world's ground truth written here (else to a temporary file)
    faults: tuple[str, ...] = ()  # a fault plan (ftc_hw.app.monitor.faults), e.g. ("ft:kill@onset+0.1",)
    resume_after_s: float | None = None  # with a UR arm: its emulated operator plays again after a stop
    ahead: bool = False  # the world's run computed first, then played to the emulators (commands change nothing)


RETREAT_TRIGGERS = ("onset", "exceedance")  # the contact events a retreat starts on


@dataclass(frozen=True)
class RetreatSettings:
    """``distance_m``: how far the touched point moves back (ESTIMATE: 3 cm clears a contact detected
    within tens of ms at the collaborative speeds of ISO/TS 15066, 0.25-1 m/s, less the detector's lag);
    ``time_limit_s``: the time the motion must end within (a path the joints' limits make longer is cut
    to end in time, and said)."""

    distance_m: float = 0.03
    time_limit_s: float = 0.5
    trigger: str = "onset"  # or "exceedance": a contact's force past its body region's limit (docs/limits.md)
    # a contact whose guidance probability exceeds this is not retreated from (the classifier's, if any)
    guided_above: float = 0.5
    # at an onset the classifier may not know yet whether a hand guides the arm. An arm that moves (faster than
    # moving_above_m_s) or pushes into the contact (faster than pushing_above_m_s against its force: a slow press,
    # a clamp) is then held where it is, and the retreat decided once two events in a row name the intent, or
    # this long after the onset at the latest; an arm at rest is left free (held, it would fight a hand, whose
    # force then builds as a clamp's) and decided on the contact's newest event this long after the onset (or at
    # its offset). ESTIMATE: a hand is told by its force's slow rise (RISE_S, 0.25 s) and the arm yielding to it
    # (judged from 0.25 s): live, the guidance scenario's hands were named 0.38-0.44 s after their onset
    # (docs/contacts.md); at rest the arm pushes on nothing meanwhile
    decide_s: float = 1.0
    pushing_above_m_s: float = 0.01  # ESTIMATE: above a DYNAMIXEL's velocity step at a 0.3 m lever (0.007 m/s)
    # a touched point faster than this (m/s) ran into what it touched and goes back the way it came
    # (ESTIMATE: ten times what the joints' holding error moves a point)
    moving_above_m_s: float = 0.05
    damping_m: float = 0.03  # the damped least squares' lambda (m)
    waypoints: int = 5  # steps of the Cartesian line (each two Gauss-Newton steps: the planning time)
    # the path is at most this many times the one fitted to move the region's points the distance (the
    # estimated point then goes back at most about max_scale x distance_m; ESTIMATE: on dxl-arm, whose four
    # joints cannot translate the hand, the region's least point needs 1.4-1.7x, docs/monitor.md)
    max_scale: float = 2.0
    # the region the contact may be at (retreat_region.py): the event's 95 % ellipsoid, each sigma at least
    # region_floor_m (ESTIMATE: a few mm, the steady-state localization error), and the surface within
    # region_tube_m of the event's line of action (ESTIMATE: 2 cm, about a finger's half-size: the line's other
    # crossings, on dxl-arm the other finger, where the onset's estimate at times is while its point_std says
    # 1 cm), within region_reach_m of the estimate (ESTIMATE: the largest onset errors measured near the touched
    # link, 91 mm on dxl-arm's other finger, 74 mm on ur5e's next link; the onset's point_std, 0.1-3 m along the
    # force's line, would take in the whole arm)
    region_floor_m: float = 0.005
    region_tube_m: float = 0.02
    region_reach_m: float = 0.1

    def __post_init__(self) -> None:
        if not 0.0 < self.distance_m <= 0.5:
            raise ValueError(f"retreat distance {self.distance_m!r} m: expected (0, 0.5]")
        if not 0.0 < self.time_limit_s <= 10.0:
            raise ValueError(f"retreat time limit {self.time_limit_s!r} s: expected (0, 10]")
        if self.trigger not in RETREAT_TRIGGERS:
            raise ValueError(f"retreat trigger {self.trigger!r}: expected one of {', '.join(RETREAT_TRIGGERS)}")
        if not 0.0 <= self.guided_above <= 1.0:
            raise ValueError(f"guided_above {self.guided_above!r}: expected a probability")
        if not 0.0 <= self.decide_s <= 1.0:
            raise ValueError(f"decide_s {self.decide_s!r} s: expected [0, 1]")
        if not 1.0 <= self.max_scale <= 10.0:
            raise ValueError(f"max_scale {self.max_scale!r}: expected [1, 10]")
        if not 0.0 <= max(self.region_floor_m, self.region_tube_m) <= self.region_reach_m <= 1.0:
            raise ValueError(f"region_floor_m {self.region_floor_m!r}, region_tube_m {self.region_tube_m!r}, "
                             f"region_reach_m {self.region_reach_m!r} m: expected 0 <= floor, tube <= reach <= 1")


@dataclass(frozen=True)
class DeviceOptions:
    """Where the scene's devices are and where their readers run."""

    overrides: tuple[str, ...] = ()  # NAME.KEY=VALUE (--device), applied after the rig file
    rig: Path | None = None  # a rig file (--rig): a table of keys per device name
    remote: str | None = None  # a Zenoh endpoint: the devices' frames from ftc serve there, not adapters here
    remote_rig: str | None = None  # the rig's name in ftc/<rig>/... (default: the scene's name)
    zenoh_config: Path | None = None  # with remote: a Zenoh JSON5 file (TLS, credentials), docs/bus.md
    readers: str = "auto"  # without remote: "process" (each reader in its own, as ftc serve), "thread", "auto"


@dataclass(frozen=True)
class MonitorOptions:
    """One monitor run (``ftc monitor``; ``ftc demo`` and ``ftc identify --sim`` run one too)."""

    scene: str  # a built-in scene's name or a scene file
    sensing: tuple[str, ...] | None = None  # which of the scene's sensing to use (None: the scene's own)
    sim: bool = False  # the scene's emulated devices in a simulated world, as ``world`` says
    world: SimOptions = SimOptions()
    duration: float | None = None  # simulated seconds with sim, else wall-clock seconds (None: until Ctrl-C)
    calibration: Path | None = None
    level: str | None = "dynamics"  # compensation level; None: the scene's
    refine: bool = False  # keep refining the calibration's identified model while the arm moves free
    record: Path | None = None
    record_format: str = "ftc"  # what --record writes: "ftc" (MCAP, the bus's JSON), "ros2" (a ROS 2 bag), "both"
    ros_namespace: str | None = None  # --ros: publish the outputs on ROS 2 under this namespace (None: not)
    events: Path | None = None
    reflex: str | None = None  # "stop" or "retreat"
    retreat: RetreatSettings = RetreatSettings()  # with reflex "retreat": how far, how fast
    limits: Path | None = None  # the cell's body limits (docs/limits.md); None: the built-in ISO/TS 15066 regions
    view: ViewOptions = ViewOptions()
    devices: DeviceOptions = DeviceOptions()
    title: str = "ftc monitor"
    connect_timeout_s: float = 20.0
    judged: bool = True  # with sim: the summary judges the events against the truth (not for a run that records
    # free motion for identification, where the model not yet identified raises alarms that mean nothing)


@dataclass(frozen=True)
class DemoOptions:
    """``ftc demo``: a simulated monitor run, in a mismatched world first identified for ``identify_s`` s."""

    monitor: MonitorOptions
    identify_s: float = 30.0  # 0: the nominal model monitors the drawn arm


@dataclass(frozen=True)
class ReplayOptions:
    """``ftc replay``: a recording's pipeline inputs through the same pipeline."""

    recording: Path  # an MCAP file of ftc monitor --record, a UR recording (CSV) or a ROS 2 bag
    speed: float = 1.0  # 1: as recorded; 0: as fast as possible
    events: Path | None = None  # the replayed events written here
    calibration: Path | None = None  # instead of the recording's
    view: ViewOptions = ViewOptions()
    limits: Path | None = None  # the cell's body limits instead of the recording's (docs/limits.md)
    scene: str | None = None  # a UR recording's scene (an MCAP recording holds its own)
    sensing: tuple[str, ...] | None = None  # a UR recording: which sensing (None: what the file allows)
    topics: Path | None = None  # a ROS 2 bag: its topic map (None: the drivers' defaults for the scene)


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
    provisional_events: list[dict[str, Any]] = field(default_factory=list)  # provisional_onset, _unconfirmed
    faults: list[tuple[str, float]] = field(default_factory=list)  # (fault, scenario time s when done)
    vendor_lines: Counter[str] = field(default_factory=Counter)  # vendor library lines, as rewritten
    degraded: list[str] = field(default_factory=list)  # why the run cannot be read as clean
    remote: dict[str, Any] = field(default_factory=dict)  # with remote: frames taken, dropped, events sent
    device_counters: dict[str, dict[str, int]] = field(default_factory=dict)  # per device: its adapter's counters
    web: dict[str, Any] = field(default_factory=dict)  # with the page: its URL, ticks sent, dropped
    ros: dict[str, Any] = field(default_factory=dict)  # with --ros: messages published, failed, frames dropped
