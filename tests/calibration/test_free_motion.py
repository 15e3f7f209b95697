"""Identification from free motion: the base-wrench regressor is MuJoCo's inverse dynamics, and the
fit gives back what a mismatched arm and sensor do to the readings, from motion alone."""
from __future__ import annotations

import mujoco
import numpy as np
import pytest

from ftc_hw.calibration.free_motion import FreeMotionFit, FreeMotionIdentifier, MotionData, smooth
from ftc_hw.compensation import Compensator
from ftc_hw.model import ArmModel
from ftc_hw.model.inertials import InertialsError, body_params, set_body_params
from ftc_hw.scene import load_scene


@pytest.mark.parametrize("name", ["ur5e", "dxl-arm", "leng2016"])
def test_regressor_times_parameters_is_mujocos_inverse_dynamics(name):
    scene = load_scene(name)
    arm = ArmModel(scene)
    ident = FreeMotionIdentifier(arm, gain=False)
    rng = np.random.default_rng(1)
    rest = []
    for _ in range(5):
        q = np.asarray(scene.robot.home) + rng.normal(size=scene.n_joints) * 0.5
        qd, qdd = rng.normal(size=scene.n_joints), 3 * rng.normal(size=scene.n_joints)
        a, nominal = ident.rows(q, qd, qdd)
        assert np.abs(nominal).max() > 1.0
        # the moving links' parameters explain every motion-dependent part; what is left is the fixed
        # bodies' weight, the same at every pose (the bias absorbs it)
        rest.append(nominal - a[:, 6:] @ ident.pi0)
    np.testing.assert_allclose(rest, [rest[0]] * 5, atol=1e-9)
    if name == "ur5e":  # the 2.9 kg base, read as the arm's load on the sensor
        np.testing.assert_allclose(rest[0], [0, 0, -2.9 * 9.80665, 0, 0, 0], atol=1e-9)


def test_body_parameters_round_trip_and_refuse_what_no_body_has():
    arm = ArmModel(load_scene("ur5e"))
    m = arm.model
    b = m.body("forearm").id
    pi = body_params(m, b)
    set_body_params(m, b, pi)
    np.testing.assert_allclose(body_params(m, b), pi, atol=1e-12)
    bad = pi.copy()
    bad[0] = -1.0
    with pytest.raises(InertialsError, match="mass"):
        set_body_params(m, b, bad)
    bad = pi.copy()
    bad[4] -= 1.0  # Ixx far below what the other two allow
    with pytest.raises(InertialsError, match="rigid"):
        set_body_params(m, b, bad)
    set_body_params(m, b, bad, nearest=True)  # the nearest rigid body instead
    assert np.all(m.body_inertia[b] > 0)


def _motion(arm: ArmModel, gain: np.ndarray, bias: np.ndarray, seconds: float = 60.0, rate: float = 500.0,
            noise: float = 1.0, seed: int = 0) -> MotionData:
    """Every joint on its own sinusoid (an exciting motion), read through ``arm`` (the true arm)."""
    scene = arm.scene
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate)
    amp = rng.uniform(0.3, 0.8, scene.n_joints)
    freq = rng.uniform(0.1, 0.4, scene.n_joints)
    phase = rng.uniform(0, 2 * np.pi, scene.n_joints)
    w = 2 * np.pi * freq
    home = np.asarray(scene.robot.home)
    q = home + amp * np.sin(np.outer(t, w) + phase)
    qd = amp * w * np.cos(np.outer(t, w) + phase)
    qdd = -amp * w * w * np.sin(np.outer(t, w) + phase)
    std = np.sqrt(np.diag(scene.sensor.noise_cov)) * noise
    wrench = np.array([gain @ arm.predicted_wrench(q[k], qd[k], qdd[k]) for k in range(len(t))]) + bias
    return MotionData(t, wrench + rng.normal(size=wrench.shape) * std, q, qd)


def test_fit_recovers_a_mismatched_arm_from_free_motion():
    scene = load_scene("ur5e")
    nominal = ArmModel(scene)
    delta = {"upper_arm": np.array([0.2, 0.02, 0.0, -0.01, 0, 0, 0, 0, 0, 0]),
             "forearm": np.array([-0.1, 0.0, 0.005, 0.0, 0, 0, 0, 0, 0, 0])}
    true_arm = ArmModel(scene, inertials=delta)
    gain = np.eye(6)
    gain[0, 0], gain[3, 4] = 1.01, 0.005
    bias = np.array([3.0, -2.0, 5.0, 0.4, -0.3, 0.1])
    fit = FreeMotionIdentifier(nominal).fit(_motion(true_arm, gain, bias))
    # the nominal model leaves N-level residuals; the fit takes them down to the noise
    assert fit.residual_rms_before[3:].max() > 5 * fit.residual_rms[3:].max()
    assert np.all(fit.residual_rms < 2.0 * np.sqrt(np.diag(scene.sensor.noise_cov)))
    # the identified model predicts a fresh motion as the true arm reads it
    check = _motion(true_arm, gain, bias, seconds=10.0, seed=7, noise=0.0)
    ident = Compensator(ArmModel(scene, inertials=dict(zip(fit.bodies, fit.delta_pi, strict=True))), "dynamics",
                        bias=fit.bias, gain=fit.gain)
    plain = Compensator(nominal, "dynamics", bias=bias)
    qdd = np.gradient(smooth(check.qd, 1), check.t, axis=0)
    err_id, err_plain = [], []
    for k in range(50, len(check.t) - 50, 25):
        err_id.append(ident.external(check.wrench[k], check.q[k], check.qd[k], qdd[k]))
        err_plain.append(plain.external(check.wrench[k], check.q[k], check.qd[k], qdd[k]))
    rms_id = np.sqrt(np.mean(np.square(err_id), axis=0))
    rms_plain = np.sqrt(np.mean(np.square(err_plain), axis=0))
    assert np.linalg.norm(rms_id[3:]) < 0.25 * np.linalg.norm(rms_plain[3:]), (rms_id, rms_plain)
    assert np.linalg.norm(rms_id[:3]) < 0.25 * np.linalg.norm(rms_plain[:3]), (rms_id, rms_plain)
    assert fit.verdict in ("good", "poorly_excited")


def test_a_poor_motion_says_what_it_could_not_tell():
    scene = load_scene("ur5e")
    arm = ArmModel(scene)
    data = _motion(arm, np.eye(6), np.zeros(6), seconds=20.0)
    data.q[:, 1:] = data.q[0, 1:]  # only the base joint turns
    data.qd[:, 1:] = 0.0
    fit = FreeMotionIdentifier(arm).fit(data)
    assert fit.verdict == "poorly_excited" and "not told apart" in fit.reasons[0]
    assert any(lab.startswith("wrist_3.") for lab in fit.untold)


def test_identity_gain_is_the_plain_compensator():
    scene = load_scene("dxl-arm")
    arm = ArmModel(scene)
    q = np.asarray(scene.robot.home)
    z = np.zeros_like(q)
    raw = arm.predicted_wrench(q, z, z) + 0.3
    a = Compensator(arm, "dynamics", bias=np.full(6, 0.3)).external(raw, q, z, z)
    b = Compensator(arm, "dynamics", bias=np.full(6, 0.3), gain=np.eye(6)).external(raw, q, z, z)
    np.testing.assert_allclose(a, b, atol=1e-12)
    assert mujoco.__version__


def _gain_fit(told_terms: list[int], gain: np.ndarray) -> FreeMotionFit:
    """A fit with no bodies whose posterior tells exactly ``told_terms`` of the 36 gain terms."""
    labels = [f"bias[{i}]" for i in range(6)] + [f"gain[{i},{j}]" for i in range(6) for j in range(6)]
    prior = np.full(42, 0.01)
    var = np.full(42, 0.01**2)
    var[[6 + k for k in told_terms]] = (0.1 * 0.01) ** 2
    z = np.zeros(6)
    return FreeMotionFit([], z, np.zeros((0, 10)), gain, np.diag(var), labels, prior, z, z, 0,
                         np.zeros(0), np.zeros((0, 6)), np.zeros((0, 6)))


def test_the_contact_gain_is_the_estimate_where_the_data_told_it():
    rng = np.random.default_rng(3)
    gain = np.eye(6) + rng.normal(0.0, 0.01, (6, 6))
    diagonal = [7 * i for i in range(6)]
    told = [k for k in range(36) if k % 2 == 0] + diagonal
    fit = _gain_fit(told, gain)
    undone = fit.told_gain(min_directions=len(set(told)))
    flat_gain, flat_undone = gain.reshape(-1), undone.reshape(-1)
    for k in range(36):
        expected = flat_gain[k] if k in told else (1.0 if k in diagonal else 0.0)
        assert flat_undone[k] == pytest.approx(expected, abs=1e-12), k
    # too few directions told: nothing undone
    np.testing.assert_array_equal(fit.told_gain(min_directions=len(set(told)) + 1), np.eye(6))
    np.testing.assert_array_equal(_gain_fit(diagonal, gain).told_gain(), np.eye(6))
