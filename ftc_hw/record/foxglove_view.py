"""The scene of a recording in Foxglove's well-known schemas, from the bus's frames: what
:class:`~ftc_hw.record.writer.McapRecorder` writes beside the bus's own channels when it is given the
scene, so that Foxglove shows the arm and its contacts in 3-D with no set-up (docs/recording.md).

- ``foxglove/tf`` (``foxglove.FrameTransforms``): ``world`` (the project's ``base`` frame, MuJoCo's
  world; named so because ur5e has a link called ``base``) to every link, and the sensor's link to
  ``sensor``, at most ``rate_hz`` a second from the joint state the pipeline used (``monitor/input``;
  the arm's own stream, ``joints/<arm>``, when no input came for 0.1 s), and at each contact event's
  own time, from the joint state of that time;
- ``foxglove/arm`` (``foxglove.SceneUpdate``): the touchable primitives the solver uses, one entity
  per link in the link's frame, once at the start (a recording keeps it for every reader);
- ``foxglove/contacts``: each contact event's point, 95 % ellipsoid, force arrow and label in the
  touched link's frame, one entity per contact (its newer events replace it), for ``contact_lifetime_s``;
- ``foxglove/wrench``: the sensor's reading as force and torque arrows in ``sensor``, ``rate_hz``.

One instance per recorder thread (it owns an :class:`~ftc_hw.model.ArmModel`). A frame it cannot use
(non-finite or misshapen q or wrench, an event with no pose near its time or on an unknown link) is
counted in ``skipped``, never raised; q and wrenches are checked where they are used (the frames
between two transforms are kept for the events' poses, and checked when one needs them).
"""
from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from ftc_hw.bus import ContactEvent, JointFrame, WrenchFrame
from ftc_hw.model import ArmModel
from ftc_hw.model.arm import link_reach
from ftc_hw.monitor import LOST_S, PipelineInput
from ftc_hw.scene import Scene

from .foxglove_messages import (
    FRAME_TRANSFORMS,
    K95_3D,
    SCENE_UPDATE,
    Json,
    color,
    contact_entity,
    entity,
    quat_of,
    quat_wxyz,
    scene_update,
    surface_primitives,
    transform,
    wrench_entity,
)

TF_TOPIC = "foxglove/tf"
ARM_TOPIC = "foxglove/arm"
CONTACTS_TOPIC = "foxglove/contacts"
WRENCH_TOPIC = "foxglove/wrench"
ROOT_FRAME = "world"
INPUT_QUIET_NS = 100_000_000  # the arm's own stream takes over when no pipeline input came for this long
HOLD_NS = 20_000_000  # an event newer than the newest pose by at most this is placed at that pose
ARM_RGBA = color(0.62, 0.68, 0.78, 0.55)


@dataclass(frozen=True, slots=True)
class FoxgloveMessage:
    topic: str
    schema: str
    log_time: int  # host ns, the clock of the bus's channels
    data: Json


def _inverse(a_T_b: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = a_T_b[:3, :3].T
    out[:3, 3] = -a_T_b[:3, :3].T @ a_T_b[:3, 3]
    return out


class FoxgloveView:
    """``feed(frame)`` -> the Foxglove messages that frame makes (often none); ``start(t_ns)`` -> the arm."""

    def __init__(self, scene: Scene, *, rate_hz: float = 50.0, contact_lifetime_s: float = 3.0) -> None:
        self.arm = arm = ArmModel(scene)  # kinematics only: a payload or identified inertials change no pose
        self.rate_hz = rate_hz
        self.contact_lifetime_s = contact_lifetime_s
        self.sensor_frame = "sensor" if "sensor" not in arm.link_names else "sensor_site"
        # without an F/T sensor its frame is the base frame (ArmModel.base_T_sensor), on the arm's first body
        self.sensor_link = arm.model.body(arm.sensor_body if arm.sensor_body is not None else 1).name
        home = np.asarray(scene.robot.home, dtype=float)
        links = arm.kinematics(home)
        link_T_sensor = _inverse(links[self.sensor_link]) @ arm.base_T_sensor(home)
        # the sensor in its link's frame: (position m, Foxglove's quaternion)
        self.sensor_tf = (link_T_sensor[:3, 3].copy(), quat_of(link_T_sensor[:3, :3]))
        self.reach = max(float(np.linalg.norm(links[k][:3, 3])) + r for k, r in link_reach(arm).items())
        self.marker_m = max(0.005, 0.02 * self.reach)
        self.contact_m_per_n = 0.25 * self.reach / 20.0  # a 20 N push: a quarter of the arm's reach
        weight = max(arm.total_mass * float(np.linalg.norm(scene.gravity)), 1e-6)
        self.wrench_m_per_n = 0.5 * self.reach / weight  # the arm's own weight: half its reach
        self.wrench_m_per_nm = 1.0 / weight  # its weight's moment at half the reach: half the reach
        self.counts: Counter[str] = Counter()  # messages made, per topic
        self.skipped: Counter[str] = Counter()  # frames that made none, per reason
        self._period_ns = round(1e9 / rate_hz)
        self._poses: deque[tuple[int, np.ndarray]] = deque(maxlen=4096)
        self._tf_bucket = -1
        self._wrench_bucket = -1
        self._last_input_ns: int | None = None
        self._estimates: dict[tuple, np.ndarray] = {}  # (contact_id, link, point) -> link_T_base then

    def describe(self) -> dict[str, str]:
        """The layout, for the recording's metadata."""
        return {"transforms": TF_TOPIC, "arm": ARM_TOPIC, "contacts": CONTACTS_TOPIC, "wrench": WRENCH_TOPIC,
                "root_frame": ROOT_FRAME, "sensor_frame": self.sensor_frame, "sensor_link": self.sensor_link,
                "rate_hz": f"{self.rate_hz:g}", "contact_lifetime_s": f"{self.contact_lifetime_s:g}",
                "contact_m_per_N": f"{self.contact_m_per_n:.5f}", "wrench_m_per_N": f"{self.wrench_m_per_n:.5f}",
                "wrench_m_per_Nm": f"{self.wrench_m_per_nm:.5f}",
                "ellipsoid": f"95 % (3-D, {K95_3D:.4f} sigma), axes along the base frame's"}

    def start(self, t_ns: int) -> list[FoxgloveMessage]:
        by_link: dict[str, dict[str, list[Json]]] = {}
        for s in self.arm.surfaces:
            prims = by_link.setdefault(s.link, {})
            for kind, items in surface_primitives(s, ARM_RGBA).items():
                prims.setdefault(kind, []).extend(items)
        entities = [entity(t_ns, link, f"arm/{link}", metadata={"link": link}, **prims)
                    for link, prims in by_link.items()]
        return [self._message(ARM_TOPIC, SCENE_UPDATE, t_ns, scene_update(entities))]

    def feed(self, frame: Any) -> list[FoxgloveMessage]:
        if isinstance(frame, PipelineInput):  # the most frequent first: every F/T sample
            self._last_input_ns = frame.t_host_ns
            return self._pose(frame.t_host_ns, frame.q)
        if isinstance(frame, WrenchFrame):
            return self._wrench(frame)
        if isinstance(frame, JointFrame):
            if self._last_input_ns is not None and frame.t_host_ns - self._last_input_ns < INPUT_QUIET_NS:
                return []
            return self._pose(frame.t_host_ns, frame.q)
        if isinstance(frame, ContactEvent):
            return self._contact(frame)
        return []

    def _message(self, topic: str, schema: str, t_ns: int, data: Json) -> FoxgloveMessage:
        self.counts[topic] += 1
        return FoxgloveMessage(topic, schema, int(t_ns), data)

    def _valid_q(self, q: Any) -> np.ndarray | None:
        q = np.asarray(q, dtype=float)
        if q.shape != (self.arm.n_joints,) or not np.isfinite(q).all():
            self.skipped["bad_q"] += 1
            return None
        return q

    def _pose(self, t_ns: int, q: Any) -> list[FoxgloveMessage]:
        # Checked where used (here at most rate_hz a second, and by _q_at): every frame's check cost more
        # than the rest of the view together.
        self._poses.append((t_ns, q))
        bucket = t_ns // self._period_ns
        if bucket <= self._tf_bucket:
            return []
        q = self._valid_q(q)
        if q is None:
            return []  # the next frame tries again
        self._tf_bucket = bucket
        return [self._transforms(t_ns, q)]

    def _transforms(self, t_ns: int, q: np.ndarray) -> FoxgloveMessage:
        xpos, xquat = self.arm.body_poses(q)
        tfs = [transform(t_ns, ROOT_FRAME, name, xpos[i + 1], quat_wxyz(xquat[i + 1]))
               for i, name in enumerate(self.arm.link_names)]
        tfs.append(transform(t_ns, self.sensor_link, self.sensor_frame, *self.sensor_tf))
        return self._message(TF_TOPIC, FRAME_TRANSFORMS, t_ns, {"transforms": tfs})

    def _q_at(self, t_ns: int) -> np.ndarray | None:
        """The joint state at t_ns: the pose of that time, else interpolated between its neighbours, else
        the newest when at most HOLD_NS older; None when none is near (or those poses are bad)."""
        poses = self._poses
        for i in range(len(poses) - 1, -1, -1):
            ti, qi = poses[i]
            if ti > t_ns:
                continue
            if ti == t_ns or i == len(poses) - 1:
                return self._valid_q(qi) if t_ns - ti <= HOLD_NS else None
            tj, qj = poses[i + 1]
            qi, qj = self._valid_q(qi), self._valid_q(qj)
            return None if qi is None or qj is None else qi + (qj - qi) * ((t_ns - ti) / (tj - ti))
        return None

    def _contact(self, ev: ContactEvent) -> list[FoxgloveMessage]:
        if "no_estimate" in ev.flags:
            self.skipped["contact_no_estimate"] += 1
            return []
        key = (ev.contact_id, ev.link, tuple(float(x) for x in ev.point))
        # an offset carries its contact's last sound estimate: shown where that estimate put it on the link
        link_T_base = self._estimates.get(key) if ev.kind == "offset" else None
        out = []
        if link_T_base is None:
            q = self._q_at(ev.t_host_ns)
            base_T_link = None if q is None else self.arm.kinematics(q).get(ev.link)
            if base_T_link is None:
                self.skipped["contact_no_pose" if q is None else "contact_unknown_link"] += 1
                return []
            link_T_base = _inverse(base_T_link)
            out.append(self._transforms(ev.t_host_ns, q))  # the link's pose at the event's own time, exactly
        if ev.kind == "offset":
            self._estimates = {k: v for k, v in self._estimates.items() if k[0] != ev.contact_id}
        else:
            self._estimates[key] = link_T_base
            if len(self._estimates) > 4096:
                del self._estimates[next(iter(self._estimates))]
        ent = contact_entity(ev, link_T_base, marker_m=self.marker_m, m_per_n=self.contact_m_per_n,
                             max_m=self.reach, lifetime_s=self.contact_lifetime_s)
        out.append(self._message(CONTACTS_TOPIC, SCENE_UPDATE, ev.t_host_ns, scene_update([ent])))
        return out

    def _wrench(self, frame: WrenchFrame) -> list[FoxgloveMessage]:
        bucket = frame.t_host_ns // self._period_ns
        if bucket <= self._wrench_bucket:
            return []
        w = np.asarray(frame.wrench, dtype=float)
        if w.shape != (6,) or not np.isfinite(w).all():
            self.skipped["bad_wrench"] += 1
            return []  # the next frame tries again
        self._wrench_bucket = bucket
        ent = wrench_entity(frame.t_host_ns, self.sensor_frame, w, m_per_n=self.wrench_m_per_n,
                            m_per_nm=self.wrench_m_per_nm, max_m=self.reach, thickness=self.marker_m / 4,
                            lifetime_s=LOST_S)
        return [self._message(WRENCH_TOPIC, SCENE_UPDATE, frame.t_host_ns, scene_update([ent]))]
