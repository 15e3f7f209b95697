"""The arm model against hand computations that do not use MuJoCo (leng2016, reference doc numbers)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ftc_hw.model import ArmModel, Contact, Payload
from ftc_hw.scene import load_scene

L1, L2, L3, L4, R = 0.120, 0.150, 0.200, 0.200, 0.040
MASS = np.array([1.629, 1.786, 2.565, 3.180])
G = np.array([0.0, -9.801, 0.0])
Q_PAPER = np.array([np.pi / 6, -np.pi / 6, -np.pi / 4])
# Inertias (body frame, about the CoM) as in leng2016.xml: uniform solid cylinders of radius R.
INERTIA = [np.diag(d) for d in ([0.0026064, 0.0026064, 0.0013032], [0.00406315, 0.00406315, 0.0014288],
                                [0.002052, 0.009576, 0.009576], [0.002544, 0.011872, 0.011872])]


def rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def hand_links(q):
    """(rotation, origin) of link0..link3 in the base frame, from the reference doc's chain."""
    r1 = rz(q[0])
    o1 = np.array([0, 0, L1])
    r2 = r1 @ ry(q[1])
    o2 = o1 + r1 @ np.array([0, 0, L2])
    r3 = r2 @ ry(q[2])
    o3 = o2 + r2 @ np.array([L3, 0, 0])
    return [(np.eye(3), np.zeros(3)), (r1, o1), (r2, o2), (r3, o3)]


def hand_coms(q):
    """Centres of mass: link0 (0,0,60 mm), link1 z = l1 + 69.995 mm, link2/link3 on u2/u3."""
    links = hand_links(q)
    local = [np.array([0, 0, 0.060]), np.array([0, 0, 0.069995]), np.array([0.086256, 0, 0]),
             np.array([0.106906, 0, 0])]
    return [r @ c + o for (r, o), c in zip(links, local, strict=True)]


def hand_gravity_wrench(q):
    """base_on_arm: reading = -(sum of external loads) = -(sum m g, sum c x m g)."""
    coms = hand_coms(q)
    f = -sum(m * G for m in MASS)
    t = -sum(np.cross(c, m * G) for c, m in zip(coms, MASS, strict=True))
    return np.concatenate([f, t])


@pytest.fixture(scope="module")
def leng():
    return ArmModel(load_scene("leng2016"))


def test_paper_pose_force_is_total_weight(leng):
    w = leng.predicted_wrench(Q_PAPER, level="gravity")
    np.testing.assert_allclose(w[:3], [0.0, 9.160 * 9.801, 0.0], atol=1e-9, rtol=0)
    np.testing.assert_allclose(w[3:], hand_gravity_wrench(Q_PAPER)[3:], atol=1e-9, rtol=0)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3))
def test_gravity_wrench_matches_hand(leng, q):
    q = np.clip(q, [-3.1, -2.0, -2.5], [3.1, 2.0, 2.5])
    np.testing.assert_allclose(leng.predicted_wrench(q, level="gravity"), hand_gravity_wrench(q), atol=1e-9)


def test_kinematics_match_hand(leng):
    rng = np.random.default_rng(1)
    for _ in range(50):
        q = rng.uniform(-2, 2, 3)
        links = leng.kinematics(q)
        for name, (r, o) in zip(["link0", "link1", "link2", "link3"], hand_links(q), strict=True):
            np.testing.assert_allclose(links[name][:3, :3], r, atol=1e-12)
            np.testing.assert_allclose(links[name][:3, 3], o, atol=1e-12)
        # the tip: l4 along u3 from joint 3; u3 = (c1 c23, s1 c23, -s23)
        c1, s1, c23, s23 = np.cos(q[0]), np.sin(q[0]), np.cos(q[1] + q[2]), np.sin(q[1] + q[2])
        tip = hand_links(q)[3][1] + L4 * np.array([c1 * c23, s1 * c23, -s23])
        np.testing.assert_allclose(leng.base_T_site(q, "tip")[:3, 3], tip, atol=1e-12)


def test_link2_rises_30_degrees_at_minus_pi_over_6(leng):
    links = leng.kinematics(Q_PAPER)
    u2 = links["link2"][:3, 0]
    assert np.degrees(np.arcsin(u2[2])) == pytest.approx(30.0, abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(point=st.lists(st.floats(-1, 1), min_size=3, max_size=3),
       force=st.lists(st.floats(-200, 200), min_size=3, max_size=3),
       link=st.sampled_from(["link1", "link2", "link3"]))
def test_contact_changes_reading_by_minus_p_minus_c_cross_p(leng, point, force, link):
    c, p = np.array(point), np.array(force)
    base = leng.predicted_wrench(Q_PAPER, level="gravity")
    with_contact = leng.predicted_wrench(Q_PAPER, level="gravity", contacts=[Contact(link, c, p)])
    np.testing.assert_allclose(with_contact - base, np.concatenate([-p, -np.cross(c, p)]), atol=1e-9)


def test_bias_level_is_contacts_only(leng):
    assert np.all(leng.predicted_wrench(Q_PAPER, level="bias") == 0.0)
    c, p = np.array([0.1, 0.2, 0.3]), np.array([3.0, -4.0, 5.0])
    np.testing.assert_allclose(leng.predicted_wrench(Q_PAPER, level="bias", contacts=[Contact("link2", c, p)]),
                               np.concatenate([-p, -np.cross(c, p)]), atol=1e-12)


def test_jacobian_matches_finite_differences(leng):
    rng = np.random.default_rng(2)
    q = rng.uniform(-1, 1, 3)
    point = leng.kinematics(q)["link3"] @ np.array([0.15, 0.02, 0.04, 1.0])
    jac = leng.jacobian(q, "link3", point[:3])
    local = np.linalg.inv(leng.kinematics(q)["link3"]) @ point
    num = np.zeros((3, 3))
    for i in range(3):
        dq = np.zeros(3)
        dq[i] = 1e-6
        plus = (leng.kinematics(q + dq)["link3"] @ local)[:3]
        minus = (leng.kinematics(q - dq)["link3"] @ local)[:3]
        num[:, i] = (plus - minus) / 2e-6
    np.testing.assert_allclose(jac, num, atol=1e-8)


def test_twist_jacobian_moves_every_point_of_the_link(leng):
    """Its positional part is ``jacobian``'s; a point ``r`` away moves at ``J_p + J_r x r`` (``jacobian`` there)."""
    q = np.random.default_rng(3).uniform(-1, 1, 3)
    point = (leng.kinematics(q)["link3"] @ np.array([0.15, 0.02, 0.04, 1.0]))[:3]
    jp, jr = leng.twist_jacobian(q, "link3", point)
    np.testing.assert_allclose(jp, leng.jacobian(q, "link3", point), atol=1e-12)
    r = np.array([-0.05, 0.03, 0.02])
    np.testing.assert_allclose(jp + np.cross(jr.T, r).T, leng.jacobian(q, "link3", point + r), atol=1e-12)


def test_static_joint_torques_match_hand(leng):
    """Gravity torque at each joint = -axis . sum over distal links (c - joint) x m g."""
    q = np.array([0.4, -0.3, 0.8])
    links, coms = hand_links(q), hand_coms(q)
    axes = [links[1][0] @ [0, 0, 1.0], links[2][0] @ [0, 1.0, 0], links[3][0] @ [0, 1.0, 0]]
    tau = []
    for j in range(3):
        origin = links[j + 1][1]
        moment = sum(np.cross(coms[k] - origin, MASS[k] * G) for k in range(j + 1, 4))
        tau.append(-axes[j] @ moment)
    np.testing.assert_allclose(leng.joint_torques(q, level="gravity"), tau, atol=1e-9)
    # a contact force p at c adds -J^T p
    c, p = np.array([0.2, 0.1, 0.4]), np.array([0.0, 10.0, -5.0])
    extra = [-(axes[j] @ np.cross(c - links[j + 1][1], p)) for j in range(3)]
    np.testing.assert_allclose(leng.joint_torques(q, level="gravity", contacts=[Contact("link3", c, p)]),
                               np.array(tau) + extra, atol=1e-9)


def test_dynamics_wrench_matches_hand_newton_euler(leng):
    """base_on_arm reading = dP/dt - m g (force), dL/dt - sum c x m g (torque about the origin).

    P and L come from the hand kinematics along q(t) = q + qd t + qdd t^2/2; their time
    derivatives at t = 0 by central differences.
    """
    q0, qd, qdd = np.array([0.3, -0.5, 0.7]), np.array([1.2, -0.8, 1.5]), np.array([-2.0, 3.0, 1.0])

    def state(t):
        return q0 + qd * t + 0.5 * qdd * t * t, qd + qdd * t

    def momentum(t, h=1e-6):
        q, v = state(t)
        coms = hand_coms(q)
        coms_next = hand_coms(state(t + h)[0])
        coms_prev = hand_coms(state(t - h)[0])
        rots = [r for r, _ in hand_links(q)]
        rots_next = [r for r, _ in hand_links(state(t + h)[0])]
        rots_prev = [r for r, _ in hand_links(state(t - h)[0])]
        lin, ang = np.zeros(3), np.zeros(3)
        for k in range(4):
            vel = (coms_next[k] - coms_prev[k]) / (2 * h)
            rdot = (rots_next[k] - rots_prev[k]) / (2 * h)
            w_hat = rdot @ rots[k].T
            omega = np.array([w_hat[2, 1], w_hat[0, 2], w_hat[1, 0]])
            lin += MASS[k] * vel
            ang += MASS[k] * np.cross(coms[k], vel) + rots[k] @ INERTIA[k] @ rots[k].T @ omega
        return lin, ang

    h = 1e-4
    (p1, l1), (p0, l0) = momentum(h), momentum(-h)
    dp, dl = (p1 - p0) / (2 * h), (l1 - l0) / (2 * h)
    coms = hand_coms(q0)
    expected = np.concatenate([dp - MASS.sum() * G, dl - sum(np.cross(c, m * G) for c, m in zip(coms, MASS,
                                                                                                   strict=True))])
    got = leng.predicted_wrench(q0, qd, qdd, level="dynamics")
    np.testing.assert_allclose(got, expected, atol=2e-5)
    # and the dynamic terms are not negligible here: the test can tell gravity-only from dynamics
    assert np.abs(got - leng.predicted_wrench(q0, level="gravity")).max() > 0.5


def test_payload_adds_its_weight(leng):
    scene = load_scene("leng2016")
    with_payload = ArmModel(scene, Payload(0.5, (0.01, 0.0, 0.02)))
    diff = with_payload.predicted_wrench(Q_PAPER, level="gravity") - leng.predicted_wrench(Q_PAPER, level="gravity")
    flange = leng.base_T_site(Q_PAPER, "flange")
    com = flange[:3, :3] @ np.array([0.01, 0.0, 0.02]) + flange[:3, 3]
    np.testing.assert_allclose(diff, np.concatenate([-0.5 * G, -np.cross(com, 0.5 * G)]), atol=1e-9)


def test_bad_q_is_a_clear_error(leng):
    with pytest.raises(ValueError, match="3 entries"):
        leng.predicted_wrench([0.0, 0.0])
    with pytest.raises(ValueError, match="NaN"):
        leng.predicted_wrench([0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="level"):
        leng.predicted_wrench(Q_PAPER, level="everything")


def test_sensor_pose_is_computed_once_per_q_and_never_stale():
    """base_T_sensor keeps its last q's pose and takes it from the kinematics arm_loads ran at that q;
    another q, another call that poses the data, or set_const (which poses it at qpos0) is never read
    as this q's pose. (On the flange: every built-in scene's sensor is under the base.)"""
    ur5e = load_scene("ur5e")
    scene = replace(ur5e, sensor=replace(ur5e.sensor, site="flange"))
    arm, fresh = ArmModel(scene), ArmModel(scene)
    rng = np.random.default_rng(3)
    for _ in range(20):
        q, qd, qdd = rng.uniform(-2.0, 2.0, size=(3, arm.n_joints))
        want = fresh.base_T_site(q, scene.sensor.site)
        arm.arm_loads(q, qd, qdd, "dynamics")
        got = arm.base_T_sensor(q)
        np.testing.assert_array_equal(got, want)
        assert arm.base_T_sensor(q.copy()) is got  # once per q
        with pytest.raises(ValueError):
            got[0, 3] = 1.0  # shared: read-only
        arm.body_poses(q + 0.5)  # the data now posed elsewhere
        arm.set_const()  # and at qpos0
        q2 = q - 0.25
        arm.arm_loads(q2, qd, qdd, "gravity")
        arm.set_const()
        np.testing.assert_array_equal(arm.base_T_sensor(q2), fresh.base_T_site(q2, scene.sensor.site))
