"""The ROS 2 bag ``ftc monitor --record-format ros2|both`` writes (ftc_hw.app.ros.bag), read back with rosbags
and decoded message for message with rclpy's own deserializer; the recorder's sinks; what the live
publisher cannot send, counted."""
from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.serialization import deserialize_message
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from ftc_hw.app.ros import encode as enc
from ftc_hw.app.ros import layout as L
from ftc_hw.app.ros.bag import RosBagWriter, bag_path
from ftc_hw.app.ros.publisher import RosPublisher
from ftc_hw.bus import Bus, ContactEvent, DeviceEvent, JointFrame, WrenchFrame
from ftc_hw.monitor import JudgedFrame, PipelineInput
from ftc_hw.record.writer_process import Sink, _Sinks
from ftc_hw.scene import load_scene

pytestmark = pytest.mark.compute

RCLPY_TYPES = {t.msgtype: cls for t, cls in ((L.EXTERNAL_WRENCH, WrenchStamped), (L.CONTACT_POSE, PoseStamped),
                                              (L.MARKERS, MarkerArray), (L.EVENTS, String),
                                              (L.DIAGNOSTICS, DiagnosticArray), (L.JOINT_STATES, JointState))}
T0 = 5_000_000_000_000
N = 3000  # 3 s at 1 kHz: a joint sample every 2 ms, diagnostics each second


def _frames(scene) -> list:
    q0 = np.asarray(scene.robot.home, dtype=float)
    out: list = []
    for i in range(N):
        t, q = T0 + i * 1_000_000, q0 + 1e-4 * i
        out.append(WrenchFrame.make(t, [0.0, 0.0, 40.0 + 1e-3 * i, 0.0, 0.0, 0.0], source="ft", seq=i))
        if i % 2 == 0:
            out.append(JointFrame.make(t, q, 0 * q, 0 * q + 0.5, source="arm", seq=i // 2))
        out.append(PipelineInput(t, None, i, "ft", np.zeros(6), q, 0 * q, 0 * q))
        out.append(JudgedFrame(t, None, i, "ft", np.array([0.0, 0.0, -1e-3 * i, 0.0, 0.0, 0.0]), 0.5, False))
        if i in (1000, 1020):
            kind = "onset" if i == 1000 else "offset"
            out.append(ContactEvent.make(t, kind, "forearm", [0.3, 0.1, 0.4], [0.0, 0.0, -10.0], [0.002, 0.002, 0.004],
                                         contact_id=1))
    out.append(DeviceEvent.make(T0 + N * 1_000_000, "ft", "sensor_lost", "no F/T frame for 0.25 s", {}))
    return out


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    scene = load_scene("ur5e")
    path = tmp_path_factory.mktemp("bag") / "run_ros2"
    writer = RosBagWriter(path=str(path), scene=scene)
    for f in _frames(scene):
        writer.write(f)
    return path, writer.finish({})


def _read(path) -> tuple[dict, list]:
    with Reader(path) as reader:
        conns = {c.topic: c for c in reader.connections}
        return conns, [(c.topic, c.msgtype, t, bytes(raw)) for c, t, raw in reader.messages()]


def test_the_bag_holds_a_message_per_frame_on_the_drivers_and_ftcs_topics(bag):
    path, summary = bag
    conns, messages = _read(path)
    counts = Counter(topic for topic, *_ in messages)
    assert counts == Counter(summary["counts"])
    assert counts["/force_torque_sensor_broadcaster/wrench"] == N and counts["/joint_states"] == N // 2
    assert counts["/ftc/external_wrench"] == N  # one per judged frame
    assert counts["/ftc/events"] == 3 and counts["/ftc/contact_markers"] == 2 and counts["/ftc/contact_pose"] == 2
    # each second of the frames (1, 2 and 3 s: the stream event ends the run at 3 s); the links at 50 Hz
    assert counts["/diagnostics"] == 3 and counts["/tf"] >= 50 * 3
    assert {c.msgtype for c in conns.values()} >= {"tf2_msgs/msg/TFMessage", "sensor_msgs/msg/JointState"}
    latched = {t for t, c in conns.items() if c.ext.offered_qos_profiles[0].durability == QosDurability.TRANSIENT_LOCAL}
    assert latched == {"/ftc/events", "/ftc/contact_markers", "/ftc/contact_pose", "/ftc/contact_wrench"}


def test_every_message_decodes_with_rclpy_and_log_times_are_its_stamps(bag):
    _, messages = _read(bag[0])
    decoded = 0
    for topic, msgtype, t, raw in messages:
        if msgtype not in RCLPY_TYPES:
            continue
        m = deserialize_message(raw, RCLPY_TYPES[msgtype])
        if hasattr(m, "header"):
            assert m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec == t, topic
        decoded += 1
    assert decoded == len(messages) - sum(1 for m in messages if m[1] == "tf2_msgs/msg/TFMessage")
    js = [deserialize_message(raw, JointState) for topic, _, _, raw in messages if topic == "/joint_states"]
    assert list(js[0].name) == list(load_scene("ur5e").robot.joints) and list(js[0].effort) == [0.5] * 6


def test_tf_carries_the_links_the_sensor_and_the_contact_frame_at_its_point(bag):
    _, messages = _read(bag[0])
    tfs = [enc.typestore().deserialize_cdr(raw, "tf2_msgs/msg/TFMessage") for topic, _, _, raw in messages
           if topic == "/tf"]
    children = {t.child_frame_id for m in tfs for t in m.transforms}
    assert {"forearm", "wrist_3", "sensor", L.CONTACT_FRAME} <= children
    contact = [t for m in tfs for t in m.transforms if t.child_frame_id == L.CONTACT_FRAME]
    assert len(contact) == 2 and contact[0].header.frame_id == "world"
    v = contact[0].transform.translation
    assert [v.x, v.y, v.z] == [0.3, 0.1, 0.4]


def test_bag_paths():
    from pathlib import Path
    assert bag_path(Path("d/run.mcap"), "both") == Path("d/run_ros2")
    assert bag_path(Path("d/run"), "ros2") == Path("d/run")


class _Boom:
    def write(self, frame):
        raise ValueError("no")

    def flush(self):
        pass

    def finish(self, final):
        return {"path": "boom"}


class _Keep:
    def __init__(self):
        self.frames = []

    def write(self, frame):
        self.frames.append(frame)

    def flush(self):
        pass

    def finish(self, final):
        return {"frames": len(self.frames)}


def test_a_sink_that_fails_is_counted_and_the_others_go_on():
    sinks = _Sinks((Sink(_Boom), Sink(_Keep)))
    for i in range(3):
        sinks.write(i)
    boom, keep = sinks.finish(None)
    assert boom["errors"] == 3 and boom["error"] == "ValueError: no" and keep == {"frames": 3, "errors": 0, "error": ""}


class _Refuses:
    def publish(self, data):
        raise RuntimeError("rmw said no")


def test_what_the_publisher_cannot_send_is_counted_never_silent():
    ros = RosPublisher(Bus(), load_scene("ur5e"))  # not started: no node, publishers stubbed
    ros._pubs = {t.full_name("/ftc"): _Refuses() for t in L.TOPICS if t.live}
    ros._publish(ros.view.feed(JudgedFrame(T0, None, 0, "ft", np.zeros(6), 0.0, False)))
    assert ros.failed == {"/ftc/external_wrench": 1} and "rmw said no" in ros.error and not ros.counts


def test_the_bags_mcap_is_the_ros2_profile_with_ros2msg_schemas(bag):
    from mcap.reader import make_reader

    (mcap_file,) = bag[0].glob("*.mcap")
    with open(mcap_file, "rb") as f:
        reader = make_reader(f)
        header, summary = reader.get_header(), reader.get_summary()
    assert header.profile == "ros2"
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
    names = {s.name for s in summary.schemas.values()}
    assert {"geometry_msgs/msg/WrenchStamped", "tf2_msgs/msg/TFMessage", "visualization_msgs/msg/MarkerArray"} <= names


def test_ftcs_own_reader_of_drivers_bags_reads_it_back_with_the_drivers_defaults(bag):
    """``ftc replay`` / ``ftc identify`` read a bag through ``read_bag`` with the drivers' defaults: what the bag
    holds of the arm and the sensor comes back as written (ur5e: ur_robot_driver's joints, a Net F/T's wrench)."""
    from ftc_hw.app.ros.bag_read import read_bag
    from ftc_hw.app.ros.topic_map import default_map

    scene = load_scene("ur5e")
    rec = read_bag(bag[0], default_map(scene), scene)
    frames = _frames(scene)
    joints = [f for f in frames if isinstance(f, JointFrame)]
    wrenches = [f for f in frames if isinstance(f, WrenchFrame)]
    assert not rec.skipped and rec.joints.values["q"].shape == (N // 2, 6)
    assert rec.wrench.values["wrench"].shape == (N, 6)
    np.testing.assert_array_equal(rec.joints.values["q"], [f.q for f in joints])
    np.testing.assert_array_equal(rec.joints.values["effort"], [f.current for f in joints])  # UR: currents, A
    np.testing.assert_array_equal(rec.wrench.values["wrench"], [f.wrench for f in wrenches])


def test_a_franka_bag_has_franka_ros2s_joint_names_and_torques(tmp_path):
    from ftc_hw.app.ros.bag_read import read_bag
    from ftc_hw.app.ros.topic_map import default_map

    scene = load_scene("fr3")
    q = np.asarray(scene.robot.home, dtype=float)
    writer = RosBagWriter(path=str(tmp_path / "fr3"), scene=scene)
    sent = [JointFrame.make(T0 + i * 1_000_000, q + 1e-3 * i, 0 * q, 0 * q, q * 0 + 2.5, source="arm", seq=i)
            for i in range(50)]
    for f in sent:
        writer.write(f)
    writer.finish({})
    _, messages = _read(tmp_path / "fr3")
    (first, *_) = [deserialize_message(raw, JointState) for topic, _, _, raw in messages
                   if topic == "/franka/joint_states"]
    assert list(first.name) == [f"fr3_{j}" for j in scene.robot.joints] and list(first.effort) == [2.5] * 7
    rec = read_bag(tmp_path / "fr3", default_map(scene), scene)
    np.testing.assert_array_equal(rec.joints.values["q"], [f.q for f in sent])
