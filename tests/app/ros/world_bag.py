"""ROS 2 bags as ``ros2 bag record`` keeps a cell's drivers' topics, written with rosbags' Writer (MCAP or
sqlite3) from the simulated world's run (tests/ur_world_csv.py: ``run_world``'s 500 Hz columns), with bad
messages put in at fixed places: which kind where is returned (what the reader must count and skip)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

STORE = get_typestore(Stores.ROS2_KILTED)
JOINT_STATE = "sensor_msgs/msg/JointState"
WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
STAMP0_NS = 1_760_000_000_000_000_000  # the drivers stamp with ROS time: Unix time in ns
# ESTIMATE: a stamp's age when the recorder gets it on the same host (DDS over loopback, 0.1-0.2 ms median
# measured here: platform-notes.md), with jitter; it is the bag's receive time.
LATENCY_NS = 200_000


@dataclass(frozen=True)
class Driver:
    """What one cell's drivers publish: joint states on ``joint_topic`` naming ``names`` in message order
    (``order``: each message slot's scene joint), effort from ``effort_column``; a wrench from
    ``wrench_column`` on ``wrench_topic`` in ``frame_id``."""

    joint_topic: str
    names: tuple[str, ...]
    order: tuple[int, ...]
    effort_column: str
    wrench_topic: str | None = None
    wrench_column: str | None = None
    frame_id: str = ""


def _time(ns: int):
    return STORE.types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _header(ns: int, frame_id: str = ""):
    return STORE.types["std_msgs/msg/Header"](stamp=_time(ns), frame_id=frame_id)


def _joint_state(ns: int, names, q, qd, effort) -> bytes:
    msg = STORE.types[JOINT_STATE](header=_header(ns), name=list(names), position=np.ascontiguousarray(q, float),
                                   velocity=np.ascontiguousarray(qd, float), effort=np.ascontiguousarray(effort, float))
    return STORE.serialize_cdr(msg, JOINT_STATE)


def _wrench(ns: int, frame_id: str, w) -> bytes:
    v3 = STORE.types["geometry_msgs/msg/Vector3"]
    wrench = STORE.types["geometry_msgs/msg/Wrench"](force=v3(x=w[0], y=w[1], z=w[2]),
                                                     torque=v3(x=w[3], y=w[4], z=w[5]))
    return STORE.serialize_cdr(STORE.types[WRENCH_STAMPED](header=_header(ns, frame_id), wrench=wrench), WRENCH_STAMPED)


def write_bag(path: Path, columns: dict[str, np.ndarray], driver: Driver, *, storage: str = "mcap",
              bad: bool = True) -> dict[str, int]:
    """The bag at ``path`` (a folder, as ros2 bag record writes it); with ``bad``, the bad messages put in,
    returned as the reader's ``<stream>:<reason>`` counts."""
    t = columns["timestamp"]
    stamps = STAMP0_NS + np.round((t - t[0]) * 1e9).astype(np.int64)
    n = len(t)
    order = list(driver.order)
    q, qd = columns["actual_q"][:, order], columns["actual_qd"][:, order]
    effort = columns[driver.effort_column][:, order].copy()
    names = list(driver.names)
    expected: dict[str, int] = {}
    if bad:
        effort[n // 5, 1] = np.nan
        stamps[3 * n // 5] = stamps[3 * n // 5 - 1]  # a repeated stamp
        stamps[4 * n // 5] = stamps[4 * n // 5 - 5]  # a stamp going backwards
        expected = {"joints:not_finite": 1, "joints:time_repeated": 1, "joints:time_backwards": 1,
                    "joints:missing_joint": 1, "joints:undecodable": 1}
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    rng = np.random.default_rng(0)
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        joints = writer.add_connection(driver.joint_topic, JOINT_STATE, typestore=STORE)
        wrench = (writer.add_connection(driver.wrench_topic, WRENCH_STAMPED, typestore=STORE)
                  if driver.wrench_topic else None)
        log_prev = 0
        for i in range(n):
            log = max(int(stamps[i]) + LATENCY_NS + int(rng.integers(0, LATENCY_NS)), log_prev + 1)
            log_prev = log
            if bad and i == 2 * n // 5:  # a driver restarting mid-message: bytes that are not a JointState
                writer.write(joints, log, b"\x00\x01\x00\x00\x07")
                continue
            row_names = names[:-1] if bad and i == n // 3 else names  # a message missing a joint
            writer.write(joints, log, _joint_state(int(stamps[i]), row_names, q[i], qd[i], effort[i]))
            if wrench is not None:
                w = columns[driver.wrench_column][i].copy()
                frame = driver.frame_id
                if bad and i == n // 4:
                    frame = "world"  # a wrench in another frame
                if bad and i == n // 2:
                    w[2] = np.nan
                writer.write(wrench, log, _wrench(int(stamps[i]), frame, w))
    if bad and driver.wrench_topic:
        expected |= {"wrench:wrong_frame": 1, "wrench:not_finite": 1, "wrench:time_repeated": 1,
                     "wrench:time_backwards": 1}  # the same stamps as the joint states
    return expected


def storage_file(bag: Path) -> Path:
    """The bag folder's one storage file (``.mcap`` or ``.db3``)."""
    return next(p for p in sorted(bag.iterdir()) if p.suffix in (".mcap", ".db3"))
