"""``ftc identify BAG...``: the free motion in ROS 2 bags of a cell's drivers (:mod:`ftc_hw.app.ros.bag_inputs`),
what each bag holds said first. The bags are taken as free motion: nothing in them says where a contact was."""
from __future__ import annotations

from collections import Counter
from pathlib import Path

from rich.console import Console

from ftc_hw.calibration.free_motion import MotionData
from ftc_hw.calibration.joint_motion import JointMotionData
from ftc_hw.record.reader import RecordingError
from ftc_hw.scene import Scene


def _read(scene: Scene, path: Path, topics: Path | None, console: Console):
    """The bag at ``path`` read with ``topics`` (else the drivers' defaults) and said; a ``RecordingError``
    naming what is wrong when it cannot be (the ros extra missing, a bad map, a bag that does not fit)."""
    from ftc_hw.app.ros import RosUnavailable, require_ros  # lazy: the ros extra, for bags only

    try:
        require_ros("ftc identify from a ROS 2 bag")
        from ftc_hw.app.ros.bag_inputs import check_fits  # lazy: rosbags, after require_ros
        from ftc_hw.app.ros.bag_read import read_bag  # lazy: rosbags, after require_ros
        from ftc_hw.app.ros.topic_map import TopicMapError, default_map, load_topic_map  # lazy: beside it

        try:
            tmap = load_topic_map(topics, scene) if topics else default_map(scene)
        except TopicMapError as exc:
            raise RecordingError(str(exc)) from None
        bag = read_bag(path, tmap, scene)
    except RosUnavailable as exc:
        raise RecordingError(str(exc)) from None
    console.print(bag.summary())
    check_fits(bag, scene)
    return bag


def bag_joint_motion(scene: Scene, path: Path, topics: Path | None,
                     console: Console) -> tuple[list[JointMotionData], dict[str, int]]:
    """A scene sensed through its joints: the bag's joint states, in stretches split at gaps."""
    from ftc_hw.app.ros.bag_inputs import joint_motion  # lazy: rosbags, after require_ros (in _read)

    bag = _read(scene, path, topics, console)
    segments = joint_motion(bag, scene)
    return segments, {"frames": len(bag.joints.t_ns), "cut": len(bag.joints.t_ns) - sum(len(s.t) for s in segments)}


def bag_ft_motion(scene: Scene, paths: list[Path], topics: Path | None,
                  console: Console) -> tuple[list[MotionData], dict[str, int]]:
    """A base F/T sensor: each bag's wrenches with the joint state at their stamps."""
    from ftc_hw.app.ros.bag_inputs import ft_motion  # lazy: rosbags, after require_ros (in _read)

    segments: list[MotionData] = []
    counts: Counter[str] = Counter()
    for path in paths:
        more, n = ft_motion(_read(scene, path, topics, console), scene)
        segments += more
        counts.update(n)
    return segments, {"frames": counts["frames"], "no_joint_state": counts["no_joint_state"]}
