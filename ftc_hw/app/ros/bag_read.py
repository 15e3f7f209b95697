"""A ROS 2 bag's arm and F/T topics (:mod:`.topic_map`) to arrays, through rosbags (MCAP and sqlite3, a
rosbag2 directory or a bare ``.mcap`` / ``.db3``). Messages that cannot be used are counted by topic
and reason and left out, never used; a bag cut short is read up to where it breaks (``complete``).

Reasons (``BagRecording.skipped`` keys ``<stream>:<reason>``, stream ``joints`` or ``wrench``), in the
order a message is checked: ``undecodable`` (its bytes are not the type's CDR), ``missing_joint`` (a
mapped joint is not in its ``name`` list), ``cut_short`` (position, velocity or effort shorter than its
names), ``no_velocity`` / ``no_effort`` (the field empty where it is used), ``wrong_frame`` (a wrench in
another frame than the map's), ``no_stamp`` (header stamp 0), ``not_finite``, ``out_of_range`` (past
:class:`~ftc_hw.record.ur_csv.PhysicalBounds`), ``time_jump`` / ``time_repeated`` / ``time_backwards``
(header stamps, as a UR recording's timestamps).
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from ftc_hw.record.reader import RecordingError
from ftc_hw.record.ur_csv import PhysicalBounds, Timing
from ftc_hw.record.ur_csv.bounds import DEFAULT_BOUNDS
from ftc_hw.record.ur_csv.rows import in_time_order  # one rule for stamps out of order, CSV and bag alike
from ftc_hw.record.ur_csv.timing import timing_of
from ftc_hw.scene import Scene

from .bag_form import mcap_profile
from .bag_stream import McapStreamBag
from .decode import joint_index, joint_state_arrays, stamp_ns, wrench_array
from .topic_map import TopicMap

JOINT_STATE = "sensor_msgs/msg/JointState"
WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
# the PhysicalBounds field each array is checked as (their limits are wide: garbage, never a reading)
_BOUNDS_AS = {"q": "actual_q", "qd": "actual_qd", "current": "actual_current", "torque": "target_moment",
              "wrench": "ft_raw_wrench"}


class BagError(RecordingError):
    """A bag that cannot be used at all: not a bag, no mapped topic, another message type, no joint of
    the map in its messages, no usable message. The message names the bag."""


@dataclass(frozen=True)
class Stream:
    """One topic's kept messages, in stamp order: ``t_ns`` (m,) header stamps, ``log_ns`` (m,) the bag's
    receive times; ``values`` by name (``q``, ``qd`` (m, n) rad, rad/s; ``effort`` (m, n) A or N m;
    ``wrench`` (m, 6) N, N m); ``messages`` on the topic; ``timing`` of the stamps (None under 2 kept)."""

    topic: str
    t_ns: np.ndarray
    log_ns: np.ndarray
    values: dict[str, np.ndarray]
    messages: int
    timing: Timing | None


@dataclass(frozen=True)
class BagRecording:
    path: Path
    storage: str  # "mcap" | "sqlite3"
    topics: dict[str, tuple[str, int]]  # every topic: (its message type, messages)
    topic_map: TopicMap
    joints: Stream
    wrench: Stream | None  # None: no wrench mapped, or none in the bag
    skipped: Counter[str]
    other_names: tuple[str, ...] = ()  # joint names in the messages the map does not use (a gripper's)
    complete: bool = True
    error: str | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def n_joints(self) -> int:
        return self.joints.values["q"].shape[1]

    @property
    def sensing(self) -> frozenset[str]:
        """The scene sensing kinds the bag holds (``ft``: the mapped wrench, whatever its mount)."""
        kinds = set(self.topic_map.sensing)
        if self.wrench is None or not len(self.wrench.t_ns):
            kinds.discard("ft")
        return frozenset(kinds)

    def summary(self) -> str:
        """What the bag holds and what of it is used, in a few lines."""
        lines = [f"{self.path.name}: ROS 2 bag ({self.storage}), topics by {self.topic_map.source}"
                 + ("" if self.complete else f" [cut short: {self.error}; read up to there]")]
        for name, s in (("joint states", self.joints), ("wrench", self.wrench)):
            if s is None:
                continue
            kept = len(s.t_ns)
            skipped = ", ".join(f"{n} {k.split(':', 1)[1].replace('_', ' ')}" for k, n in sorted(self.skipped.items())
                                if k.startswith("joints:" if s is self.joints else "wrench:"))
            line = f"  {name} {s.topic}: {kept} of {s.messages} messages kept"
            line += f" (skipped: {skipped})" if skipped else ""
            line += f", {s.timing.describe()}" if s.timing is not None else ""
            lines.append(line)
        unused = sorted(set(self.topics) - {self.joints.topic} - ({self.wrench.topic} if self.wrench else set()))
        if unused:
            lines.append("  not used: " + ", ".join(f"{t} ({self.topics[t][0]})" for t in unused))
        if self.other_names:
            lines.append(f"  joints not in the map, left out: {', '.join(self.other_names)}")
        lines += [f"  {n}" for n in self.notes]
        return "\n".join(lines)


def _storage(reader: Reader | McapStreamBag, path: Path) -> str:
    if path.is_dir():
        ids = {type(s).__name__ for s in getattr(reader.storage, "storages", [])}
        return "mcap" if any("Mcap" in i for i in ids) else "sqlite3"
    return "mcap" if path.suffix == ".mcap" else "sqlite3"


def read_bag(path: Path | str, topic_map: TopicMap, scene: Scene, *,
             bounds: PhysicalBounds = DEFAULT_BOUNDS) -> BagRecording:
    """The bag at ``path``: the mapped joint states (in the scene's joint order) and wrench. Raises
    :class:`BagError` when it cannot be used at all."""
    path = Path(path)
    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds on a file that is not a bag
        reader = _cut_mcap(path, exc)
    try:
        return _read(reader, path, topic_map, scene, bounds)
    finally:
        reader.close()


def _cut_mcap(path: Path, exc: Exception) -> McapStreamBag:
    """A ros2 MCAP file rosbags cannot open (no footer: a recorder killed), read from its start instead."""
    if not (path.is_file() and mcap_profile(path) == "ros2"):
        raise BagError(f"{path}: cannot open as a ROS 2 bag: {exc}") from None
    reader = McapStreamBag(path)
    reader.open()
    if not reader.connections:
        raise BagError(f"{path}: cannot open as a ROS 2 bag ({exc}), and no channel before the file breaks off")
    return reader


def _connections(reader: Reader | McapStreamBag, path: Path, topic: str, msgtype: str, required: bool) -> list:
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        if not required:
            return []
        have = ", ".join(f"{c.topic} ({c.msgtype})" for c in reader.connections) or "no topics"
        raise BagError(f"{path}: no topic {topic} (the bag has {have}): give --topics map.toml naming "
                       "the joint states' topic (docs/ros.md, \"Bags in\")")
    wrong = sorted({c.msgtype for c in conns if c.msgtype != msgtype})
    if wrong:
        raise BagError(f"{path}: {topic} carries {', '.join(wrong)}, not {msgtype}")
    return conns


def _read(reader: Reader | McapStreamBag, path: Path, tmap: TopicMap, scene: Scene,
          bounds: PhysicalBounds) -> BagRecording:
    js = tmap.joint_states
    wanted = js.bag_names(scene.robot.joints)
    joint_conns = _connections(reader, path, js.topic, JOINT_STATE, True)
    wrench_conns = _connections(reader, path, tmap.wrench.topic, WRENCH_STAMPED, False) if tmap.wrench else []
    store = get_typestore(Stores.LATEST)
    skipped: Counter[str] = Counter()
    rows: dict[str, list] = {"joints": [], "wrench": []}
    counts = Counter()
    other: set[str] = set()
    frames_seen: Counter[str] = Counter()
    complete, error = True, None
    is_joint = {c.id for c in joint_conns}
    try:
        for conn, log_ns, raw in reader.messages(connections=joint_conns + wrench_conns):
            stream = "joints" if conn.id in is_joint else "wrench"
            counts[stream] += 1
            try:
                msg = store.deserialize_cdr(raw, conn.msgtype)
            except Exception:  # noqa: BLE001 - any decoding failure is a message we cannot use
                skipped[f"{stream}:undecodable"] += 1
                continue
            if stream == "joints":
                row = _joint_row(msg, wanted, js.effort, skipped, other)
            else:
                frames_seen[msg.header.frame_id] += 1
                row = None
                if msg.header.frame_id != tmap.wrench.frame_id:
                    skipped["wrench:wrong_frame"] += 1
                else:
                    row = {"wrench": wrench_array(msg)}
            if row is not None:
                rows[stream].append((stamp_ns(msg.header), int(log_ns), row))
    except Exception as exc:  # noqa: BLE001 - a bag cut short or corrupt: keep what was read before it
        complete, error = False, f"{type(exc).__name__}: {exc}"
    joints = _stream(js.topic, rows["joints"], counts["joints"], "joints", bounds, skipped, js.effort)
    if len(joints.t_ns) < 2:
        _no_joints(path, js.topic, wanted, other, counts["joints"], skipped)
    wrench = None
    notes = []
    if tmap.wrench is not None and wrench_conns:
        wrench = _stream(tmap.wrench.topic, rows["wrench"], counts["wrench"], "wrench", bounds, skipped, "none")
        if not len(wrench.t_ns) and frames_seen:
            seen = ", ".join(repr(f) for f in frames_seen)
            raise BagError(f"{path}: {tmap.wrench.topic} is in frame {seen}, the map says {tmap.wrench.frame_id!r}: "
                           "map frame_id to the frame the scene's F/T sensor measures in (--topics)")
    elif tmap.wrench is not None:
        notes.append(f"no {tmap.wrench.topic} in the bag: no F/T readings")
    return BagRecording(path, _storage(reader, path), {c.topic: (c.msgtype, c.msgcount) for c in reader.connections},
                        tmap, joints, wrench, +skipped, tuple(sorted(other)), complete, error, tuple(notes))


def _joint_row(msg, wanted: list[str], effort: str, skipped: Counter[str], other: set[str]) -> dict | None:
    index = joint_index(msg.name, wanted)
    other.update(n for n in msg.name if n not in wanted)
    if index is None:
        skipped["joints:missing_joint"] += 1
        return None
    try:
        q, qd, eff = joint_state_arrays(msg, index)
    except IndexError:
        skipped["joints:cut_short"] += 1
        return None
    if not q.size:
        skipped["joints:cut_short"] += 1
        return None
    if not qd.size:
        skipped["joints:no_velocity"] += 1
        return None
    if effort != "none" and not eff.size:
        skipped["joints:no_effort"] += 1
        return None
    row = {"q": q, "qd": qd}
    if effort != "none":
        row[effort] = eff
    return row


def _stream(topic: str, rows: list, messages: int, name: str, bounds: PhysicalBounds, skipped: Counter[str],
            effort: str) -> Stream:
    """The rows as arrays, those with no stamp, not finite, out of bounds or out of time order left out."""
    t = np.array([r[0] for r in rows], dtype=np.int64)
    log = np.array([r[1] for r in rows], dtype=np.int64)
    keys = list(rows[0][2]) if rows else (["wrench"] if name == "wrench" else ["q", "qd"])
    values = {k: np.array([r[2][k] for r in rows], dtype=float).reshape(len(rows), -1) if rows else np.zeros((0, 0))
              for k in keys}
    keep = t > 0
    skipped[f"{name}:no_stamp"] += int((~keep).sum())
    for reason, test in (("not_finite", lambda k, v: np.isfinite(v).all(axis=1)),
                         ("out_of_range", lambda k, v: bounds.within(_BOUNDS_AS[k], v))):
        for k, v in values.items():
            bad = keep & ~test(k, v)
            skipped[f"{name}:{reason}"] += int(bad.sum())
            keep &= ~bad
    local: Counter[str] = Counter()
    in_time_order(t, keep, local)
    for k, n in local.items():
        skipped[f"{name}:{k}"] += n
    values = {("effort" if k in ("current", "torque") else k): np.ascontiguousarray(v[keep]) for k, v in values.items()}
    t, log = t[keep], log[keep]
    timing = timing_of(t * 1e-9) if len(t) >= 2 else None
    return Stream(topic, t, log, values, messages, timing)


def _no_joints(path: Path, topic: str, wanted: list[str], other: set[str], messages: int,
               skipped: Counter[str]) -> None:
    if messages and skipped["joints:missing_joint"]:
        names = ", ".join(sorted(other)) or "none"
        raise BagError(f"{path}: the joint states on {topic} name {names}, not the map's {', '.join(wanted)}: "
                       "map the driver's names to the scene's joints ([joint_states.names] in --topics)")
    why = ", ".join(f"{n} {k}" for k, n in sorted(skipped.items()) if k.startswith("joints:") and n) or "none"
    raise BagError(f"{path}: {messages} joint state messages on {topic}, fewer than two usable (skipped: {why})")
