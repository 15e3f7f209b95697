"""The world and the model for every sensing a scene may declare (issue 37): no F/T sensor, an F/T
sensor at the flange, joint torque sensors. Tolerances are measured on this code (ideal world, noise
off): the world's physics is the model's, so its F/T reading and joint torques match the model to
rounding (1e-14 N m measured; the tests allow 1e-9)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ftc_hw.model import ArmModel, Contact, Payload, sample_rate_hz
from ftc_hw.scene import JointTorqueSpec, SceneError, load_scene
from ftc_hw.sim_devices.runner import SimRunner
from ftc_hw.sim_devices.world import Hold, Probe, ScenarioSetup, Sinusoid, World

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

UR5E = load_scene("ur5e")
N = UR5E.n_joints
HOME = np.array(UR5E.robot.home)
SWEEP = Sinusoid(HOME, np.array([0.6, 0.4, 0.5, 0.8, 0.8, 1.0]), 0.4)
EXACT = 1e-9  # N, N m: the world's physics is the model's (measured 1e-14)
FOREARM_PUSH = Probe("forearm", np.array([0.2, 0.0, 0.05]), np.array([0.0, 0.6, -0.8]), 40.0, t_start=0.3)


def _torque_sensors(**kw) -> JointTorqueSpec:
    values = {"noise_std": np.zeros(N), "range": np.full(N, 1e4), "offset": np.zeros(N)} | kw
    return JointTorqueSpec(**values)


def _flange_scene():
    """ur5e with its F/T sensor between the flange and the tool (UR e-Series' own sensor's place)."""
    sensor = dataclasses.replace(UR5E.sensor, site="flange", mount="flange",
                                 range=np.array([200.0, 200.0, 200.0, 10.0, 10.0, 10.0]))
    return dataclasses.replace(UR5E, sensor=sensor)


# -- no F/T sensor ------------------------------------------------------------------------------------

def test_a_world_without_an_f_t_sensor_samples_at_the_joints_rate_and_sees_every_contact():
    scene = dataclasses.replace(UR5E, sensor=None)
    assert sample_rate_hz(scene) == 500.0  # the UR arm device's RTDE frequency
    assert sample_rate_hz(dataclasses.replace(scene, joint_torque=_torque_sensors(rate_hz=1000.0))) == 1000.0
    assert sample_rate_hz(dataclasses.replace(scene, devices=())) == 1000.0
    world = World(scene, ScenarioSetup(Hold(HOME), probes=(FOREARM_PUSH,)), noise=False)
    assert world.sensor is None and world.steps_per_sample == 4
    samples = list(world.run(0.4))
    assert len(samples) == 200 and all(reading is None and state.wrench is None for state, reading in samples)
    touched = [c for state, _ in samples for c in state.contacts]
    assert touched and {c.link for c in touched} == {"forearm"}
    with pytest.raises(SceneError, match="no F/T sensor"):
        world.read_sensor()
    assert np.array_equal(world.read_joint_torques(), np.zeros(N))  # no joint torque sensors either


def test_the_model_without_an_f_t_sensor_gives_joint_torques_and_refuses_a_wrench():
    model = ArmModel(dataclasses.replace(UR5E, sensor=None))
    full = ArmModel(UR5E)
    np.testing.assert_allclose(model.joint_torques(HOME), full.joint_torques(HOME), atol=EXACT)
    assert model.sensor_body is None and model.total_mass == pytest.approx(full.total_mass)
    with pytest.raises(SceneError, match="no F/T sensor"):
        model.predicted_wrench(HOME)
    with pytest.raises(SceneError, match="no F/T sensor"):
        model.arm_loads(HOME, level="gravity")


def test_a_runner_without_an_f_t_sensor_publishes_joints_only():
    runner = SimRunner(dataclasses.replace(UR5E, sensor=None), "hold", duration=0.1, noise=False)
    try:
        assert runner.link.ft is None and runner.link.info.ft_ring is None
        reader = runner.link.joints
        before = reader.written
        runner.run(realtime=False)
        assert reader.written - before == 200  # every physics step (0.5 ms) of 0.1 s
    finally:
        runner.stop()


# -- a flange F/T sensor ------------------------------------------------------------------------------

def test_a_flange_sensor_reads_the_payload_and_its_contacts_only_as_the_model_predicts():
    scene = _flange_scene()
    payload = Payload(1.2, (0.01, -0.02, 0.06))
    model = ArmModel(scene, payload=payload)
    assert model.total_mass == pytest.approx(1.2)  # it carries the payload, not the arm
    on_payload = Probe("ftc_payload", np.array([0.0, 0.0, 0.08]), np.array([1.0, 0.0, 0.0]), 10.0, t_start=0.8)
    for trajectory in (Hold(HOME), SWEEP):
        world = World(scene, ScenarioSetup(trajectory, probes=(FOREARM_PUSH, on_payload), payload=payload),
                      noise=False)
        links = set()
        for state, _ in world.run(1.3):
            beyond = [Contact(c.link, c.point, c.force) for c in state.contacts if c.link == "ftc_payload"]
            links |= {c.link for c in state.contacts}
            predicted = model.predicted_wrench(state.q, state.qd, state.qdd, "dynamics", contacts=beyond)
            np.testing.assert_allclose(state.wrench, predicted, atol=EXACT)
            if isinstance(trajectory, Hold) and state.t < FOREARM_PUSH.t_start:  # at rest: the payload's weight
                static = model.predicted_wrench(state.q, level="gravity")
                np.testing.assert_allclose(state.wrench, static, atol=1e-3)
        assert links == {"forearm", "ftc_payload"}  # the truth has both: the reading only the payload's


def test_the_flange_sensor_does_not_feel_a_push_on_the_arm():
    scene = _flange_scene()
    quiet = World(scene, ScenarioSetup(Hold(HOME)), noise=False)
    pushed = World(scene, ScenarioSetup(Hold(HOME), probes=(FOREARM_PUSH,)), noise=False)
    gap = 0.0
    for (a, _), (b, _) in zip(quiet.run(0.5), pushed.run(0.5), strict=True):
        gap = max(gap, float(np.abs(b.q - a.q).max()))
        if b.contacts:  # the push moves the arm a little: the reading changes only by that motion
            assert np.abs(b.wrench - a.wrench).max() < 0.05
    assert gap > 0  # the push did reach the arm


# -- joint torque sensors -----------------------------------------------------------------------------

def test_joint_torques_are_the_inverse_dynamics_and_a_contact_is_its_external_torque():
    scene = dataclasses.replace(UR5E, joint_torque=_torque_sensors())
    model = ArmModel(scene)
    world = World(scene, ScenarioSetup(SWEEP, probes=(FOREARM_PUSH,)), noise=False)
    free, touched = [], []
    for state, _ in world.run(0.8):
        residual = state.tau_j - model.joint_torques(state.q, state.qd, state.qdd)
        assert np.array_equal(world.read_joint_torques(state), state.tau_j)  # no offset, noise or clip here
        if state.contacts:
            c = state.contacts[0]
            touched.append(residual + model.jacobian(state.q, c.link, c.point).T @ c.force)
        else:
            free.append(residual)
    assert len(free) > 100 and len(touched) > 100
    assert np.abs(free).max() < EXACT and np.abs(touched).max() < EXACT
    friction = state.tau - state.tau_j  # the sweep moves every joint: its friction is what it does not transmit
    assert np.all(np.abs(friction) > 0.5)


def test_joint_torque_readings_carry_the_offset_noise_and_range():
    spec = _torque_sensors(noise_std=np.full(N, 0.05), range=np.full(N, 20.0), offset=np.linspace(-1, 1, N))
    scene = dataclasses.replace(UR5E, joint_torque=spec)
    world = World(scene, ScenarioSetup(Hold(HOME)), seed=3)
    states = [state for state, _ in world.run(0.5)]
    true = np.array([s.tau_j for s in states])
    read = np.array([world.read_joint_torques(s) for s in states])
    inside = np.all(np.abs(true + spec.offset) < 20.0 - 0.5, axis=0)  # joints whose load stays within range
    assert 0 < inside.sum() < N  # ur5e's shoulder holds more than 20 N m at home: it is clipped
    errors = (read - true)[:, inside]
    np.testing.assert_allclose(errors.mean(axis=0), spec.offset[inside], atol=0.02)
    np.testing.assert_allclose(errors.std(axis=0), 0.05, rtol=0.2)
    clipped = np.abs(true + spec.offset).min(axis=0) > 20.0 + 6 * 0.05  # beyond the range by 6 sigma of noise
    assert clipped.sum() == 2 and np.all(np.abs(read[:, clipped]) == 20.0)  # shoulder lift and elbow
