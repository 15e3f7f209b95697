"""The bus's frames as ROS 2 messages: :class:`RosView` (``feed(frame) -> [RosMessage]``), the one
translation behind ``ftc monitor --ros`` (live) and ``--record-format ros2`` (a bag).

- ``monitor/judged``: the external wrench, the load the environment applies to the arm (all contacts
  together), as ``WrenchStamped`` in the base frame about its origin, one per judged frame;
- ``events/contact``: the event whole as JSON (``std_msgs/String``, the events file's record with its ROS
  stamp and frame), its point as ``PoseStamped``, its force in the contact frame (``WrenchStamped``), its
  markers; in a bag also ``/tf`` with the contact frame and the links at the event's time;
- ``events/device``: the monitor's stream events (``sensor_lost``, ...) as JSON on the same topic, and the
  streams' state in the diagnostics;
- bag only: the raw inputs as the drivers publish them, by the drivers' defaults that ``ftc replay`` and
  ``ftc identify`` read bags with (:func:`.topic_map.default_map`: topic, joint names, what ``effort``
  holds, the wrench's topic and frame id), and ``/tf`` of the links (the Foxglove view's transforms, 50 Hz).

Stamps are ROS time: the frames' host monotonic ns plus ``clock_offset_ns`` (the system clock's offset from
the monotonic one, taken once), so a bag and live topics carry dates as every ROS node's do.
"""
from __future__ import annotations

import json
import time
from collections import Counter, deque
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ftc_hw.bus import (
    CONTACT_CLASSES,
    CONTACT_KINDS,
    INTENTS,
    STREAM_EVENT_KINDS,
    ContactEvent,
    DeviceEvent,
    JointFrame,
    WrenchFrame,
)
from ftc_hw.monitor import JudgedFrame, PipelineInput
from ftc_hw.record.events import event_record
from ftc_hw.record.foxglove_messages import FRAME_TRANSFORMS
from ftc_hw.record.foxglove_view import ROOT_FRAME, FoxgloveView
from ftc_hw.record.schemas import LIMITS_JSON_SCHEMA
from ftc_hw.scene import Scene

from . import encode as enc
from . import layout as L
from .health import StreamHealth, counters_status
from .markers import MarkerScale, contact_markers
from .topic_map import default_map

EVENT_SCHEMA = "ftc_hw/ros/event/1"  # the events topic's JSON: docs/ros.md, "The event JSON"
_NUM, _INT, _STR = {"type": "number"}, {"type": "integer"}, {"type": "string"}
_VEC3 = {"type": "array", "items": _NUM, "minItems": 3, "maxItems": 3}
_COMMON = {"schema": {"const": EVENT_SCHEMA}, "stamp_ns": _INT, "frame_id": _STR, "t": _NUM, "t_host_ns": _INT}
# the events topic's messages, as a JSON Schema (the tests check every message against it)
EVENT_JSON_SCHEMA = {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": EVENT_SCHEMA, "oneOf": [
    {"type": "object", "additionalProperties": False, "required": [*_COMMON, "kind", "contact_id", "link", "point",
     "force", "point_std", "flags", "probability", "duration_s", "peak_force", "impulse"], "properties": {
        **_COMMON, "kind": {"enum": sorted(CONTACT_KINDS)}, "limits": LIMITS_JSON_SCHEMA, "contact_id": _INT,
        "link": _STR, "point": _VEC3,
        "force": _VEC3, "point_std": _VEC3, "flags": {"type": "array", "items": _STR}, "probability": _NUM,
        "duration_s": _NUM, "peak_force": _NUM, "impulse": _NUM, "contact_class": {"enum": sorted(CONTACT_CLASSES)},
        "p_quasi_static": _NUM, "intent": {"enum": sorted(INTENTS)}, "p_guidance": _NUM,
        "class_features": {"type": "object", "additionalProperties": _NUM}}},
    {"type": "object", "additionalProperties": False, "required": [*_COMMON, "kind", "source", "message"],
     "properties": {**_COMMON, "kind": {"enum": sorted(STREAM_EVENT_KINDS)}, "source": _STR, "message": _STR}}]}


@dataclass(frozen=True, slots=True)
class RosMessage:
    topic: L.Topic
    t_ns: int  # ROS time, ns (the bag's log time)
    data: bytes  # CDR


def clock_offset_ns() -> int:
    """The system clock less the monotonic one, now (ns): host monotonic times to ROS time."""
    return time.time_ns() - time.monotonic_ns()


def _matrix(tf: dict) -> np.ndarray:
    """A Foxglove transform's pose (translation, quaternion x y z w) as a 4x4 matrix."""
    x, y, z, w = (tf["rotation"][k] for k in ("x", "y", "z", "w"))
    out = np.eye(4)
    out[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                   [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                   [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    out[:3, 3] = [tf["translation"][k] for k in ("x", "y", "z")]
    return out


class RosView:
    """``feed(frame)`` -> the ROS messages it makes; ``diagnostics(now_ns, counters, published)`` -> one
    ``DiagnosticArray``. ``bag``: the bag's messages too (raw inputs, ``/tf``). One per thread (it owns an
    ArmModel)."""

    def __init__(self, scene: Scene, *, namespace: str = L.DEFAULT_NAMESPACE, bag: bool = False,
                 clock_offset: int | None = None) -> None:
        self.scene, self.namespace, self.bag = scene, namespace, bag
        self.offset = clock_offset_ns() if clock_offset is None else clock_offset
        self.fox = fox = FoxgloveView(scene)
        self.arm = fox.arm
        self.base_frame, self.sensor_frame = ROOT_FRAME, fox.sensor_frame
        self.scale = MarkerScale(fox.marker_m, fox.contact_m_per_n, fox.reach)
        self.sign = 1.0 if scene.sensor is None else -scene.sensor.reading_sign  # external -> applied to the arm
        fixed = self.arm.sensor_body is None or int(self.arm.model.body_weldid[self.arm.sensor_body]) == 0
        self._fixed_T = self.arm.base_T_sensor(np.asarray(scene.robot.home, dtype=float)) if fixed else None
        self._surfaces = {s.link: [x for x in self.arm.surfaces if x.link == s.link] for s in self.arm.surfaces}
        self._q: deque[tuple[int, np.ndarray]] = deque(maxlen=64)  # the newest inputs' joint states
        self.skipped: Counter[str] = Counter()
        self.health: dict[str, StreamHealth] = {}
        self.prefix = namespace.strip("/") or "ftc"
        self._link_T: tuple[int, np.ndarray] | None = None  # (contact id, base_T_link) of its newest estimate
        drivers = default_map(scene)  # the raw inputs as the scene's drivers would publish them
        js = drivers.joint_states
        self.joint_topic = replace(L.JOINT_STATES, name=js.topic)
        self.joint_names, self.effort = tuple(js.bag_names(scene.robot.joints)), js.effort
        # no driver publishes a flange sensor's raw reading by default (UR's wrench topic is its TCP estimate)
        w = drivers.wrench
        self.wrench_topic = L.RAW_WRENCH if w is None else replace(L.FT_WRENCH, name=w.topic)
        self.wrench_frame = self.sensor_frame if w is None else w.frame_id

    def ros_time(self, t_host_ns: int) -> int:
        return int(t_host_ns) + self.offset

    def feed(self, frame: Any) -> list[RosMessage]:
        if isinstance(frame, JudgedFrame):  # the most frequent first
            self._stream("judged", "ftc", frame)
            return self._external(frame)
        if isinstance(frame, PipelineInput):
            self._q.append((frame.t_host_ns, frame.q))
            fox = self.fox.feed(frame)  # the links' poses, kept for the events' (and /tf in a bag, 50 Hz)
            return self._tf(fox) if self.bag else []
        if isinstance(frame, WrenchFrame):
            self._stream("sensor", frame.source, frame)
            return [self._raw_wrench(frame)] if self.bag else []
        if isinstance(frame, JointFrame):
            self._stream("arm", frame.source, frame)
            out = [self._joint_state(frame)] if self.bag else []
            return out + (self._tf(self.fox.feed(frame)) if self.bag else [])
        if isinstance(frame, ContactEvent):
            return self._contact(frame)
        if isinstance(frame, DeviceEvent) and frame.kind in STREAM_EVENT_KINDS:
            return self._stream_event(frame)
        return []

    # -- streams ---------------------------------------------------------------------------------------------
    def _stream(self, role: str, source: str, frame: Any) -> None:
        h = self.health.get(role)
        if h is None:
            name = {"judged": "judged frames", "sensor": f"F/T {source}", "arm": f"joints {source}"}[role]
            h = self.health[role] = StreamHealth(name, source)
        h.update(frame.t_host_ns, getattr(frame, "seq", None))

    def _stream_event(self, ev: DeviceEvent) -> list[RosMessage]:
        stream = ev.kind.split("_")[0]  # sensor or arm
        h = self.health.get(stream) or self.health.setdefault(
            stream, StreamHealth(f"{'F/T' if stream == 'sensor' else 'joints'} {ev.source}", ev.source))
        h.lost, h.last_event = ev.kind.endswith("_lost"), f"{ev.kind}: {ev.message}"
        return [self._event_json(ev)]

    def diagnostics(self, now_host_ns: int, counters: dict[str, Any] | None = None,
                    published: dict[str, int] | None = None) -> RosMessage:
        """Every stream's health at host time ``now_host_ns``; the monitor's counters where given."""
        statuses = [h.status(now_host_ns, self.prefix) for h in self.health.values()]
        if counters is not None:
            statuses.append(counters_status(self.prefix, counters, published or {}))
        t = self.ros_time(now_host_ns)
        return RosMessage(L.DIAGNOSTICS, t, enc.diagnostic_array(t, statuses))

    # -- the external wrench ---------------------------------------------------------------------------------
    def _q_at(self, t_host_ns: int) -> np.ndarray | None:
        """The joint state the pipeline judged at ``t_host_ns`` (or the newest before it)."""
        for t, q in reversed(self._q):
            if t <= t_host_ns:
                return q
        return None

    def external_base(self, frame: JudgedFrame) -> np.ndarray | None:
        """The external wrench as the load applied to the arm, base frame, about the base origin (6,)."""
        b_T_s = self._fixed_T
        if b_T_s is None:
            q = self._q_at(frame.t_host_ns)
            if q is None:
                return None
            b_T_s = self.arm.base_T_sensor(q)
        rot, r = b_T_s[:3, :3], b_T_s[:3, 3]
        w = (self.sign * rot) @ np.reshape(frame.external, (2, 3)).T  # force, torque as columns: base axes
        f, t = w[:, 0], w[:, 1]
        # about the base origin: t + r x f (written out: np.cross costs 50 us a call)
        return np.array([f[0], f[1], f[2], t[0] + r[1] * f[2] - r[2] * f[1], t[1] + r[2] * f[0] - r[0] * f[2],
                         t[2] + r[0] * f[1] - r[1] * f[0]])

    def _external(self, frame: JudgedFrame) -> list[RosMessage]:
        w = self.external_base(frame)
        if w is None or not np.isfinite(w).all():
            self.skipped["external_no_pose" if w is None else "external_not_finite"] += 1
            return []
        t = self.ros_time(frame.t_host_ns)
        return [RosMessage(L.EXTERNAL_WRENCH, t, enc.wrench_stamped(t, self.base_frame, w))]

    # -- contact events --------------------------------------------------------------------------------------
    def _event_json(self, ev: ContactEvent | DeviceEvent) -> RosMessage:
        t = self.ros_time(ev.t_host_ns)
        record = {"schema": EVENT_SCHEMA, "stamp_ns": t, "frame_id": self.base_frame, **event_record(ev)}
        return RosMessage(L.EVENTS, t, enc.string(json.dumps(record, separators=(",", ":"))))

    def _contact(self, ev: ContactEvent) -> list[RosMessage]:
        out = [self._event_json(ev)]
        fox = self.fox.feed(ev)  # the links' poses at the event's time (none for an offset it has placed)
        if "no_estimate" in ev.flags:
            self.skipped["contact_no_estimate"] += 1
            return out
        t = self.ros_time(ev.t_host_ns)
        p = np.asarray(ev.point, dtype=float)
        contact_tf = enc.transform_stamped(t, self.base_frame, L.CONTACT_FRAME, p, (0.0, 0.0, 0.0, 1.0))
        out.append(RosMessage(L.CONTACT_POSE, t, enc.pose_stamped(t, self.base_frame, p)))
        out.append(RosMessage(L.CONTACT_WRENCH, t, enc.wrench_stamped(t, L.CONTACT_FRAME, [*ev.force, 0.0, 0.0, 0.0])))
        base_T_link = self._link_pose(fox, ev)
        out.append(RosMessage(L.MARKERS, t, enc.marker_array(
            contact_markers(t, self.base_frame, ev, self._surfaces.get(ev.link, []), base_T_link, self.scale))))
        if self.bag:
            out += self._tf(fox, extra=[contact_tf])
        return out

    def _link_pose(self, fox: list, ev: ContactEvent) -> np.ndarray | None:
        for m in fox:
            if m.schema == FRAME_TRANSFORMS:
                for tf in m.data["transforms"]:
                    if tf["child_frame_id"] == ev.link and tf["parent_frame_id"] == self.base_frame:
                        self._link_T = (ev.contact_id, _matrix(tf))
                        return self._link_T[1]
        last = self._link_T  # an offset: where its contact's last estimate was
        return last[1] if last is not None and last[0] == ev.contact_id else None

    # -- bag only: the raw inputs and /tf --------------------------------------------------------------------
    def _tf(self, fox: list, extra: list | None = None) -> list[RosMessage]:
        out = []
        for m in fox:
            if m.schema == FRAME_TRANSFORMS:
                t = self.ros_time(m.log_time)
                tfs = [enc.transform_stamped(t, tf["parent_frame_id"], tf["child_frame_id"],
                                             [tf["translation"][k] for k in "xyz"],
                                             [tf["rotation"][k] for k in "xyzw"]) for tf in m.data["transforms"]]
                out.append(RosMessage(L.TF, t, enc.tf_message(tfs + (extra or []))))
                extra = None
        if extra:
            out.append(RosMessage(L.TF, extra[0].header.stamp.sec * 1_000_000_000 + extra[0].header.stamp.nanosec,
                                  enc.tf_message(extra)))
        return out

    def _raw_wrench(self, frame: WrenchFrame) -> RosMessage:
        t = self.ros_time(frame.t_host_ns)
        return RosMessage(self.wrench_topic, t, enc.wrench_stamped(t, self.wrench_frame, frame.wrench))

    def _joint_state(self, frame: JointFrame) -> RosMessage:
        t = self.ros_time(frame.t_host_ns)
        effort = {"current": frame.current, "torque": frame.tau}.get(self.effort)
        return RosMessage(self.joint_topic, t, enc.joint_state(t, self.joint_names, frame.q, frame.qd,
                                                               () if effort is None else effort))
