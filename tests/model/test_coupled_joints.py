"""A scene joint that drives several model joints: dxl-arm's gripper servo turning both fingers' racks
(0.015 m per rad each, left along +y of link5, right along -y)."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.model import ArmModel, Contact
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world import Hold, Probe, ScenarioSetup, Sinusoid, World

RATIO = 0.015  # m of each finger per rad of the gripper servo
SCENE = load_scene("dxl-arm")
HOME = np.array(SCENE.robot.home)


@pytest.fixture(scope="module")
def arm():
    return ArmModel(SCENE)


def _finger_point(arm, q, link):
    return (arm.kinematics(q)[link] @ np.array([0.035, 0.004 if "left" in link else -0.004, 0.01, 1.0]))[:3]


def test_the_gripper_joint_moves_both_fingers_apart(arm):
    q = HOME.copy()
    closed = arm.kinematics(q)
    q[4] = 0.8
    opened = arm.kinematics(q)
    y5 = closed["link5"][:3, 1]
    np.testing.assert_allclose(opened["gripper_left_link"][:3, 3] - closed["gripper_left_link"][:3, 3],
                               0.8 * RATIO * y5, atol=1e-12)
    np.testing.assert_allclose(opened["gripper_right_link"][:3, 3] - closed["gripper_right_link"][:3, 3],
                               -0.8 * RATIO * y5, atol=1e-12)
    np.testing.assert_allclose(opened["link5"], closed["link5"], atol=1e-15)
    lo, hi = arm.joint_limits()  # the URDF's -10..19 mm per finger, in servo radians
    assert (lo[4], hi[4]) == pytest.approx((-0.010 / RATIO, 0.019 / RATIO))


@pytest.mark.parametrize("link", ["gripper_left_link", "gripper_right_link", "link5"])
def test_jacobian_over_the_scene_joints_matches_finite_differences(arm, link):
    q = HOME + np.array([0.3, 0.2, -0.1, 0.4, 0.5])
    point = _finger_point(arm, q, link)
    local = np.linalg.inv(arm.kinematics(q)[link]) @ np.append(point, 1.0)
    num = np.zeros((3, 5))
    for i in range(5):
        dq = np.zeros(5)
        dq[i] = 1e-6
        num[:, i] = ((arm.kinematics(q + dq)[link] @ local)[:3] - (arm.kinematics(q - dq)[link] @ local)[:3]) / 2e-6
    np.testing.assert_allclose(arm.jacobian(q, link, point), num, atol=1e-8)


def test_a_finger_push_loads_the_gripper_servo_by_ratio_times_its_force_along_the_rack(arm):
    q = HOME.copy()
    y5 = arm.kinematics(q)["link5"][:3, 1]
    force = np.array([3.0, -20.0, 5.0])
    for link, sign in (("gripper_left_link", 1.0), ("gripper_right_link", -1.0)):
        tau = arm.joint_torques(q, level="bias", contacts=[Contact(link, _finger_point(arm, q, link), force)])
        # the servo holds the finger against the push: -J^T f, J's gripper column = ratio x the rack's axis
        assert tau[4] == pytest.approx(-sign * RATIO * (y5 @ force), abs=1e-12)
    tau = arm.joint_torques(q, level="bias", contacts=[Contact("link5", _finger_point(arm, q, "link5"), force)])
    assert tau[4] == 0.0


def test_inverse_and_forward_dynamics_agree_on_the_coupled_mass_matrix(arm):
    """contact_acceleration solves C^T M C qdd = (J C)^T f; mj_inverse at that qdd gives back J^T f."""
    q = HOME + np.array([0.2, -0.1, 0.3, -0.2, 0.6])
    point = _finger_point(arm, q, "gripper_right_link")
    force = np.array([1.0, 15.0, -4.0])
    qdd = arm.contact_acceleration(q, "gripper_right_link", point, force)
    assert abs(qdd[4]) > 1.0
    tau = arm.joint_torques(q, np.zeros(5), qdd, "dynamics", [Contact("gripper_right_link", point, force)])
    np.testing.assert_allclose(tau, arm.joint_torques(q, level="gravity"), atol=1e-9)
    # the wrench's qdd Jacobian over the scene joints: the wrench is linear in qdd
    qd = np.array([0.1, -0.2, 0.3, 0.1, -0.4])
    base = arm.predicted_wrench(q, qd, np.zeros(5), "dynamics")
    jac = arm.wrench_qdd_jacobian()
    step = np.array([0.5, -1.0, 2.0, 1.5, 40.0])
    np.testing.assert_allclose(arm.predicted_wrench(q, qd, step, "dynamics") - base, jac @ step, atol=1e-10)


def test_the_world_keeps_the_fingers_together_and_its_gripper_current_carries_a_finger_push():
    """While the gripper moves (kinetic friction, known sign), a 20 N push along the rack on one finger
    shows in the gripper servo's current as ratio x 20 N; the fingers stay coupled."""
    motion = Sinusoid(HOME, np.full(5, 0.1), 0.25)
    probe = Probe("gripper_left_link", np.array([0.035, 0.004, 0.0]), np.array([0.0, -1.0, 0.0]), 20.0,
                  t_start=0.9, ramp_s=0.05, hold_s=0.3)
    arm = ArmModel(SCENE)
    out = {}
    for with_probe in (False, True):
        world = World(SCENE, ScenarioSetup(motion, probes=(probe,) if with_probe else ()), noise=False)
        worst_strain = 0.0
        for state, _ in world.run(1.05):  # noqa: B007 - the last state is the one compared
            jm = world.joints
            left, right = world.data.qpos[jm.qadr[4]], world.data.qpos[jm.qadr[5]]
            worst_strain = max(worst_strain, abs(left - right))
        assert worst_strain < 1e-5  # m
        out[with_probe] = state
    pushed, free = out[True], out[False]
    assert len(pushed.contacts) == 1 and not free.contacts
    c = pushed.contacts[0]
    along_rack = arm.jacobian(pushed.q, c.link, c.point)[:, 4] @ c.force  # N m on the servo
    y5 = arm.kinematics(pushed.q)["link5"][:3, 1]
    assert along_rack == pytest.approx(RATIO * (y5 @ c.force), abs=1e-12)
    assert along_rack == pytest.approx(-20.0 * RATIO, rel=0.01)
    # the servo's extra torque answers the push (the PD and friction states differ a little)
    assert pushed.tau[4] - free.tau[4] == pytest.approx(-along_rack, abs=0.03)


def test_a_held_gripper_holds_its_fingers():
    world = World(SCENE, ScenarioSetup(Hold(HOME + np.array([0, 0, 0, 0, 0.6]))), noise=False)
    for state, _ in world.run(1.0):  # noqa: B007 - the last state is the one we want
        pass
    assert state.q[4] == pytest.approx(0.6, abs=1e-3)
    finger = world.data.qpos[world.joints.qadr[4:6]]
    np.testing.assert_allclose(finger, [0.6 * RATIO] * 2, atol=2e-5)


@pytest.mark.parametrize("pushed", ["gripper_left_link", "gripper_right_link"])
def test_the_gripper_current_tells_which_finger_a_squeeze_line_touched(arm, pushed):
    """A push along the rack axis whose line runs through both fingers' tips: the same moment about
    joints 1-4 either way, so only the gripper servo's torque (+-ratio x the force along its rack)
    tells the fingers apart. Without torques: ambiguous; with them: the right finger, single and batch."""
    from ftc_hw.solver import ContactSolver

    solver = ContactSolver(arm)
    q = HOME.copy()
    link5 = arm.kinematics(q)["link5"]
    y5 = link5[:3, 1]
    inward = -y5 if pushed == "gripper_left_link" else y5
    tip_outside = (link5 @ np.array([0.1168, 0.0, 0.0, 1.0]))[:3] - 0.05 * inward
    kin = arm.kinematics(q)[pushed]
    box = next(s for s in arm.surfaces if s.link == pushed and s.geom.endswith("tip"))
    point = tip_outside + inward * _entry_distance(kin @ box.link_T_geom, box.size, tip_outside, inward)
    force = 20.0 * inward
    contact = [Contact(pushed, point, force)]
    wrench = arm.predicted_wrench(q, level="bias", contacts=contact)
    tau_ext = -arm.joint_torques(q, level="bias", contacts=contact)
    assert abs(tau_ext[4]) == pytest.approx(RATIO * 20.0, abs=1e-9) and np.abs(tau_ext[:4]).max() < 20.0

    blind = solver.solve(wrench, q)
    assert {c.link for c in blind.candidates} >= {"gripper_left_link", "gripper_right_link"}
    assert "ambiguous" in blind.flags
    told = solver.solve(wrench, q, tau_ext=tau_ext)
    assert told.link == pushed and "ambiguous" not in told.flags
    np.testing.assert_allclose(told.point, point, atol=1e-9)
    batch = solver.solve_batch(wrench[None], q[None], tau_ext=tau_ext[None])
    assert solver.links[batch.link[0]] == pushed


def _entry_distance(base_T_box, half, origin, direction):
    """Where a ray enters a box (slab method): the distance from ``origin`` along ``direction``."""
    rot, centre = base_T_box[:3, :3], base_T_box[:3, 3]
    o, d = rot.T @ (origin - centre), rot.T @ direction
    with np.errstate(divide="ignore"):
        t1, t2 = (-half - o) / d, (half - o) / d
    return float(np.max(np.minimum(t1, t2)))
