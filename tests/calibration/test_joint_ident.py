"""Identification from the joints' own signals: the joint-torque regressor is MuJoCo's inverse dynamics,
a fit on an arm whose inertials, torque constants, friction and torque sensors' offsets differ from the
model gives them back from motion alone, and bad data gives the typed error or verdict."""
from __future__ import annotations

import dataclasses
import json

import mujoco
import numpy as np
import pytest

from ftc_hw.app.calibration.identify_joints import joint_covariance
from ftc_hw.calibration.file import Calibration, Identification, load_calibration, save_calibration
from ftc_hw.calibration.free_motion import IdentificationError
from ftc_hw.calibration.joint_ident import JointIdentifier
from ftc_hw.calibration.joint_motion import V_EPS, JointMotionData
from ftc_hw.model import ArmModel
from ftc_hw.model.build import moves
from ftc_hw.model.inertials import body_params, joint_regressor
from ftc_hw.pipeline import PipelineSettings, pipeline_for
from ftc_hw.scene import load_scene

UR5E = load_scene("ur5e")
DELTA = {"upper_arm": np.array([0.2, 0.02, 0.0, -0.01, 0, 0, 0, 0, 0, 0]),
         "forearm": np.array([-0.1, 0.0, 0.005, 0.0, 0, 0, 0, 0, 0, 0])}


@pytest.mark.parametrize("name", ["ur5e", "dxl-arm", "leng2016"])
def test_joint_regressor_times_parameters_is_mujocos_inverse_dynamics(name):
    scene = load_scene(name)
    arm = ArmModel(scene)
    m = arm.model
    bodies = [b for b in range(1, m.nbody) if moves(m, b)]
    pi0 = np.concatenate([body_params(m, b) for b in bodies])
    d = mujoco.MjData(m)
    c = arm.joints.matrix  # dxl-arm's gripper: one motor, two fingers (and their armature)
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = np.asarray(scene.robot.home) + rng.normal(size=scene.n_joints) * 0.5
        qd, qdd = rng.normal(size=scene.n_joints), 3 * rng.normal(size=scene.n_joints)
        arm.joints.set_qpos(q, d.qpos)
        arm.joints.set_dofs(qd, d.qvel)
        arm.joints.set_dofs(qdd, d.qacc)
        for stage in (mujoco.mj_kinematics, mujoco.mj_comPos, mujoco.mj_comVel, mujoco.mj_rnePostConstraint):
            stage(m, d)
        tau = arm.joint_torques(q, qd, qdd)
        assert np.abs(tau).max() > 0.1
        armature = c.T @ (m.dof_armature * (c @ qdd))
        np.testing.assert_allclose(c.T @ joint_regressor(m, d, bodies) @ pi0 + armature, tau, atol=1e-9)
    ident = JointIdentifier(arm, kinds=["currents"])
    y, nominal = ident.rows(q, qd, qdd)
    np.testing.assert_allclose(nominal, tau, atol=1e-9)
    assert y.shape == (scene.n_joints, 10 * len(bodies))


def _truth():
    r = UR5E.robot
    kt = np.asarray(r.torque_constant) * np.array([1.04, 0.97, 1.02, 0.96, 1.03, 0.99])
    return (ArmModel(UR5E, inertials=DELTA), kt, np.asarray(r.friction_viscous) * 1.3,
            np.asarray(r.friction_coulomb) * 0.8, np.array([0.5, -1.0, 0.3, 0.2, -0.1, 0.05]))


def _motion(true_arm, kt, b, fc, offset, *, seconds=60.0, rate=200.0, seed=0, jitter=0.0,
            current_noise=0.0) -> JointMotionData:
    """Every joint on a sum of sinusoids about home, as the true arm's motors and torque sensors report it."""
    scene = true_arm.scene
    rng = np.random.default_rng(seed)
    n = scene.n_joints
    t = np.arange(0.0, seconds, 1.0 / rate) + rng.uniform(0.0, jitter, int(round(seconds * rate)))
    q = np.tile(np.asarray(scene.robot.home, dtype=float), (len(t), 1))
    qd, qdd = np.zeros_like(q), np.zeros_like(q)
    for _ in range(3):
        amp, w, ph = rng.uniform(0.1, 0.4, n), 2 * np.pi * rng.uniform(0.1, 0.5, n), rng.uniform(0, 2 * np.pi, n)
        s, c = np.sin(np.outer(t, w) + ph), np.cos(np.outer(t, w) + ph)
        q, qd, qdd = q + amp * s, qd + amp * w * c, qdd - amp * w * w * s
    tau = np.array([true_arm.joint_torques(q[k], qd[k], qdd[k]) for k in range(len(t))])
    current = (tau + b * qd + fc * np.tanh(qd / V_EPS)) / kt + rng.normal(size=q.shape) * current_noise
    return JointMotionData(t, q, qd, current, tau + offset)


@pytest.fixture(scope="module")
def ideal_motion():
    return _motion(*_truth())


def _held_out_error(fit, true_arm, kt, b, fc) -> tuple[np.ndarray, np.ndarray]:
    """RMS current error (A) of the identified and of the scene's model on a fresh motion."""
    check = _motion(true_arm, kt, b, fc, 0.0, seconds=5.0, rate=50.0, seed=7)
    qdd = np.gradient(check.qd, check.t, axis=0)
    r = UR5E.robot
    ident = ArmModel(UR5E, inertials=dict(zip(fit.bodies, fit.delta_pi, strict=True)))
    nominal = ArmModel(UR5E)
    err_id, err_nom = [], []
    for k in range(5, len(check.t) - 5):
        q, qd, a = check.q[k], check.qd[k], qdd[k]
        sgn = np.tanh(qd / V_EPS)
        err_id.append((ident.joint_torques(q, qd, a) + fit.friction_viscous * qd + fit.friction_coulomb * sgn
                       + fit.rotor_inertia * a) / fit.torque_constant - check.current[k])
        err_nom.append((nominal.joint_torques(q, qd, a) + r.friction_viscous * qd + r.friction_coulomb * sgn)
                       / r.torque_constant - check.current[k])
    return np.sqrt(np.mean(np.square(err_id), axis=0)), np.sqrt(np.mean(np.square(err_nom), axis=0))


def test_currents_give_back_the_torque_constants_friction_and_what_the_inertials_do(ideal_motion):
    true_arm, kt, b, fc, _ = _truth()
    fit = JointIdentifier(ArmModel(UR5E), kinds=["currents"]).fit(ideal_motion)
    # the common scale is what the vendor's masses' gravity torques and the torque constants' priors say
    # (the true torque constants average 0.2 % above the scene's, the upper arm is 2.4 % heavier): the
    # ratios between the joints are the data's (but wrist 3's, whose load is almost all its own friction)
    ratio = fit.torque_constant / kt
    assert np.all(np.abs(ratio - 1) < 0.02), ratio
    assert np.ptp(ratio[:5]) < 0.005, ratio
    assert fit.scale_std is not None and 0.005 < fit.scale_std < 0.05
    np.testing.assert_allclose(fit.friction_viscous / ratio, b, rtol=0.02, atol=0.01)
    np.testing.assert_allclose(fit.friction_coulomb / ratio, fc, rtol=0.02, atol=0.01)
    before, after = fit.residual_std_before["currents"], fit.residual_std["currents"]
    assert np.all(after < 0.05 * before), (before, after)
    err_id, err_nom = _held_out_error(fit, true_arm, kt, b, fc)
    assert np.all(err_id < 0.05 * err_nom), (err_id, err_nom)
    assert any("common scale" in r for r in fit.reasons)
    # wrist 3's links take 0.03 % of its motor's torque: its torque constant is the scene's, said
    assert "kt_scale[5]" in fit.untold and any("wrist_3_joint" in r for r in fit.reasons)
    assert fit.unidentifiable and all(lab.split(".")[0] in fit.bodies for lab in fit.unidentifiable)


def test_joint_torques_give_back_the_offsets_and_the_inertials_scale_included(ideal_motion):
    true_arm, kt, b, fc, offset = _truth()
    fit = JointIdentifier(ArmModel(UR5E), kinds=["joint_torques"]).fit(ideal_motion)
    np.testing.assert_allclose(fit.offset, offset, atol=0.02)
    assert fit.scale_std is None
    assert np.all(fit.residual_std["joint_torques"] < 0.01)
    # what the motion tells of the links (their joint torques) is the true arm's
    ident = ArmModel(UR5E, inertials=dict(zip(fit.bodies, fit.delta_pi, strict=True)))
    rng = np.random.default_rng(5)
    for _ in range(10):
        q = np.asarray(UR5E.robot.home) + rng.uniform(-0.5, 0.5, 6)
        z = np.zeros(6)
        truth, nominal = true_arm.joint_torques(q, z, z), ArmModel(UR5E).joint_torques(q, z, z)
        assert np.abs(ident.joint_torques(q, z, z) - truth).max() < 0.1 * max(np.abs(nominal - truth).max(), 0.1)


def test_both_signals_tell_the_absolute_torque_constants(ideal_motion):
    _, kt, b, fc, offset = _truth()
    fit = JointIdentifier(ArmModel(UR5E), kinds=["currents", "joint_torques"]).fit(ideal_motion)
    np.testing.assert_allclose(fit.torque_constant / kt, 1.0, atol=0.005)
    np.testing.assert_allclose(fit.friction_viscous, b, atol=0.02)
    np.testing.assert_allclose(fit.offset, offset, atol=0.02)


def test_jittered_slow_stamps_and_bad_rows_are_survived_and_counted():
    true_arm, kt, b, fc, offset = _truth()
    data = _motion(true_arm, kt, b, fc, offset, seconds=40.0, rate=100.0, jitter=0.004)
    data.q[500:510] = np.nan  # ten rows a recording could not read
    data.t[800] = data.t[799]  # a repeated stamp
    fit = JointIdentifier(ArmModel(UR5E), kinds=["joint_torques"]).fit(data)
    assert fit.dropped_rows == 11
    np.testing.assert_allclose(fit.offset, offset, atol=0.05)


def test_no_motion_or_no_usable_rows_is_a_typed_error_or_a_verdict():
    true_arm, kt, b, fc, offset = _truth()
    data = _motion(true_arm, kt, b, fc, offset, seconds=20.0, rate=100.0)
    still = dataclasses.replace(data, q=np.tile(data.q[0], (len(data.t), 1)), qd=np.zeros_like(data.qd))
    still.current = np.tile(data.current[0], (len(data.t), 1))
    with pytest.raises(IdentificationError, match="usable samples"):
        JointIdentifier(ArmModel(UR5E), kinds=["currents"]).fit(still)  # friction holds anything at rest
    fit = JointIdentifier(ArmModel(UR5E), kinds=["joint_torques"]).fit(still)
    assert fit.verdict == "poorly_excited" and "not told apart" in fit.reasons[0]
    broken = dataclasses.replace(data, current=np.full_like(data.current, np.nan))
    with pytest.raises(IdentificationError, match="no usable stretch"):
        JointIdentifier(ArmModel(UR5E), kinds=["currents"]).fit(broken)
    with pytest.raises(IdentificationError, match="no joint torques"):
        JointIdentifier(ArmModel(UR5E), kinds=["joint_torques"]).fit(dataclasses.replace(data, tau_j=None))
    with pytest.raises(IdentificationError, match="no joint signal"):
        JointIdentifier(ArmModel(UR5E.with_sensing(["base_ft"])))


def test_the_joint_identification_reaches_the_pipeline_through_the_file(tmp_path, ideal_motion):
    fit = JointIdentifier(ArmModel(UR5E), kinds=["currents", "joint_torques"]).fit(ideal_motion)
    joints = {"torque_constant": fit.torque_constant, "friction_viscous": fit.friction_viscous,
              "friction_coulomb": fit.friction_coulomb, "rotor_inertia": fit.rotor_inertia,
              "torque_offset": fit.offset}
    nb = len(fit.bodies)
    ident = Identification("2026-01-01", "test", fit.verdict, fit.reasons, np.eye(6),
                           dict(zip(fit.bodies, fit.delta_pi, strict=True)), fit.untold, {}, joints,
                           fit.cov[:10 * nb, :10 * nb], False, None, "currents,joint_torques",
                           fit.residual_std, fit.noise_std)
    cal = Calibration("ur5e", None, "2026-01-01", np.zeros(6), None, identification=ident)
    back = load_calibration(save_calibration(cal, tmp_path / "cal.toml"), scene=UR5E).corrections(UR5E)
    np.testing.assert_allclose(back.joints["torque_offset"], fit.offset)
    assert np.any(back.joints["torque_offset"] < 0)  # an offset has either sign
    np.testing.assert_allclose(back.joint_residual_std["currents"], fit.residual_std["currents"])
    assert back.model_error.cov.shape == (10 * nb, 10 * nb) and not back.model_error.gain
    # identify_joints keeps the joint terms' rows: the pipeline's residual covariance needs them
    cov, keys = joint_covariance(fit, np.asarray(UR5E.robot.torque_constant, dtype=float))
    full = load_calibration(save_calibration(Calibration("ur5e", None, "2026-01-01", np.zeros(6), None,
                                                         identification=dataclasses.replace(
                                                             ident, covariance=cov, covariance_joints=keys)),
                                             tmp_path / "full.toml"), scene=UR5E).corrections(UR5E)
    assert full.model_error.joints == keys == ("torque_constant", "friction_viscous", "friction_coulomb",
                                               "rotor_inertia", "torque_offset")
    assert full.model_error.cov.shape == (10 * nb + 30, 10 * nb + 30)
    np.testing.assert_allclose(full.model_error.body_cov, back.model_error.cov)
    pipe = pipeline_for(UR5E.with_sensing(["currents"]), PipelineSettings(corrections=full))
    assert pipe.residual.model_error.joints == keys and pipe.residual.model_error.source == "currents"
    again = PipelineSettings.from_json(PipelineSettings(corrections=full).to_json()).corrections
    assert again.model_error.joints == keys
    settings = PipelineSettings(corrections=back)
    again = PipelineSettings.from_json(settings.to_json()).corrections
    np.testing.assert_allclose(again.joint_residual_std["joint_torques"], fit.residual_std["joint_torques"])
    # settings recorded before these fields existed still read
    data = json.loads(settings.to_json())
    for k in ("joint_residual_std", "joint_noise_std"):
        del data["corrections"][k]
    assert PipelineSettings.from_json(json.dumps(data)).corrections.joint_residual_std is None
