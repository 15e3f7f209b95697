"""ROS messages to the scene's arrays (ftc_hw.app.ros.decode) and a stream's sequence from its stamps
(ftc_hw.app.ros.stamps): the same decoding on rclpy's message objects and on rosbags' (a bag's), joints
matched by name whatever their order, bad input named."""
from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import WrenchStamped
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState

from ftc_hw.app.ros import decode as d
from ftc_hw.app.ros.stamps import StampSequence

pytestmark = pytest.mark.compute

SCENE = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint")
# the order ros2_control's joint_state_broadcaster may send (its map's, not the robot description's)
SENT = ("elbow_joint", "shoulder_lift_joint", "shoulder_pan_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint")
STAMP = 1_700_000_123_456_789_012


def rclpy_joint_state(names=SENT, effort=True):
    msg = JointState(name=list(names), position=[float(i) for i in range(len(names))],
                     velocity=[10.0 + i for i in range(len(names))],
                     effort=[100.0 + i for i in range(len(names))] if effort else [])
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(STAMP, 10**9)
    return msg


def rosbags_joint_state(names=SENT):
    ts = get_typestore(Stores.LATEST)
    Time, Header, JS = ts.types["builtin_interfaces/msg/Time"], ts.types["std_msgs/msg/Header"], \
        ts.types["sensor_msgs/msg/JointState"]
    n = len(names)
    sec, nsec = divmod(STAMP, 10**9)
    return JS(header=Header(stamp=Time(sec=sec, nanosec=nsec), frame_id=""), name=list(names),
              position=np.arange(n, dtype=float), velocity=10.0 + np.arange(n), effort=100.0 + np.arange(n))


@pytest.mark.parametrize("make", [rclpy_joint_state, rosbags_joint_state], ids=["rclpy", "rosbags"])
def test_a_joint_state_comes_out_in_the_scene_s_order_by_name(make):
    msg = make()
    q, qd, eff = d.joint_arrays(msg, d.joint_index(msg.name, SCENE), effort="current")
    # shoulder_pan was sent third (position 2), elbow first (position 0)
    np.testing.assert_array_equal(q, [2.0, 1.0, 0.0, 3.0, 4.0, 5.0])
    np.testing.assert_array_equal(qd, [12.0, 11.0, 10.0, 13.0, 14.0, 15.0])
    np.testing.assert_array_equal(eff, [102.0, 101.0, 100.0, 103.0, 104.0, 105.0])
    assert d.stamp_ns(msg.header) == STAMP


def test_missing_and_repeated_joint_names_are_named_never_mixed_up():
    with pytest.raises(d.JointNamesError, match="no joint wrist_3_joint"):
        d.joint_index(SENT[:5], SCENE)
    with pytest.raises(d.JointNamesError, match="elbow_joint named twice"):
        d.joint_index((*SENT, "elbow_joint"), SCENE)
    # a prefixed driver (tf_prefix) without the mapping: every joint missing, said
    with pytest.raises(d.JointNamesError, match="no joint shoulder_pan_joint"):
        d.joint_index(tuple("ur_" + n for n in SENT), SCENE)
    # a gripper's fingers beside the arm: left out, and said
    names = (*SENT, "finger_joint")
    assert d.extra_joints(names, SCENE) == ["finger_joint"]
    np.testing.assert_array_equal(d.joint_index(names, SCENE), [2, 1, 0, 3, 4, 5])


def test_arrays_of_the_wrong_length_and_a_missing_effort_are_refused():
    msg = rclpy_joint_state()
    index = d.joint_index(msg.name, SCENE)
    msg.velocity = [0.0] * 5
    with pytest.raises(d.RosInputError, match="velocity has 5 values for 6 joint names"):
        d.joint_arrays(msg, index, effort="none")
    no_effort = rclpy_joint_state(effort=False)
    with pytest.raises(d.RosInputError, match="effort has 0 values"):
        d.joint_arrays(no_effort, index, effort="torque")
    assert d.joint_arrays(no_effort, index, effort="none")[2] is None


def test_nan_is_found_where_ros2_control_puts_it():
    msg = rclpy_joint_state()
    msg.effort[3] = float("nan")  # an interface the hardware lacks
    q, qd, eff = d.joint_arrays(msg, d.joint_index(msg.name, SCENE), effort="torque")
    assert d.non_finite(position=q, velocity=qd, effort=eff) == ["effort"]
    assert d.non_finite(position=q, velocity=qd, effort=None) == []


@pytest.mark.parametrize("store", ["rclpy", "rosbags"])
def test_a_wrench_and_its_frame(store):
    if store == "rclpy":
        msg = WrenchStamped()
        msg.header.frame_id = "ft_sensor"
        f, t = msg.wrench.force, msg.wrench.torque
        f.x, f.y, f.z, t.x, t.y, t.z = 1.0, 2.0, -202.0, 0.1, 0.2, 0.3
    else:
        ts = get_typestore(Stores.LATEST)
        V = ts.types["geometry_msgs/msg/Vector3"]
        msg = ts.types["geometry_msgs/msg/WrenchStamped"](
            header=ts.types["std_msgs/msg/Header"](stamp=ts.types["builtin_interfaces/msg/Time"](sec=1, nanosec=2),
                                                   frame_id="ft_sensor"),
            wrench=ts.types["geometry_msgs/msg/Wrench"](force=V(x=1.0, y=2.0, z=-202.0), torque=V(x=0.1, y=0.2, z=0.3)))
    np.testing.assert_array_equal(d.wrench_array(msg), [1.0, 2.0, -202.0, 0.1, 0.2, 0.3])
    d.check_frame(msg, "ft_sensor")
    with pytest.raises(d.FrameIdError, match="frame 'ft_sensor', not the scene's sensor frame 'tool0_controller'"):
        d.check_frame(msg, "tool0_controller")


def test_the_sequence_counts_messages_and_the_ones_missing_between_stamps():
    period = 2_000_000  # 500 Hz
    seq = StampSequence(period)
    t = [0, 1, 2, 5, 6]  # periods: 3 and 4 missing
    steps = [seq.update(STAMP + k * period) for k in t]
    assert [s.seq for s in steps] == [0, 1, 2, 5, 6] and [s.lost for s in steps] == [0, 0, 0, 2, 0]
    # jitter of under half a period is no gap
    assert seq.update(STAMP + 7 * period + period // 3).lost == 0
    assert seq.update(STAMP + 7 * period + period // 3).duplicate
    back = seq.update(STAMP)  # the driver restarted its clock
    assert back.backwards and back.seq == 8 and back.lost == 0
    assert seq.update(STAMP + period).seq == 9  # the new epoch goes on from there
    # without a rate: the message count only
    plain = StampSequence()
    assert [plain.update(s).seq for s in (10, 5_000_000_000, 5_000_000_001)] == [0, 1, 2]
