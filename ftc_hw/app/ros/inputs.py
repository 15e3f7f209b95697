"""Devices read from ROS 2 topics: the kinds ``ros-joint-state`` (an arm's ``sensor_msgs/JointState``) and
``ros-wrench`` (an F/T sensor's ``geometry_msgs/WrenchStamped``), registered into the adapter registry
when this module is imported (:data:`ftc_hw.devices.registry.PLUGINS`: on the first adapter of one).

They are adapters like every other (``ftc_hw.devices.base``): a reader thread that publishes frames on
the bus, ``connect`` when a publisher of the topic is matched (``reconnecting`` while none is, as a
device that does not answer), ``disconnect`` when it goes away, ``stale`` / ``recovered`` on silence (the
F/T kind through its watchdog, the arm kind judged by its reader), and the monitor's ``sensor_lost`` /
``arm_lost`` when a topic stops, as for a silent device. The subscription's callback (in the process's
one executor thread, :mod:`.context`) only takes the host's ``monotonic_ns`` at receipt and queues the
message; the reader decodes (:mod:`.decode`) and publishes.

Frames: ``t_host_ns`` = receipt, ``t_device_ns`` = the header stamp (ROS time, ns), ``seq`` = the message
count with the messages missing between stamps added where ``rate_hz`` is given (:mod:`.stamps`:
``SEQ_GAP``, ``lost``); a repeated stamp is a duplicate (not published), an earlier one a clock reset
(``CLOCK_SUSPECT``, ``stamp_backwards``). A message that cannot be the scene's frame is not published, is
counted and said once in an ``error`` event: joint names that do not hold the scene's joints
(``joint_names``), arrays of the wrong length (``bad_messages``), NaN or Inf (``bad_values``:
ros2_control sends NaN for an interface the hardware lacks), a wrench in another frame
(``wrong_frame``). A JointState's ``effort`` is the joints' current (A; ``tau`` = torque constant x
current where the constants are known) or their measured torque (N m, ``current`` zeros), per the
device's ``effort`` param; a wrench at the sensor's range is flagged ``SATURATED``.
"""
from __future__ import annotations

import queue
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from ftc_hw.bus import Bus, JointFlag, JointFrame, joints_topic
from ftc_hw.devices.arm_base import ArmAdapter
from ftc_hw.devices.base import Adapter, DeviceError, DeviceIOError
from ftc_hw.devices.ft_base import FTAdapter
from ftc_hw.devices.registry import AdapterKind, register_kind
from ftc_hw.scene import DeviceSpec, Scene

from .availability import require_ros
from .decode import (
    FrameIdError,
    JointNamesError,
    RosInputError,
    check_frame,
    extra_joints,
    joint_arrays,
    joint_index,
    non_finite,
    stamp_ns,
    wrench_array,
)
from .stamps import StampSequence

require_ros("a ROS device (ros-joint-state, ros-wrench)")

from geometry_msgs.msg import WrenchStamped  # noqa: E402 - after the check that names what to install
from rclpy.event_handler import SubscriptionEventCallbacks  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from . import context  # noqa: E402
from .stop_service import UR_DASHBOARD_STOP, StopClient  # noqa: E402

RELIABILITY = {"reliable": ReliabilityPolicy.RELIABLE, "best_effort": ReliabilityPolicy.BEST_EFFORT}
SAID_MAX = 32  # distinct problems said in events, per adapter (each is counted whatever)


class _Subscribed:
    """What both ROS kinds share: the subscription, the queue of received messages, the publishers matched,
    problems said once."""

    msg_type: Any = None

    def _ros_setup(self, topic: str, reliability: str, depth: int, rate_hz: float | None) -> None:
        self.ros_topic = topic
        self.qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(depth), reliability=RELIABILITY[reliability])
        self.reliability = reliability
        self.rate_hz = rate_hz
        self.stamps = StampSequence(None if rate_hz is None else round(1e9 / rate_hz))
        self._queue: queue.SimpleQueue[tuple[int, Any]] = queue.SimpleQueue()
        self._sub: Any = None
        self._node: Any = None
        self._matched = 0
        self._said: set[str] = set()

    # -- the subscription (kept across reconnects: discovery keeps running) --------------------------
    def _subscribe(self) -> None:
        if self._sub is not None:
            return
        self._node = context.acquire()
        events = SubscriptionEventCallbacks(incompatible_qos=self._incompatible, matched=self._on_matched,
                                            message_lost=self._on_lost)
        self._sub = self._node.create_subscription(self.msg_type, self.ros_topic, self._on_message, self.qos,
                                                   event_callbacks=events)

    def _unsubscribe(self) -> None:
        sub, self._sub = self._sub, None
        if sub is not None:
            self._node.destroy_subscription(sub)
            context.release()

    def _on_message(self, msg: Any) -> None:
        self._queue.put((time.monotonic_ns(), msg))

    def _on_matched(self, info: Any) -> None:
        self._matched = int(info.current_count)

    def _on_lost(self, info: Any) -> None:
        self.counters["dds_lost"] += int(info.total_count_change)

    def _incompatible(self, info: Any) -> None:
        self.counters["incompatible_qos"] += 1
        self._say(f"a publisher of {self.ros_topic} has an incompatible QoS (policy {info.last_policy_kind}): "
                  f"this subscription is {self.reliability}; a best_effort publisher needs reliability = "
                  "\"best_effort\"")

    def _wait_for_publisher(self) -> None:
        self._subscribe()
        if self._sub.get_publisher_count() == 0:
            raise DeviceIOError(f"no publisher of {self.msg_type.__name__} on {self.ros_topic} (discovery takes up "
                                "to ~2 s; is the driver running, on this ROS_DOMAIN_ID?)")

    def _drain(self, timeout: float) -> list[tuple[int, Any]]:
        """The messages received (waiting up to ``timeout`` s for the first); DeviceIOError when the topic's
        publishers are gone."""
        try:
            got = [self._queue.get(timeout=timeout)]
        except queue.Empty:
            got = []
        while True:
            try:
                got.append(self._queue.get_nowait())
            except queue.Empty:
                break
        if not got and self._sub is not None and self._sub.get_publisher_count() == 0:
            raise DeviceIOError(f"the publisher of {self.ros_topic} is gone")
        return got

    def _say(self, why: str) -> None:
        if why not in self._said and len(self._said) < SAID_MAX:
            self._said.add(why)
            self.event("error", why)

    def _reject(self, counter: str, exc: Exception | str) -> None:
        self.counters[counter] += 1
        self._say(f"{self.ros_topic}: {exc} (such messages are not used: {counter} counts them)")


class RosJointStateArm(_Subscribed, ArmAdapter):
    """An arm's joint state from a ``sensor_msgs/JointState`` topic, in the scene's joint order.
    ``names``: the message's name of each scene joint; ``effort``: current, torque or none."""

    kind = "ros-joint-state"
    msg_type = JointState

    def __init__(self, name: str, bus: Bus, topic: str, *, names: Sequence[str], effort: str,
                 torque_constant: Sequence[float] | None = None, reliability: str = "reliable", depth: int = 1000,
                 rate_hz: float | None = None, stale_after: float | None = None, stop_service: str | None = None,
                 reconnect_backoff: tuple[float, float] = (0.05, 0.5)) -> None:
        ArmAdapter.__init__(self, name, bus, reconnect_backoff=reconnect_backoff)
        self.stop_service = stop_service or None
        self._stopper: StopClient | None = None
        self._ros_setup(topic, reliability, depth, rate_hz)
        self.topic = joints_topic(name)
        self.names = tuple(names)
        self.effort = effort
        self.torque_constant = None if torque_constant is None else np.asarray(torque_constant, dtype=float)
        if self.torque_constant is not None and self.torque_constant.shape != (len(self.names),):
            raise DeviceError(f"device {name!r}: torque_constant has {self.torque_constant.size} values for "
                              f"{len(self.names)} joints")
        self.stale_after = stale_after if stale_after is not None else (
            0.1 if rate_hz is None else max(0.05, 10.0 / rate_hz))
        self._zeros = np.zeros(len(self.names))
        self._index: dict[tuple[str, ...], np.ndarray | JointNamesError] = {}
        self._last_new = time.monotonic()

    def describe(self) -> str:
        return f"{self.kind} {self.ros_topic} ({self.reliability}, effort {self.effort})"

    def _connect(self) -> None:
        self._wait_for_publisher()
        self._last_new = time.monotonic()
        if self.stop_service is not None and self._stopper is None:  # discovered before the first stop needs it
            self._stopper = StopClient(context.acquire(), self.stop_service)

    def _disconnect(self) -> None:
        pass  # the subscription stays: its discovery finds the publisher again

    def close(self) -> None:
        super().close()
        self._unsubscribe()
        stopper, self._stopper = self._stopper, None
        if stopper is not None:
            stopper.close()
            context.release()

    def _read_once(self) -> None:
        self._stale_on_failure(self._read)

    def _read(self) -> None:
        for t_host, msg in self._drain(self.poll_timeout):
            self.handle(msg, t_host)
        silent = time.monotonic() - self._last_new
        if silent > self.stale_after:
            self._mark_stale(f"no message on {self.ros_topic} for {silent:.3f} s")

    def index(self, names: Sequence[str]) -> np.ndarray:
        """Where the scene's joints are in a message naming ``names`` (cached per set of names)."""
        key = tuple(names)
        found = self._index.get(key)
        if found is None:
            try:
                found = joint_index(key, self.names)
            except JointNamesError as exc:
                found = exc
            else:
                extra = extra_joints(key, self.names)
                if extra:
                    self._say(f"{self.ros_topic}: joints {', '.join(extra)} are not the scene's: left out")
            self._index[key] = found
        if isinstance(found, JointNamesError):
            raise found
        return found

    def handle(self, msg: Any, t_host_ns: int) -> JointFrame | None:
        """One received message to the bus; the frame published, or None (not used: counted, said)."""
        try:
            q, qd, eff = joint_arrays(msg, self.index(msg.name), effort=self.effort)
        except JointNamesError as exc:
            return self._reject("joint_names", exc)
        except RosInputError as exc:
            return self._reject("bad_messages", exc)
        bad = non_finite(position=q, velocity=qd, effort=eff)
        if bad:
            return self._reject("bad_values", f"NaN or Inf in {', '.join(bad)}")
        stamp = stamp_ns(msg.header)
        step = self.stamps.update(stamp)
        if step.duplicate:
            self.counters["duplicates"] += 1
            return None
        flags = JointFlag.NONE
        if step.lost:
            flags |= JointFlag.SEQ_GAP
            self.counters["missed_packets"] += step.lost
        if step.backwards:
            flags |= JointFlag.CLOCK_SUSPECT
            self.counters["stamp_backwards"] += 1
        current, tau = self._current_tau(eff)
        frame = JointFrame.make(t_host_ns, q, qd, current, tau, source=self.name, seq=step.seq, t_device_ns=stamp,
                                flags=flags)
        self._last_new = time.monotonic()
        self.counters["frames"] += 1
        self.bus.publish(self.topic, frame)
        self._mark_fresh(f"messages on {self.ros_topic} again")
        return frame

    def _current_tau(self, eff: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        if self.effort == "torque":
            return self._zeros, eff
        if self.effort == "current" and eff is not None:
            return eff, None if self.torque_constant is None else self.torque_constant * eff
        return self._zeros, None

    def stop(self) -> None:
        """The driver's stop service called (``stop_service``, e.g. ur_robot_driver's ``/dashboard_client/stop``)
        and its answer awaited; :class:`DeviceError` without one."""
        if self.stop_service is None:
            raise DeviceError(f"{self.name}: an arm read from a ROS topic ({self.ros_topic}) is stopped through its "
                              f"driver's stop service: set params.stop_service (ur_robot_driver: {UR_DASHBOARD_STOP})")
        if self._stopper is None:
            self._stopper = StopClient(context.acquire(), self.stop_service)
        try:
            self._stopper.call()
        except DeviceError:
            self.counters["stop_failures"] += 1
            raise
        self.counters["stops"] += 1


class RosWrenchFT(_Subscribed, FTAdapter):
    """An F/T sensor's wrench from a ``geometry_msgs/WrenchStamped`` topic in ``frame_id`` (the scene's
    sensor frame)."""

    kind = "ros-wrench"
    msg_type = WrenchStamped

    def __init__(self, name: str, bus: Bus, topic: str, *, frame_id: str, reliability: str = "reliable",
                 depth: int = 1000, rate_hz: float | None = None, **kw: Any) -> None:
        FTAdapter.__init__(self, name, bus, **kw)
        self._ros_setup(topic, reliability, depth, rate_hz)
        self.frame_id = frame_id

    def describe(self) -> str:
        return f"{self.kind} {self.ros_topic} in {self.frame_id!r} ({self.reliability})"

    def _connect(self) -> None:
        self._wait_for_publisher()

    def _disconnect(self) -> None:
        pass

    def close(self) -> None:
        super().close()
        self._unsubscribe()

    def _read_once(self) -> None:
        for t_host, msg in self._drain(self.poll_timeout):
            self.handle(msg, t_host)

    def handle(self, msg: Any, t_host_ns: int) -> Any:
        """One received message to the bus; the frame published, or None (not used: counted, said)."""
        try:
            check_frame(msg, self.frame_id)
        except FrameIdError as exc:
            return self._reject("wrong_frame", exc)
        wrench = wrench_array(msg)
        if non_finite(wrench=wrench):
            return self._reject("bad_values", "NaN or Inf in the wrench")
        stamp = stamp_ns(msg.header)
        step = self.stamps.update(stamp)
        if step.duplicate:
            self.counters["duplicates"] += 1
            return None
        if step.backwards:
            self.counters["stamp_backwards"] += 1
        return self.publish_sample(wrench, t_host_ns=t_host_ns, seq=step.seq, t_device_ns=stamp)


# -- the registry's entries ---------------------------------------------------------------------------
def default_effort(scene: Scene | None) -> str:
    """What a JointState's effort is by default: torque where the scene has joint torque sensors, current
    where it has torque constants, else none."""
    if scene is None:
        return "none"
    if scene.joint_torque is not None:
        return "torque"
    return "current" if scene.has_currents else "none"


def _ros_common(device: DeviceSpec) -> dict[str, Any]:
    p = device.params
    return {"reliability": str(p.get("reliability", "reliable")), "depth": int(p.get("depth", 1000)),
            "rate_hz": None if "rate_hz" not in p else float(p["rate_hz"])}


def joint_state_arm(device: DeviceSpec, bus: Bus, endpoint: Any, scene: Scene | None,
                    overrides: dict[str, Any]) -> Adapter:
    p = device.params
    if "joints" in p:
        names = list(p["joints"])
        if scene is not None and len(names) != scene.n_joints:
            raise DeviceError(f"device {device.name!r}: joints names {len(names)} joints, the scene has "
                              f"{scene.n_joints} ({', '.join(scene.robot.joints)})")
    elif scene is not None:
        names = [str(p.get("joint_prefix", "")) + j for j in scene.robot.joints]
    else:
        raise DeviceError(f"device {device.name!r}: without a scene, params.joints must name the joints")
    effort = str(p.get("effort", default_effort(scene)))
    kt = p.get("torque_constant")
    if kt is None and effort == "current" and scene is not None and scene.has_currents:
        kt = list(scene.robot.torque_constant)
    kw: dict[str, Any] = {"names": names, "effort": effort, "torque_constant": kt, **_ros_common(device)}
    if "stale_after" in p:
        kw["stale_after"] = float(p["stale_after"])
    if p.get("stop_service"):
        kw["stop_service"] = str(p["stop_service"])
    return RosJointStateArm(device.name, bus, str(p["topic"]), **{**kw, **overrides})


def wrench_ft(device: DeviceSpec, bus: Bus, endpoint: Any, scene: Scene | None, overrides: dict[str, Any]) -> Adapter:
    p = device.params
    sensor = scene.sensor if scene is not None else None
    frame_id = p.get("frame_id") or (sensor.site if sensor is not None else None)
    if not frame_id:
        raise DeviceError(f"device {device.name!r}: params.frame_id (the driver's frame) is needed without a "
                          "scene sensor")
    kw: dict[str, Any] = {"frame_id": str(frame_id), **_ros_common(device)}
    if "stale_after_s" in p:
        kw["stale_after"] = float(p["stale_after_s"])
    if "range" in p:
        kw["range"] = tuple(float(x) for x in p["range"])
    elif sensor is not None:
        kw["range"] = tuple(float(x) for x in sensor.range)
    return RosWrenchFT(device.name, bus, str(p["topic"]), **{**kw, **overrides})


register_kind("ros-joint-state", AdapterKind("arm", joint_state_arm))
register_kind("ros-wrench", AdapterKind("ft", wrench_ft))
