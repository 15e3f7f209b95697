"""``ftc ros publish``: a scene's devices, read through ftc's adapters (from emulators through the real
client libraries with ``--sim``, or the cell's hardware), published on ROS 2 as the vendors' drivers
publish them (:mod:`.drivers`): a ``sensor_msgs/JointState`` per joint frame, a
``geometry_msgs/WrenchStamped`` per F/T frame, each at its device's own rate, reliable (the drivers'
``SystemDefaultsQoS``). The header stamp is the frame's device time mapped to ROS time (the system
clock): the device clock's steps from the system clock's time of the stream's first frame
(:class:`StampClock`); a frame without device time is stamped with its receipt.

With ``--sim`` the world holds the scenario's start pose until every topic has a subscriber and ``hold_s``
seconds have passed (a monitor subscribing tares its sensor on the still arm), then runs it; the run ends
with the scenario, at ``duration`` without ``--sim``, or on Ctrl-C / SIGTERM. Its first stdout line says
what it publishes, ``{"scene", "topics": [{"topic", "type", "source"}]}``.
"""
from __future__ import annotations

import contextlib
import json
import signal
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ftc_hw.app.setup.rig import Rig, RigError, build_rig
from ftc_hw.bus import Bus, JointFrame, WrenchFrame, joints_topic, wrench_topic
from ftc_hw.devices.base import responsive_readers
from ftc_hw.scene import Scene, SceneError, load_rig_scene
from ftc_hw.sim_devices.host import WorldHost

from .availability import require_ros
from .drivers import Stream, joint_stream, stop_service, wrench_stream

require_ros("ftc ros publish")

from geometry_msgs.msg import WrenchStamped  # noqa: E402 - after the check that names what to install
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from . import context  # noqa: E402
from .stop_service import StopServer  # noqa: E402

# the drivers' reliability (SystemDefaultsQoS); ESTIMATE: a second of a 1 kHz stream kept for a slow subscriber
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)


class PublishError(RuntimeError):
    """The publisher cannot start (the message says why)."""


@dataclass(frozen=True)
class PublishOptions:
    scene: str
    devices: tuple[str, ...] = ()  # --device NAME.KEY=VALUE
    rig: Path | None = None
    sim: bool = False
    scenario: str = "static-pokes"
    reality: str = "typical"
    seed: int = 0
    duration: float = 10.0  # s: the scenario's with --sim, else the run's (0: until stopped)
    hold_s: float = 1.0
    joints_topic: str | None = None
    wrench_topic: str | None = None
    frame_id: str | None = None
    joint_prefix: str | None = None
    stop_service: str | None = None  # a std_srvs/Trigger stopping the arm (None: its driver's, drivers.stop_service)
    truth: Path | None = None


@dataclass
class PublishOutcome:
    published: Counter[str] = field(default_factory=Counter)  # by ROS topic
    device_counters: dict[str, dict[str, int]] = field(default_factory=dict)  # by device: its adapter's
    stopped_by: str = ""
    stop_service: str = ""  # served ("" none)
    stop_calls: int = 0
    stop_failures: int = 0


class StampClock:
    """Device time (ns) to ROS time (ns) for one stream: the device clock's own steps, placed at the system
    clock's time of the first frame's receipt (an alignment that moves would put steps into the stamps that
    the device never made, and a subscriber judging gaps by them would count messages lost); receipt time
    for frames without device time. Never earlier than the stamp before."""

    def __init__(self, wall_minus_mono_ns: int) -> None:
        self.offset = wall_minus_mono_ns
        self.origin: tuple[int, int] | None = None  # (device ns, ROS ns) of the first frame with device time
        self.last = 0

    def stamp(self, frame: JointFrame | WrenchFrame) -> int:
        if frame.t_device_ns is None:
            ros = frame.t_host_ns + self.offset
        else:
            if self.origin is None or frame.t_device_ns < self.origin[0]:  # first, or the device clock reset
                self.origin = (frame.t_device_ns, max(frame.t_host_ns + self.offset, self.last + 1))
            ros = self.origin[1] + frame.t_device_ns - self.origin[0]
        self.last = max(ros, self.last + 1)
        return self.last


def _header(msg: Any, stamp_ns: int, frame_id: str = "") -> Any:
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.header.frame_id = frame_id
    return msg


def joint_state_msg(frame: JointFrame, stream: Stream, stamp_ns: int) -> JointState:
    """A joint frame as its driver's JointState: effort the currents (A) or the joint torques (N m)."""
    effort = frame.tau if stream.effort == "torque" else frame.current
    return _header(JointState(name=list(stream.names), position=frame.q.tolist(), velocity=frame.qd.tolist(),
                              effort=[] if effort is None else effort.tolist()), stamp_ns)


def wrench_msg(frame: WrenchFrame, stream: Stream, stamp_ns: int) -> WrenchStamped:
    msg = _header(WrenchStamped(), stamp_ns, stream.frame_id)
    w = np.asarray(frame.wrench, dtype=float)
    f, t = msg.wrench.force, msg.wrench.torque
    f.x, f.y, f.z, t.x, t.y, t.z = (float(v) for v in w)
    return msg


def streams_of(scene: Scene, rig: Rig, opts: PublishOptions) -> list[Stream]:
    """The rig's arm and F/T sensor as their drivers' streams."""
    out = []
    specs = {d.name: d for d in scene.devices}
    if rig.arm is not None and rig.arm.name in specs:
        out.append(joint_stream(scene, specs[rig.arm.name], topic=opts.joints_topic, prefix=opts.joint_prefix))
    if rig.ft is not None:
        out.append(wrench_stream(scene, specs[rig.ft.name], topic=opts.wrench_topic, frame_id=opts.frame_id))
    return out


def run_publish(opts: PublishOptions, say: Callable[[str], None] = print) -> PublishOutcome:
    """Publish until the scenario ends (``--sim``), ``duration`` s pass, or Ctrl-C / SIGTERM."""
    try:
        scene = load_rig_scene(opts.scene, opts.devices, opts.rig)
    except SceneError as exc:
        raise PublishError(str(exc)) from None
    out = PublishOutcome()
    # the readers poll (ur_rtde keeps only its newest packet): as in the monitor, ahead of ordinary processes
    with contextlib.ExitStack() as stack, responsive_readers():
        _stop_on_sigterm(stack)
        world = _world(opts, scene, stack) if opts.sim else None
        try:
            roles = ("ft", "arm") if scene.sensing.ft is not None else ("arm",)
            rig = build_rig(scene, endpoints=world.endpoints if world is not None else None, roles=roles)
            stack.callback(rig.close)
            rig.open().wait()
        except RigError as exc:
            raise PublishError(str(exc)) from None
        streams = streams_of(scene, rig, opts)
        forwards: list[_Forward] = []
        specs = {d.name: d for d in scene.devices}
        arm = rig.arm if rig.arm is not None and rig.arm.name in specs else None
        out.stop_service = stop_service(specs[arm.name], opts.stop_service) if arm is not None else ""
        try:
            _publish(opts, scene, rig.bus, streams, world, forwards, say, out, arm)
        except KeyboardInterrupt:
            out.stopped_by = "interrupted"
    # the adapters' readers, which publish, are stopped now: the counts are final
    out.published.update({f.stream.topic: f.count for f in forwards})
    out.device_counters = {a.name: dict(a.counters) for a in rig.adapters}
    return out


def _world(opts: PublishOptions, scene: Scene, stack: contextlib.ExitStack) -> WorldHost:
    try:
        world = WorldHost(scene, opts.scenario, duration=opts.duration, seed=opts.seed, preroll=True,
                          truth=opts.truth, reality=opts.reality)
        world.start()
    except Exception as exc:  # noqa: BLE001 - the world's and emulators' start failures carry their reason
        raise PublishError(str(exc)) from None
    stack.callback(world.close)
    return world


def _stop_on_sigterm(stack: contextlib.ExitStack) -> None:
    """SIGTERM stops like Ctrl-C: adapters, world and node are closed, never orphaned."""
    with contextlib.suppress(ValueError):  # not the main thread
        previous = signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt()))
        stack.callback(signal.signal, signal.SIGTERM, previous)


class _Forward:
    """One stream's frames from the bus to its ROS publisher, in the adapter's reader thread (no queue: the
    message leaves as the frame arrives)."""

    def __init__(self, stream: Stream, publisher: Any, clock: StampClock) -> None:
        self.stream, self.publisher, self.clock = stream, publisher, clock
        self.count = 0

    def __call__(self, frame: Any) -> None:
        stamp = self.clock.stamp(frame)
        msg = joint_state_msg(frame, self.stream, stamp) if self.stream.kind == "joints" else \
            wrench_msg(frame, self.stream, stamp)
        self.publisher.publish(msg)
        self.count += 1


def _publish(opts: PublishOptions, scene: Scene, bus: Bus, streams: list[Stream], world: WorldHost | None,
             forwards: list[_Forward], say: Callable[[str], None], out: PublishOutcome, arm: Any) -> None:
    """Each stream forwarded (``forwards`` filled), and the arm's stop served where ``out.stop_service`` names
    a service, until done."""
    node = context.acquire("ftc_ros_publish")
    subs: list[Any] = []
    server = StopServer(node, out.stop_service, arm.stop) if out.stop_service else None
    try:
        offset = time.time_ns() - time.monotonic_ns()
        forwards += [_Forward(s, node.create_publisher(JointState if s.kind == "joints" else WrenchStamped,
                                                      s.topic, QOS), StampClock(offset)) for s in streams]
        for f in forwards:
            topic = (joints_topic if f.stream.kind == "joints" else wrench_topic)(f.stream.source)
            subs.append(bus.subscribe(topic, f))
        say(json.dumps({"scene": scene.name, "topics": [
            {"topic": s.topic, "type": "sensor_msgs/msg/JointState" if s.kind == "joints"
             else "geometry_msgs/msg/WrenchStamped", "source": s.source} for s in streams],
            "services": [{"service": out.stop_service, "type": "std_srvs/srv/Trigger"}] if server else []}))
        _until_done(opts, world, [f.publisher for f in forwards])
    finally:
        for sub in subs:
            sub.close()
        if server is not None:
            out.stop_calls, out.stop_failures = server.calls, server.failures
            server.close()
        context.release()


def _until_done(opts: PublishOptions, world: WorldHost | None, publishers: list[Any]) -> None:
    """With a world: its start pose held until every publisher has a subscriber and ``hold_s`` passed, then
    its scenario to the end; without: ``duration`` s (0: until stopped)."""
    if world is None:
        t_end = time.monotonic() + opts.duration if opts.duration else None
        while t_end is None or time.monotonic() < t_end:
            time.sleep(0.05)
        return
    while not all(p.get_subscription_count() > 0 for p in publishers):
        time.sleep(0.02)
    time.sleep(opts.hold_s)
    world.go()
    while not world.wait_done(0.2):
        pass
