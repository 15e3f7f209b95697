"""One monitor run: the scene's device adapters on a bus (with ``sim``, connected to the emulated
devices of a :class:`~ftc_hw.sim_devices.host.WorldHost` with a pre-roll), the live contact monitor, optionally the MCAP
recorder, the events file and the stop reflex; the live view while it runs; the summary (with the
ground truth when simulated) at the end. ``ftc monitor`` and ``ftc demo`` run this.
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console
from rich.live import Live

from ftc_hw import __version__
from ftc_hw.app.serving.remote_rig import RemoteRig
from ftc_hw.app.serving.serve import ServedReaders
from ftc_hw.app.setup.rig import Rig, RigError, build_rig, check_located, pick_device, require_device
from ftc_hw.app.setup.vendor_output import vendor_stderr
from ftc_hw.app.web.feed import WebFeed, WebViewError
from ftc_hw.bus import (
    EVENTS_DEVICE,
    PROVISIONAL_EVENT_KINDS,
    STREAM_EVENT_KINDS,
    Bus,
    ContactEvent,
    DeviceEvent,
    joints_topic,
    wrench_topic,
)
from ftc_hw.bus.remote import free_loopback_endpoint
from ftc_hw.calibration.file import CalibrationError, load_calibration
from ftc_hw.devices.base import DeviceError, frozen_heap, responsive_readers
from ftc_hw.devices.registry import role_of
from ftc_hw.model import ArmModel
from ftc_hw.monitor import MONITOR_INPUT, LiveMonitor
from ftc_hw.pipeline import Corrections, PipelineSettings
from ftc_hw.record.events import EventWriter, event_record, read_truth
from ftc_hw.record.writer_process import RecorderProcess, Sink
from ftc_hw.scene import DeviceSpec, Scene, SceneError, load_rig_scene
from ftc_hw.scene.limits import CellLimits, LimitsError, builtin_limits, load_limits
from ftc_hw.sim_devices.ahead import AheadError
from ftc_hw.sim_devices.host import WorldHost

from .config import MonitorOptions, MonitorOutcome, MonitorSetupError
from .evaluate import crlb_of_truth, evaluate, solver_rms_of_truth
from .faults import Fault, FaultError, FaultPlan
from .reflex import RetreatReflex, StopReflex
from .report import judge_degraded, print_summary
from .sim_joints import SimJointSource
from .view import LiveView

SETTLE_S = 0.5


def load_pipeline_calibration(path: Path, scene: Scene) -> tuple[Corrections, dict[str, str]]:
    """``(the pipeline's corrections, MCAP metadata)`` of a calibration file (``load_calibration``)."""
    try:
        cal = load_calibration(path, scene=scene, sensor_serial=None)
    except Exception as exc:  # noqa: BLE001 - its typed error (or an OS error): shown to the user
        raise MonitorSetupError(f"--calibration {path}: {exc}") from None
    try:
        corrections = cal.corrections(scene)
    except (CalibrationError, ValueError) as exc:
        raise MonitorSetupError(f"--calibration {path}: {exc}") from None
    text = Path(path).read_text(encoding="utf-8", errors="replace")
    meta = {"file": str(path), "content": text, "pipeline": PipelineSettings(corrections=corrections).to_json()}
    applied = [k for k in ("frame", "gravity", "inertials", "gain", "joints", "model_error")
               if getattr(corrections, k) is not None]
    if applied:
        meta["applied"] = ", ".join(applied)
    return corrections, meta


def cell_limits(path: Path | None, console: Console) -> CellLimits:
    """The cell's body limits (``--limits``; None: the built-in regions), said; MonitorSetupError on a bad file."""
    try:
        limits = load_limits(path) if path is not None else builtin_limits()
    except LimitsError as exc:
        raise MonitorSetupError(str(exc)) from None
    console.print(f"body limits {path or 'built-in (ISO/TS 15066)'}: {len(limits.regions)} regions, "
                  f"{len(limits.links)} links and {len(limits.zones)} zones assigned, the rest "
                  f"{limits.default_region} (docs/limits.md)")
    return limits


def _devices(scene: Scene, sim: bool, remote: bool = False) -> tuple[DeviceSpec | None, DeviceSpec | None]:
    """The scene's F/T sensor (None where its sensing uses none) and arm devices (one device may be both:
    a UR reading its flange sensor); without an arm device only a simulated world will do."""
    try:
        ft = require_device(scene, "ft") if scene.sensing.ft is not None else None
        arm = pick_device(scene, "arm") if sim else require_device(scene, "arm")
        if not sim and not remote:  # said before anything loads: the devices must say where they are
            check_located([d for d in (ft, arm) if d is not None])
        return ft, arm
    except RigError as exc:
        hint = ": with --sim the world's joint state is used" if "arm device" in str(exc) else ""
        raise MonitorSetupError(f"{exc}{hint}") from None


def _wait_idle(monitor: LiveMonitor, timeout: float = 5.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end and monitor.backlog():
        time.sleep(0.01)
    time.sleep(0.05)


def run_monitor(cfg: MonitorOptions, console: Console | None = None) -> MonitorOutcome:
    console = console or Console()
    try:
        scene = load_rig_scene(cfg.scene, cfg.devices.overrides, cfg.devices.rig, cfg.sensing)
    except SceneError as exc:
        raise MonitorSetupError(str(exc)) from None
    _check_remote(cfg)
    _check_ros(cfg)
    ft_dev, arm_dev = _devices(scene, cfg.sim, cfg.devices.remote is not None)
    try:
        faults = [Fault.parse(f) for f in cfg.world.faults]
    except FaultError as exc:
        raise MonitorSetupError(str(exc)) from None
    corrections, cal_meta = load_pipeline_calibration(cfg.calibration, scene) if cfg.calibration else (None, None)
    out = MonitorOutcome(0)
    if cal_meta and cal_meta.get("applied"):
        console.print(f"calibration {cfg.calibration}: bias{', payload' if corrections.payload else ''} and "
                      f"its corrections ({cal_meta['applied']})")
    # readers that poll, and the reflex, while the pipeline computes (the pipeline in the readers' tier even
    # when they run in processes of their own: at ordinary priority it fell behind the world and emulators
    # on a host with no core to spare, docs/measurements/bus.md); vendor C++ lines made readable
    with responsive_readers(), vendor_stderr() as vendor:
        out.vendor_lines = vendor.counts
        return _run(cfg, console, scene, ft_dev, arm_dev, corrections, cal_meta, out, faults)


SIM_PROCESS_READERS_MIN_CPUS = 4


def readers_mode(cfg: MonitorOptions) -> tuple[str, str]:
    """Where this run's readers run, "process" or "thread", and why. ``auto``: in processes of their own,
    except with a simulated world on a host of fewer than 4 cores, where the world and the emulators
    already take most of the cores: measured on 2 cores (docs/measurements/bus.md), reader processes (their own
    interpreters, Zenoh) there left the pipeline seconds behind and RTDE missed as many packets."""
    if cfg.devices.readers != "auto":
        return cfg.devices.readers, f"--readers {cfg.devices.readers}"
    cpus = os.cpu_count() or 1
    if cfg.sim and cpus < SIM_PROCESS_READERS_MIN_CPUS:
        return "thread", (f"the simulated world and its emulators share this host's {cpus} cores: readers in "
                          f"threads (--readers process to override; docs/measurements/bus.md)")
    return "process", "readers in processes of their own (--readers thread to keep them here)"


def _served(cfg: MonitorOptions) -> bool:
    """Whether the devices' readers run in processes of their own (ftc serve's, or this run's)."""
    return bool(cfg.devices.remote) or readers_mode(cfg)[0] == "process"


def _check_remote(cfg: MonitorOptions) -> None:
    if cfg.devices.remote is None:
        return
    clash = [what for what, on in (("--sim", cfg.sim), ("--fault", cfg.world.faults)) if on]
    if clash:  # the faults act on emulators this process starts
        raise MonitorSetupError(f"--remote takes the devices' frames from ftc serve: not with {', '.join(clash)} "
                                "(start the world with ftc serve --sim)")


def _check_ros(cfg: MonitorOptions) -> None:
    """``--ros`` and the ROS 2 recording need the ``ros`` extra: said before anything starts."""
    wanted = [what for what, on in (("--ros", cfg.ros_namespace is not None),
                                    (f"--record-format {cfg.record_format}", cfg.record and cfg.record_format != "ftc"))
              if on]
    if not wanted:
        return
    from ftc_hw.app.ros import RosUnavailable, require_ros  # lazy: ROS only for its options
    try:
        require_ros(" and ".join(wanted))
    except RosUnavailable as exc:
        raise MonitorSetupError(str(exc)) from None
    if cfg.ros_namespace is not None:
        from ftc_hw.app.ros.layout import check_namespace  # lazy: ROS only for its options
        try:
            check_namespace(cfg.ros_namespace)
        except ValueError as exc:
            raise MonitorSetupError(f"--ros-namespace: {exc}") from None


def _ros_sinks(cfg: MonitorOptions, scene: Scene) -> tuple[Sink, ...]:
    """The ROS 2 bag's writer for the recorder's process (``--record-format ros2|both``)."""
    if cfg.record_format == "ftc":
        return ()
    from ftc_hw.app.ros.bag import bag_path, bag_sink  # lazy: ROS only for its options
    path = bag_path(cfg.record, cfg.record_format)
    if path.exists():
        raise MonitorSetupError(f"--record-format {cfg.record_format}: {path} exists (a ROS 2 bag is a new directory)")
    return (bag_sink(path=path, scene=scene, namespace=cfg.ros_namespace or "/ftc"),)


def _start_ros(cfg: MonitorOptions, console: Console, scene: Scene, bus: Bus, stack: contextlib.ExitStack):
    """``--ros``: the node publishing the outputs (docs/ros.md), from a thread of its own."""
    from ftc_hw.app.ros.publisher import RosPublisher  # lazy: ROS only for its options
    ros = RosPublisher(bus, scene, namespace=cfg.ros_namespace).start()
    stack.callback(ros.stop)  # on a failed start; a no-op after the stop below
    console.print(f"ROS 2: node {ros.node_name} publishing under {cfg.ros_namespace} (ROS_DOMAIN_ID "
                  f"{os.environ.get('ROS_DOMAIN_ID', '0')})")
    return ros


def _stop_on_sigterm(stack: contextlib.ExitStack) -> None:
    """SIGTERM stops like Ctrl-C: adapters, recorder and emulators are closed, never orphaned."""
    with contextlib.suppress(ValueError):  # not the main thread
        previous = signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt()))
        stack.callback(signal.signal, signal.SIGTERM, previous)


def _launch_world(cfg: MonitorOptions, console: Console, scene: Scene, stack: contextlib.ExitStack
                  ) -> tuple[WorldHost, Path]:
    """The scene's world and emulators launched (:func:`_world_up` waits for them), to hold the scenario's start
    pose until ``go()``; the truth file."""
    world_options = cfg.world
    truth_path = world_options.truth
    if truth_path is None:
        truth_path = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="ftc-monitor-"))) / "truth.jsonl"
    try:
        world = WorldHost(scene, world_options.scenario, duration=cfg.duration, seed=world_options.seed,
                          noise=world_options.noise, preroll=True, truth=truth_path, reality=world_options.reality,
                          options=_resume_options(cfg, scene), ahead=world_options.ahead)
    except (SceneError, AheadError) as exc:
        raise MonitorSetupError(str(exc)) from None
    if world_options.ahead:
        world.on_progress = _progress(console)
    console.print(f"starting the world (MuJoCo, reality [cyan]{world_options.reality}[/]) and the emulated devices of "
                  f"[cyan]{scene.name}[/] "
                  f"({', '.join(f'{d.name}: {d.kind}' for d in scene.devices)}) ...")
    world.launch()
    stack.callback(world.close)
    return world, truth_path


def _world_up(console: Console, world: WorldHost, t0: float) -> None:
    """Until the launched world and its emulators are up (launched at ``t0``, monotonic s)."""
    try:
        world.wait_started()
    except Exception as exc:  # noqa: BLE001 - emulator start failures carry their reason
        raise MonitorSetupError(str(exc)) from None
    took = world.startup_s
    ahead = f", computed ahead in {took['ahead']:.1f} s" if "ahead" in took else ""
    console.print(f"world up in {time.monotonic() - t0:.1f} s (built in {took.get('world', 0.0):.1f} s{ahead}); "
                  "emulators up: "
                  + ", ".join(f"{n} ({e['kind']}) {took.get(n, 0.0):.1f} s" for n, e in world.endpoints.items()))


def _progress(console: Console, every_s: float = 5.0):
    """What a world computed ahead says while it computes, at most every ``every_s``."""
    last = [time.monotonic()]

    def said(done: float, of: float) -> None:
        if time.monotonic() - last[0] >= every_s:
            last[0] = time.monotonic()
            console.print(f"computing the world ahead: {done:.0f} of {of:.0f} simulated s", highlight=False)
    return said


def _arms(scene: Scene) -> list[DeviceSpec]:
    return [d for d in scene.devices if role_of(d.kind) == "arm"]


def resumable(scene: Scene) -> bool:
    """Whether ``--resume-after`` applies: the scene's arm is a UR controller (no other has an operator)."""
    arms = _arms(scene)
    return bool(arms) and all(d.kind == "ur-rtde" for d in arms)


def _resume_options(cfg: MonitorOptions, scene: Scene) -> dict[str, dict]:
    """The emulators' options for ``--resume-after``: the UR controller's operator."""
    if cfg.world.resume_after_s is None:
        return {}
    if not resumable(scene):
        raise MonitorSetupError(f"--resume-after: only an emulated UR controller resumes its program; {scene.name}'s "
                                f"arm is {', '.join(d.kind for d in _arms(scene)) or 'missing'}")
    return {d.name: {"resume_after_s": cfg.world.resume_after_s} for d in _arms(scene)}


def _start_recorder(cfg: MonitorOptions, scene: Scene, bus: Bus, monitor_meta: dict[str, str],
                    cal_meta: dict[str, str] | None) -> RecorderProcess:
    toml = Path(scene.path).read_text(encoding="utf-8")
    meta = {"scene": {"name": scene.name, "path": str(scene.path), "toml": toml,
                      "sensing": ",".join(sorted(scene.sensing.kinds))}, "monitor": monitor_meta}
    if cal_meta is not None:
        meta["calibration"] = cal_meta
    try:
        return RecorderProcess(bus, cfg.record, metadata=meta, scene=scene, sinks=_ros_sinks(cfg, scene),
                               ftc=cfg.record_format != "ros2").start()
    except OSError as exc:
        raise MonitorSetupError(f"--record {cfg.record}: {exc}") from None


def _tare_then_go(cfg: MonitorOptions, monitor: LiveMonitor, world: WorldHost) -> None:
    """The world's pre-roll starts from a posed state: let the arm settle (SETTLE_S from when the world was up),
    tare at rest, start the scenario."""
    time.sleep(max(0.0, SETTLE_S - (time.monotonic() - world.up_since)))
    monitor.start()
    end = time.monotonic() + cfg.connect_timeout_s
    while not monitor.tared and time.monotonic() < end:
        time.sleep(0.02)
    if not monitor.tared:
        raise MonitorSetupError(f"no tare within {cfg.connect_timeout_s:g} s: {dict(monitor.counters)}")
    world.go()


@dataclass
class _Live:
    """What a run started, for its live view, its stop and its summary."""

    bus: Bus
    topics: list[str]
    monitor: LiveMonitor
    rig: Rig | RemoteRig
    world: WorldHost | None
    truth_path: Path | None
    plan: FaultPlan | None
    web: WebFeed | None
    recorder: RecorderProcess | None
    view: LiveView
    pump: _EventPump
    reflex: StopReflex | RetreatReflex | None = None
    ros: object | None = None  # the RosPublisher with --ros


class _EventPump:
    """The bus's events, as they come (each call): into the live view, the outcome and the events file."""

    def __init__(self, sub, view: LiveView, out: MonitorOutcome, writer: EventWriter | None) -> None:
        self._sub, self._view, self._out, self._writer = sub, view, out, writer

    def __call__(self) -> None:
        for ev in self._sub.drain():
            if isinstance(ev, DeviceEvent) and ev.kind == "counters":
                continue  # a reader's counters, each second: the summary's
            self._view.add(ev)
            stream = isinstance(ev, DeviceEvent) and ev.kind in STREAM_EVENT_KINDS
            provisional = isinstance(ev, DeviceEvent) and ev.kind in PROVISIONAL_EVENT_KINDS
            if isinstance(ev, ContactEvent) or stream or provisional:
                (self._out.stream_events if stream else self._out.provisional_events if provisional
                 else self._out.events).append(event_record(ev))
            # the events file: contact events, streams lost and back, short retreats (a provisional onset is
            # the live run's arrival timing, which no replay has: in the recording, the outcome and the counters)
            if (isinstance(ev, ContactEvent) or stream or ev.kind == "retreat_short") and self._writer is not None:
                self._writer.write(ev)


def _run(cfg: MonitorOptions, console: Console, scene: Scene, ft_dev: DeviceSpec | None, arm_dev: DeviceSpec | None,
         corrections: Corrections | None, cal_meta: dict[str, str] | None, out: MonitorOutcome,
         faults: list[Fault]) -> MonitorOutcome:
    with contextlib.ExitStack() as stack:
        _stop_on_sigterm(stack)
        live = _start(cfg, console, scene, ft_dev, arm_dev, corrections, cal_meta, out, faults, stack)
        try:
            _go(cfg, console, scene, live, stack)
            _watch(cfg, console, live, out)
        finally:
            _stop(live, out)
        live.pump()
        _conclude(cfg, console, scene, live, out)
    return out


def _start(cfg: MonitorOptions, console: Console, scene: Scene, ft_dev: DeviceSpec | None, arm_dev: DeviceSpec | None,
           corrections: Corrections | None, cal_meta: dict[str, str] | None, out: MonitorOutcome, faults: list[Fault],
           stack: contextlib.ExitStack) -> _Live:
    """The page, the world, the bus, the monitor, the recorder, the events file and the rig (not opened yet)."""
    web = _serve_page(cfg, console, scene, stack) if cfg.view.web is not None else None
    bus = Bus()
    # first: ROS discovery (up to ~2 s) runs while the world starts, so subscribers match before the first frame
    ros = _start_ros(cfg, console, scene, bus, stack) if cfg.ros_namespace is not None else None
    # the world is built in its process while this one loads the pipeline (each ~1 s with a scene's meshes)
    t_world = time.monotonic()
    world, truth_path = _launch_world(cfg, console, scene, stack) if cfg.sim else (None, cfg.world.truth)
    ft_name, arm_name = ft_dev.name if ft_dev is not None else "ft", arm_dev.name if arm_dev is not None else "arm"
    topics = [wrench_topic(ft_name), joints_topic(arm_name), MONITOR_INPUT]  # no frames on the first: no F/T
    ev_sub = bus.subscribe("events/", maxsize=None)
    monitor, recorder = _start_monitor(cfg, console, scene, bus, ft_name, arm_name, corrections, cal_meta, stack)
    if world is not None:
        _world_up(console, world, t_world)
    try:
        plan = FaultPlan(faults, world, bus) if faults and world is not None else None
    except FaultError as exc:
        raise MonitorSetupError(str(exc)) from None
    events_file = stack.enter_context(open(cfg.events, "w", encoding="utf-8")) if cfg.events else None  # noqa: SIM115 - the stack closes it
    writer = EventWriter(events_file) if events_file is not None else None
    if world is None:
        monitor.start()  # on hardware the arm must be still now: the tare takes the first 0.1 s
    devices = list({d.name: d for d in (ft_dev, arm_dev) if d is not None}.values())  # one may fill both roles
    console.print(f"connecting to {' and '.join(d.name for d in devices) or 'the world'}"
                  + (f" served at {cfg.devices.remote}" if cfg.devices.remote else "") + " ...")
    try:
        rig = _make_rig(cfg, scene, bus, devices, topics[:2] if ft_dev is not None else topics[1:2], world)
    except RigError as exc:
        raise MonitorSetupError(str(exc)) from None
    if arm_dev is None:
        rig.add(SimJointSource(arm_name, bus, world))
    view = LiveView(bus, monitor, topics, ft_topic=topics[0], title=cfg.title)
    if ros is not None:
        ros.counters = lambda: monitor.counters  # the diagnostics' monitor status
    return _Live(bus, topics, monitor, rig, world, truth_path, plan, web, recorder, view,
                 _EventPump(ev_sub, view, out, writer), ros=ros)


def _start_monitor(cfg: MonitorOptions, console: Console, scene: Scene, bus: Bus, ft_name: str, arm_name: str,
                   corrections: Corrections | None, cal_meta: dict[str, str] | None, stack: contextlib.ExitStack
                   ) -> tuple[LiveMonitor, RecorderProcess | None]:
    """The monitor with the calibration's pipeline options (not started), and the recorder of its bus."""
    tare_s = None if corrections is not None else 0.1
    settings = PipelineSettings(corrections=corrections or Corrections()).with_level(cfg.level)
    if cfg.refine and corrections is not None and corrections.model_error is not None:
        settings = settings.replace(motion=dataclasses.replace(settings.motion, refine=True))
    elif cfg.refine:
        console.print("[yellow]--refine: the calibration holds no identification (ftc identify): nothing to "
                      "refine[/]")
    console.print("loading the pipeline (its compiled kernels) ...")
    ros_outputs = cfg.ros_namespace is not None or bool(cfg.record and cfg.record_format != "ftc")
    limits = cell_limits(cfg.limits, console)
    try:
        monitor = LiveMonitor(bus, scene, ft_source=ft_name, arm_source=arm_name, tare_s=tare_s,
                              settings=settings, publish_judged=ros_outputs, limits=limits)
    except LimitsError as exc:
        raise MonitorSetupError(str(exc)) from None
    console.print(f"contact points on the scene's {monitor.pipeline.surface_source}"
                  + (" (its vendor meshes are not fetched: ftc scenes --fetch-meshes)"
                     if scene.robot.vendor_shell and monitor.pipeline.surface_source == "primitives" else ""))
    recorder = None
    if cfg.record:
        recorder = _start_recorder(cfg, scene, bus, {
            "ft_source": ft_name, "arm_source": arm_name, "tare_s": str(tare_s),
            "pipeline": settings.to_json(), "limits": limits.to_json(), "ftc_hw": __version__, "sim": str(cfg.sim),
            "scenario": cfg.world.scenario if cfg.sim else "", "seed": str(cfg.world.seed),
            "started_host_ns": str(time.monotonic_ns())}, cal_meta)
        stack.callback(recorder.stop)  # on a failed start; a no-op after the final stop below
    return monitor, recorder


def _go(cfg: MonitorOptions, console: Console, scene: Scene, live: _Live, stack: contextlib.ExitStack) -> None:
    """The devices opened, the reflex armed, the sensor tared and the world's scenario started, the page fed."""
    rig, monitor, world = live.rig, live.monitor, live.world
    try:
        rig.open().wait()
    except RigError as exc:
        raise MonitorSetupError(str(exc)) from None
    if isinstance(rig, RemoteRig) and rig.readers is not None:
        console.print(f"readers in processes of their own: {rig.readers.describe()}, over Zenoh on "
                      f"{rig.endpoint}")
    elif not cfg.devices.remote:
        console.print(readers_mode(cfg)[1])
    if cfg.reflex == "stop":
        live.reflex = (StopReflex(live.bus, rig.stop_arm, inline=True) if isinstance(rig, RemoteRig) else
                       StopReflex(live.bus, lambda _ev: rig.arm.stop()))
    elif cfg.reflex == "retreat":
        live.reflex = _retreat_reflex(cfg, scene, live)
    if world is not None:
        console.print("waiting for the first frames (the sensor is tared at rest) ...")
        _tare_then_go(cfg, monitor, world)
        if live.plan is not None:
            live.plan.start()
    if live.web is not None:
        live.web.feed(live.bus, monitor, live.topics, ft_topic=live.topics[0],
                      truth_path=live.truth_path if cfg.sim else None)
    stack.enter_context(frozen_heap())  # set up: no collector pause may stall the readers now
    live.view.status = (f"scene {scene.name}, {monitor.pipeline.level} compensation"
                        + (f", scenario {cfg.world.scenario} (emulated devices)" if cfg.sim else ""))


def _retreat_reflex(cfg: MonitorOptions, scene: Scene, live: _Live) -> RetreatReflex:
    """The retreat, armed: its setpoints go to the arm's adapter in this process (a stream, not one command)."""
    rig = live.rig
    arm = None if isinstance(rig, RemoteRig) else rig.arm
    if arm is None or not arm.servo_period_s:
        where = "in this process (--readers thread)" if isinstance(rig, RemoteRig) else "that takes joint setpoints"
        raise MonitorSetupError(f"--reflex retreat streams joint setpoints to an arm adapter {where}")
    try:
        return RetreatReflex(live.bus, arm, ArmModel(scene), cfg.retreat, joints_topic=live.topics[1])
    except DeviceError as exc:
        raise MonitorSetupError(f"--reflex retreat: {exc}") from None


def _stop(live: _Live, out: MonitorOutcome) -> None:
    """The fault plan, the monitor, the devices, the reflex and the page stopped, in that order."""
    out.t_closed_ns = time.monotonic_ns()
    if live.plan is not None:
        live.plan.close()
        out.faults = list(live.plan.done)
        if live.plan.error:
            out.problems.append(f"fault plan stopped: {live.plan.error}")
    live.monitor.stop()  # first: the streams end with the adapters, and that is no loss
    live.rig.close()
    if live.reflex is not None:
        live.reflex.close()
    if live.web is not None:
        live.web.close()
        out.web = live.web.summary
    if live.ros is not None:  # after the devices: every frame they gave is published
        live.ros.stop()
        out.ros = live.ros.summary()
        lost = sum(out.ros["failed"].values()) + out.ros["dropped"]
        if lost:
            out.problems.append(f"ROS: {lost} messages or frames not published ({out.ros['error'] or 'queue full'})")


def _conclude(cfg: MonitorOptions, console: Console, scene: Scene, live: _Live, out: MonitorOutcome) -> None:
    """The outcome's figures and judgements, and the summary printed."""
    monitor, rig = live.monitor, live.rig
    _finish(cfg, scene, live, out)
    refiner = getattr(getattr(monitor.pipeline, "motion", None), "refiner", None)  # the F/T pipeline's only
    if refiner is not None:
        out.drift = refiner.drift()
        console.print(out.drift.summary())
    if isinstance(rig, RemoteRig):
        out.remote = rig.counts
        if rig.readers is not None and rig.readers.restarts:
            out.degraded.append(f"reader processes restarted {rig.readers.restarts}x (crashed or killed)")
    judge_degraded(monitor, rig.adapters, out, cfg.sim)
    out.device_counters = {a.name: dict(a.counters) for a in rig.adapters}
    for sink in live.recorder.summary.get("sinks", []) if live.recorder is not None else []:
        console.print(f"ROS 2 bag: {sum(sink.get('counts', {}).values())} messages -> {sink.get('path', '?')}",
                      highlight=False)
    if out.ros:
        published = out.ros["published"]
        console.print(f"ROS 2: published {sum(published.values())} messages ("
                      + ", ".join(f"{k} {v}" for k, v in sorted(published.items()))
                      + f"); failed {sum(out.ros['failed'].values())}, frames dropped {out.ros['dropped']}"
                      + f", not published {_skips(out.ros['skipped'])}"
                      + (f"; not acknowledged by a subscriber at the stop: {', '.join(out.ros['unacked'])}"
                         if out.ros.get("unacked") else ""), highlight=False)
    print_summary(console, cfg, _served(cfg), live.bus, live.topics, out, rig.adapters, live.recorder)


def _skips(skipped: dict[str, int]) -> str:
    """``"0"`` or ``"3 (external_not_finite 3)"``: the frames the ROS view could not publish, by reason."""
    n = sum(skipped.values())
    return f"{n} (" + ", ".join(f"{k} {v}" for k, v in sorted(skipped.items())) + ")" if n else "0"


def _setpoints_at_interface(retreats: list[dict], applied: list) -> list[float | None]:
    """Per retreat: ms from its onset to when the emulated arm read its first setpoint (the first goal the
    world applied after the onset whose request time the emulator recorded, else its sending time)."""
    out: list[float | None] = []
    for r in retreats:
        onset = r["onset_t_host_ns"]
        rx = [a.t_rx_ns or a.t_sent_ns for a in applied if a.kind == "goal" and (a.t_rx_ns or a.t_sent_ns) > onset]
        out.append((min(rx) - onset) / 1e6 if rx else None)
    return out


def _serve_page(cfg: MonitorOptions, console: Console, scene: Scene, stack: contextlib.ExitStack) -> WebFeed:
    """The page, served before the world starts (it loads meanwhile); its URL printed."""
    web = WebFeed(scene, cfg.title, cfg.view.web)
    try:
        url = web.serve()
    except WebViewError as exc:
        raise MonitorSetupError(f"--view web: {exc}") from None
    stack.callback(web.close)
    console.print(f"the live page: [bold cyan]{url}[/] (open it in a browser)", highlight=False)
    return web


def _make_rig(cfg: MonitorOptions, scene: Scene, bus: Bus, devices: list[DeviceSpec], topics: list[str],
              world: WorldHost | None) -> Rig | RemoteRig:
    """The devices' frames onto ``bus``: from ftc serve at ``cfg.devices.remote``; from reader processes of our
    own (the default: nothing this process computes can make a reader miss a packet); or from adapters here."""
    endpoints = world.endpoints if world is not None else None
    at = cfg.devices
    if at.remote:
        return RemoteRig(bus, at.remote, at.remote_rig or scene.name, topics, cfg.connect_timeout_s, at.zenoh_config)
    if readers_mode(cfg)[0] == "process":
        listen = free_loopback_endpoint()
        readers = ServedReaders(scene, devices, scene.name, [listen], endpoints=endpoints,
                                device_overrides=at.overrides, rig_file=at.rig)
        return RemoteRig(bus, listen, scene.name, topics, cfg.connect_timeout_s, readers=readers)
    return build_rig(scene, bus=bus, devices=devices, endpoints=endpoints, timeout=cfg.connect_timeout_s)


def _watch(cfg: MonitorOptions, console: Console, live: _Live, out: MonitorOutcome) -> None:
    """The live view until the world's run ends, the duration is up, or Ctrl-C."""
    t_end = None if (cfg.sim or not cfg.duration) else time.monotonic() + cfg.duration
    shown = cfg.view.terminal
    screen = Live(console=console, refresh_per_second=4, transient=False, auto_refresh=False) \
        if shown else contextlib.nullcontext()
    world, pump, view = live.world, live.pump, live.view
    try:
        with screen:
            while True:
                pump()
                if shown:
                    screen.update(view.render(), refresh=True)
                if world is not None and world.done:
                    break
                if t_end is not None and time.monotonic() >= t_end:
                    break
                time.sleep(0.25 if shown else 0.05)
            _wait_idle(live.monitor)
            pump()
            if shown:
                screen.update(view.render(), refresh=True)
    except KeyboardInterrupt:
        out.problems.append("interrupted")


def _finish(cfg: MonitorOptions, scene: Scene, live: _Live, out: MonitorOutcome) -> None:
    """Counters, the evaluation against the world's truth, the recording's final metadata, problems."""
    monitor, reflex, world, recorder = live.monitor, live.reflex, live.world, live.recorder
    out.counters = dict(monitor.counters)
    if isinstance(reflex, RetreatReflex):
        out.reflex = {"retreats": reflex.retreats, "not_fought": reflex.not_fought, "ignored": reflex.ignored,
                      "errors": reflex.errors}
        if world is not None:  # when the arm's interface took the first setpoint of each retreat
            out.reflex["at_interface"] = _setpoints_at_interface(reflex.retreats, world.applied())
    elif reflex is not None:
        out.reflex = {"stops": reflex.stops, "errors": reflex.errors, "followed": reflex.followed}
        if world is not None:  # when each stop reached the arm's interface (the emulator read it), host ns
            out.reflex["stops_at_arm_ns"] = [a.t_rx_ns or a.t_sent_ns for a in world.applied() if a.kind == "stop"]
        if _served(cfg):  # the arm's reader process says when it stopped the arm
            out.reflex["stopped_by_reader"] = [dict(e.counters) for e in monitor.bus.history(EVENTS_DEVICE)
                                               if e.kind == "stopped"]
    if world is not None and world.done and "error" not in (world.result or {}):
        ft = scene.sensing.ft is not None  # the bound and the solver's own error are the F/T sensor's
        out.evaluation = evaluate(out.events, read_truth(live.truth_path), world.sample_period_s,
                                  crlb=crlb_of_truth(scene) if ft else None,
                                  solver_rms=solver_rms_of_truth(scene) if ft else None)
    elif world is not None and "interrupted" not in out.problems:  # Ctrl-C: the world was stopped, not failed
        out.problems.append(f"the simulated world did not finish: {world.result}")
    if recorder is not None:
        final = {"events": {"count": str(len(out.events)),
                            "jsonl": "\n".join(json.dumps(e, separators=(",", ":")) for e in out.events)}}
        if out.evaluation is not None:
            final["evaluation"] = {"json": json.dumps(out.evaluation.to_dict())}
        recorder.stop(final)
        for sink in recorder.summary.get("sinks", []):
            if sink.get("errors"):
                out.degraded.append(f"the ROS 2 bag {sink.get('path', '')}: {sink['errors']} errors ({sink['error']})")
        if recorder.drops:
            out.problems.append(f"recorder dropped {recorder.drops} frames")
        if recorder.error is not None:
            out.degraded.append(f"the recording is incomplete: {recorder.error}; {recorder.lost} frames not written")
    if monitor.counters.get("errors"):
        out.problems.append(f"pipeline errors: {monitor.counters['errors']}")
    if out.counters.get("frames", 0) == 0:
        out.problems.append("no F/T frame reached the pipeline")
        out.exit_code = 1
