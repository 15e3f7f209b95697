"""The ROS encoder and view (ftc_hw.app.ros.encode, .view, .markers): CDR equal to rosbags' and readable by
rclpy's own deserializer, the external wrench carried into the base frame, a contact's markers on its point."""
from __future__ import annotations

import json

import jsonschema
import mujoco
import numpy as np
import pytest
from geometry_msgs.msg import WrenchStamped
from rclpy.serialization import deserialize_message
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from ftc_hw.app.ros import encode as enc
from ftc_hw.app.ros import layout as L
from ftc_hw.app.ros.markers import ARROW, ELLIPSOID, LINK, POINT
from ftc_hw.app.ros.view import EVENT_JSON_SCHEMA, RosView
from ftc_hw.bus import ContactEvent, DeviceEvent
from ftc_hw.monitor import JudgedFrame, PipelineInput
from ftc_hw.record.foxglove_messages import K95_3D
from ftc_hw.scene import load_scene

pytestmark = pytest.mark.compute

T0 = 1_000_000_000_000  # a host monotonic time, ns


@pytest.mark.parametrize("frame_id", ["w", "world", "sensor", "sensor_site", "a" * 13])
def test_the_packed_wrench_is_rosbags_cdr_and_rclpy_reads_it(frame_id):
    w = [1.5, -2.25, 30.0, 0.125, -0.5, 1e-9]
    data = enc.wrench_stamped(1_795_000_000_123_456_789, frame_id, w)
    assert data == enc.wrench_stamped_typestore(1_795_000_000_123_456_789, frame_id, w)
    m = deserialize_message(data, WrenchStamped)
    assert (m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id) == (1_795_000_000, 123_456_789, frame_id)
    f, t = m.wrench.force, m.wrench.torque
    assert [f.x, f.y, f.z, t.x, t.y, t.z] == w


def test_quaternions_are_mujocos_in_ros_order():
    rng = np.random.default_rng(3)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, q)
        x, y, z, w = enc.quat_xyzw(rot.reshape(3, 3))
        assert min(np.abs([w, x, y, z] - q).max(), np.abs([w, x, y, z] + q).max()) < 1e-9


def _judged(external, t=T0) -> JudgedFrame:
    return JudgedFrame(t, None, 0, "ft", np.asarray(external, dtype=float), 0.0, False)


# a sensor on the fixed base; one on the flange (it moves with q); none (the joint pipeline's wrench in base axes)
@pytest.mark.parametrize("scene_name", ["ur5e", "ur10e", "fr3"])
def test_the_external_wrench_is_the_load_on_the_arm_in_the_base_frame(scene_name):
    scene = load_scene(scene_name)
    view = RosView(scene, clock_offset=0)
    q = np.asarray(scene.robot.home, dtype=float) + 0.3
    view.feed(PipelineInput(T0, None, 0, "ft", np.zeros(6), q, 0 * q, 0 * q))
    p, c = np.array([3.0, -4.0, 12.0]), np.array([0.2, 0.1, 0.5])  # a push p at c, base frame
    b_T_s = view.arm.base_T_sensor(q)
    rot, r = b_T_s[:3, :3], b_T_s[:3, 3]
    # what the pipeline says: the change the push makes in the reading (sensor frame, the scene's convention)
    sign = 1.0 if scene.sensor is None else -scene.sensor.reading_sign
    external = sign * np.concatenate([rot.T @ p, rot.T @ np.cross(c - r, p)])
    (msg,) = view.feed(_judged(external))
    assert msg.topic is L.EXTERNAL_WRENCH
    m = deserialize_message(msg.data, WrenchStamped)
    got = [m.wrench.force.x, m.wrench.force.y, m.wrench.force.z, m.wrench.torque.x, m.wrench.torque.y,
           m.wrench.torque.z]
    assert m.header.frame_id == "world"
    np.testing.assert_allclose(got, np.concatenate([p, np.cross(c, p)]), atol=1e-9)


def test_a_wrench_with_no_joint_state_for_a_moving_sensor_is_counted_not_sent():
    view = RosView(load_scene("ur10e"), clock_offset=0)  # its sensor on the flange
    assert view.feed(_judged(np.ones(6))) == [] and view.skipped["external_no_pose"] == 1


def _event(kind="onset", flags=(), cid=2, link="forearm") -> ContactEvent:
    return ContactEvent.make(T0 + 5, kind, link, [0.31, -0.12, 0.45], [0.0, -6.0, -8.0], [0.002, 0.004, 0.008],
                             flags=flags, contact_id=cid, probability=0.97)


def _markers(view: RosView, ev: ContactEvent) -> tuple[list, dict]:
    out = {m.topic.name: m for m in view.feed(ev)}
    return deserialize_message(out[L.MARKERS.name].data, MarkerArray).markers, out


def test_a_contacts_markers_sit_on_its_point_with_its_ellipsoid_arrow_and_link():
    scene = load_scene("ur5e")
    view = RosView(scene, clock_offset=0)
    q = np.asarray(scene.robot.home, dtype=float)
    view.feed(PipelineInput(T0 + 5, None, 0, "ft", np.zeros(6), q, 0 * q, 0 * q))
    ev = _event()
    markers, out = _markers(view, ev)
    by_id = {m.id: m for m in markers}
    pos = lambda m: np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z])  # noqa: E731
    assert {m.header.frame_id for m in markers} == {"world"}
    np.testing.assert_allclose(pos(by_id[200 + POINT]), ev.point, atol=1e-12)
    ell = by_id[200 + ELLIPSOID]
    np.testing.assert_allclose(pos(ell), ev.point, atol=1e-12)
    np.testing.assert_allclose([ell.scale.x, ell.scale.y, ell.scale.z], 2 * K95_3D * ev.point_std, rtol=1e-12)
    tail, head = (np.array([p.x, p.y, p.z]) for p in by_id[200 + ARROW].points)
    np.testing.assert_allclose(head, ev.point, atol=1e-12)  # the head on the point, along the force
    np.testing.assert_allclose((head - tail) / np.linalg.norm(head - tail), ev.force / np.linalg.norm(ev.force))
    # the touched link's primitives where the link is at the event's time
    links = view.arm.kinematics(q)
    centres = [pos(m) for m in markers if m.id >= 200 + LINK]
    expected = [(links["forearm"] @ s.link_T_geom)[:3, 3] for s in view.arm.surfaces if s.link == "forearm"]
    assert len(centres) >= len(expected) > 0
    assert all(min(np.linalg.norm(c - e) for c in centres) < 1e-9 for e in expected)
    # its pose and its wrench in the contact frame
    assert {L.CONTACT_POSE.name, L.CONTACT_WRENCH.name, L.EVENTS.name} <= set(out)
    w = deserialize_message(out[L.CONTACT_WRENCH.name].data, WrenchStamped)
    assert w.header.frame_id == L.CONTACT_FRAME and [w.wrench.force.y, w.wrench.force.z] == [-6.0, -8.0]


def test_the_events_json_is_the_documented_schema_and_the_events_files_record():
    scene = load_scene("ur5e")
    view = RosView(scene, clock_offset=7)
    records = []
    for ev in (_event(), _event("offset", ("lost",)), DeviceEvent.make(T0 + 9, "ft", "sensor_lost", "no frame", {})):
        (msg,) = [m for m in view.feed(ev) if m.topic is L.EVENTS]
        records.append(json.loads(deserialize_message(msg.data, String).data))
    for r in records:
        jsonschema.validate(r, EVENT_JSON_SCHEMA)
    assert records[0]["stamp_ns"] == T0 + 5 + 7 and records[0]["t_host_ns"] == T0 + 5
    assert records[0]["point"] == [0.31, -0.12, 0.45] and records[1]["flags"] == ["lost"]
    assert records[2]["kind"] == "sensor_lost" and records[2]["source"] == "ft"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**records[0], "point": [0.0, 1.0]}, EVENT_JSON_SCHEMA)


def test_an_event_without_estimate_has_no_markers_and_is_counted():
    view = RosView(load_scene("ur5e"), clock_offset=0)
    out = view.feed(_event(flags=("no_estimate",)))
    assert [m.topic for m in out] == [L.EVENTS] and view.skipped["contact_no_estimate"] == 1


def test_a_lost_stream_shows_in_the_diagnostics():
    view = RosView(load_scene("ur5e"), clock_offset=0)
    view.feed(_judged(np.zeros(6)))
    view.feed(DeviceEvent.make(T0 + 1, "ft", "sensor_lost", "no F/T frame for 0.3 s", {}))
    from diagnostic_msgs.msg import DiagnosticArray
    msg = view.diagnostics(T0 + 2, counters={"frames": 1}, published={"failed:/ftc/events": 2})
    status = {s.name: s for s in deserialize_message(msg.data, DiagnosticArray).status}
    assert status["ftc: F/T ft"].level == bytes([enc.ERROR]) and "lost" in status["ftc: F/T ft"].message
    assert status["ftc: judged frames"].level == bytes([enc.OK])
    assert status["ftc: monitor"].level == bytes([enc.WARN])
    assert {v.key: v.value for v in status["ftc: monitor"].values}["frames"] == "1"
