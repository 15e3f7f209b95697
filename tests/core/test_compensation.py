"""Compensation levels, the qdd estimate, joint-current residuals, detection and link isolation."""
from __future__ import annotations

import mujoco
import numpy as np
import pytest

from ftc_hw.bench import isolation as isolation_bench
from ftc_hw.compensation import Compensator, JointResiduals, QddEstimator
from ftc_hw.detection import ContactDetector, chi2_isf6, chi2_sf6
from ftc_hw.model import ArmModel, Contact
from ftc_hw.pipeline import ContactPipeline
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world import Hold, Probe, ScenarioSetup, Sinusoid, World, build_scenario
from tests.conftest import settings


def test_levels_compute_only_what_they_need(monkeypatch):
    model = ArmModel(load_scene("ur5e"))
    calls = {"inverse": 0, "kinematics": 0}
    real_inverse, real_kin = mujoco.mj_inverse, mujoco.mj_kinematics

    def inverse(m, d):
        calls["inverse"] += 1
        real_inverse(m, d)

    def kinematics(m, d):
        calls["kinematics"] += 1
        real_kin(m, d)

    monkeypatch.setattr(mujoco, "mj_inverse", inverse)
    monkeypatch.setattr(mujoco, "mj_kinematics", kinematics)
    q = np.array(model.scene.robot.home)
    Compensator(model, "bias").external(np.ones(6), q)
    assert calls == {"inverse": 0, "kinematics": 0}
    Compensator(model, "gravity").external(np.ones(6), q)
    assert calls["inverse"] == 0 and calls["kinematics"] == 1
    Compensator(model, "dynamics").external(np.ones(6), q, np.zeros(6), np.zeros(6))
    assert calls["inverse"] == 1


@pytest.mark.parametrize("scene_name", ["ur5e", "dxl-arm", "leng2016"])
def test_dynamics_level_leaves_exactly_the_contact_in_motion(scene_name):
    scene = load_scene(scene_name)
    model = ArmModel(scene)
    setup = build_scenario("sweep-with-collision", scene, model, 0, 3.0)
    world = World(scene, setup, seed=0, noise=False)
    comp = Compensator(model, "dynamics", bias=scene.sensor.bias)
    worst = 0.0
    touched = 0
    for state, reading in world.run(3.0):
        ext = comp.external(reading.wrench - scene.sensor.drift_per_s * state.t, state.q, state.qd, state.qdd)
        contact = model.predicted_wrench(state.q, level="bias",
                                         contacts=[Contact(c.link, c.point, c.force) for c in state.contacts])
        worst = max(worst, float(np.abs(ext - contact).max()))
        touched += bool(state.contacts)
    assert touched > 0
    assert worst < 1e-6 * (1 + np.abs(scene.sensor.range).max()) + np.max(scene.sensor.quantization)


def test_the_identified_gain_is_undone_on_the_contact_s_wrench_too():
    """The sensor reads the arm's loads and the contact through one gain: both are corrected."""
    scene = load_scene("ur5e")
    model = ArmModel(scene)
    rng = np.random.default_rng(3)
    gain = np.eye(6) + rng.normal(0.0, 0.01, (6, 6))
    q, qd, qdd = np.array(scene.robot.home) + 0.3, rng.normal(0, 1, 6), rng.normal(0, 3, 6)
    contact = [Contact("forearm", model.kinematics(q)["forearm"][:3, 3], np.array([20.0, -35.0, 10.0]))]
    loads = model.predicted_wrench(q, qd, qdd, level="dynamics")
    touched = model.predicted_wrench(q, qd, qdd, level="dynamics", contacts=contact)
    bias = rng.normal(0, 2, 6)
    reading = gain @ touched + bias
    want = touched - loads
    corrected = Compensator(model, "dynamics", bias=bias, gain=gain).external(reading, q, qd, qdd)
    np.testing.assert_allclose(corrected, want, atol=1e-9 * np.abs(reading).max())
    left_as_read = Compensator(model, "dynamics", bias=bias).external(reading, q, qd, qdd)
    assert np.abs(left_as_read - want).max() > 0.1  # N or N m: what the gain costs a 40 N contact


def test_gravity_level_misses_the_inertial_load_in_motion():
    scene = load_scene("ur5e")
    model = ArmModel(scene)
    world = World(scene, build_scenario("sweep", scene, model, 0, 2.0), seed=0, noise=False)
    comp = Compensator(model, "gravity", bias=scene.sensor.bias)
    worst = max(float(np.abs(comp.external(r.wrench, s.q)).max()) for s, r in world.run(2.0))
    assert worst > 1.0  # N or N m of unmodelled dynamics: what the bench counts as false alarms


def test_qdd_estimate_lag_and_noise():
    dt, tau = 1e-3, 0.004
    est = QddEstimator(1, tau)
    # velocity ramp: constant acceleration 2 rad/s^2 is recovered exactly after the transient
    for k in range(200):
        a = est.update(k * dt, [2.0 * k * dt])
    assert a[0] == pytest.approx(2.0, rel=1e-9)
    # acceleration ramp (jerk 10): the estimate lags by about tau
    est.reset()
    for k in range(400):
        t = k * dt
        a = est.update(t, [0.5 * 10.0 * t * t])
    lag = (10.0 * 399 * dt - a[0]) / 10.0
    assert lag == pytest.approx(tau, rel=0.05)
    # white velocity noise: the documented gain
    rng = np.random.default_rng(0)
    est.reset()
    out = np.array([est.update(k * dt, rng.normal(0, 0.01, 1))[0] for k in range(20000)])[100:]
    assert out.std() == pytest.approx(0.01 * QddEstimator.noise_gain(dt, tau), rel=0.05)


def test_chi2_functions():
    assert chi2_sf6(12.591587243743977) == pytest.approx(0.05, rel=1e-9)
    assert chi2_sf6(0.0) == 1.0
    for p in (0.5, 1e-3, 1e-9):
        assert chi2_sf6(chi2_isf6(p)) == pytest.approx(p, rel=1e-9)


def test_detector_distance_with_model_error_matches_the_full_covariance():
    """The compiled distance under a per-sample covariance update equals w^T (C + U^T U)^-1 w."""
    rng = np.random.default_rng(11)
    for k in (1, 3, 6):
        a = rng.normal(size=(6, 6))
        cov = a @ a.T + 0.05 * np.eye(6)
        u = rng.normal(size=(k, 6)) * rng.uniform(0.01, 10.0)
        w = rng.normal(size=6) * 5.0
        det = ContactDetector(cov)
        want = float(w @ np.linalg.solve(cov + u.T @ u, w))
        assert det.update(0, w, model_error=u).d2 == pytest.approx(want, rel=1e-9)
        assert det.update(1, w).d2 == pytest.approx(float(w @ np.linalg.solve(cov, w)), rel=1e-9)
    with pytest.raises(ValueError, match="NaN"):
        ContactDetector(np.eye(6)).update(0, np.array([np.nan, 0, 0, 0, 0, 0]), model_error=np.ones((1, 6)))


def test_detector_false_alarm_rate_onset_and_hysteresis():
    cov = np.diag([0.09, 0.09, 0.25, 0.0025, 0.0025, 0.0025])
    det = ContactDetector(cov, p_false=1e-3, n_on=1, n_off=3)
    rng = np.random.default_rng(1)
    noise = rng.multivariate_normal(np.zeros(6), cov, 200_000)
    alarms = 0
    for i, w in enumerate(noise):
        d = det.update(i, w)
        if d.change == "onset":
            alarms += 1
            det.reset()
    assert alarms == pytest.approx(200, rel=0.25)  # p_false per sample
    det = ContactDetector(cov, n_on=2, n_off=3)
    step = np.array([0.0, 0.0, -20.0, 1.0, 0.0, 0.0])
    changes = [det.update(i, step if 10 <= i < 20 else np.zeros(6)).change for i in range(30)]
    assert changes.index("onset") == 11 and det.onset_t_ns is not None
    assert changes.index("offset") == 22
    assert det.update(0, np.zeros(6)).active is False


def test_a_20_newton_step_is_detected_within_two_samples_plus_a_millisecond(contacts):
    scene = load_scene("ur5e")
    model = ArmModel(scene)
    q = np.array(scene.robot.home)
    rng = np.random.default_rng(3)
    delays = []
    for sp, _ in contacts(model, q, 10, seed=5, max_angle_deg=30):
        local = np.linalg.inv(model.kinematics(q)[sp.link]) @ np.append(sp.point, 1.0)
        probe = Probe(sp.link, local[:3], -sp.normal, 20.0, t_start=0.3 + rng.uniform(0, 1e-3), ramp_s=1e-9,
                      hold_s=0.1)
        world = World(scene, ScenarioSetup(Hold(q), probes=(probe,)), seed=int(rng.integers(1000)))
        pipe = ContactPipeline(scene)
        pipe.motion.compensator.bias = scene.sensor.bias.copy()
        for state, reading in world.run(0.45):
            r = pipe.process(int(round(state.t * 1e9)), reading.wrench - scene.sensor.drift_per_s * state.t,
                             state.q, state.qd, world.read_current(state))
            if any(e.kind == "onset" for e in r.events):
                assert state.t >= probe.t_start - 1e-9, "alarm before the contact"
                delays.append(state.t - probe.t_start)
                break
    period = 1.0 / scene.sensor.rate_hz
    assert len(delays) == 10
    assert max(delays) <= 2 * period + 1e-3


@pytest.mark.parametrize("scene_name", ["ur5e", "dxl-arm"])
def test_motor_currents_minus_model_and_friction_leave_nothing_in_free_motion(scene_name):
    """The world's joint friction is the scene's Coulomb + viscous law (light wrist joints included),
    so the residual of every joint is zero while it slides, to a small fraction of its std."""
    scene = load_scene(scene_name)
    model = ArmModel(scene)
    residuals = JointResiduals(scene)
    motion = Sinusoid(np.array(scene.robot.home), np.full(scene.n_joints, 0.1), 0.25)
    world = World(scene, ScenarioSetup(motion), seed=1)
    for state, _ in world.run(1.0):  # noqa: B007 - every joint at full speed at t = 1 s
        pass
    _, model_tau = model.arm_loads(state.q, state.qd, state.qdd, level="dynamics", joint_torques=True)
    tau_ext, tau_std = residuals.external_torques(model_tau, state.current, state.qd)
    assert np.all(np.abs(state.qd) > 0.1)
    assert np.all(np.abs(tau_ext) < 0.05 * tau_std), tau_ext / tau_std


@pytest.mark.parametrize("scene_name", ["ur5e", "dxl-arm"])
def test_currents_isolate_the_link_when_the_force_line_crosses_two(scene_name):
    """The arm moves while a probe pushes a point whose force line also crosses another link (the
    world simulates the motor currents): without currents every such estimate is flagged
    ``ambiguous``; with them the right link wins whenever the two links' torque signatures differ by
    more than 4 sigma, and a wrong link is rarely given without a flag (ftc bench isolation)."""
    r = isolation_bench.evaluate(scene_name, n_cases=1500, seed=7, max_discriminable=20)
    assert r["discriminable"] >= 20, r
    assert r["ambiguous_without"] == r["two_link"], r
    assert r["discriminable_right"] >= 0.95 * r["discriminable"], r
    assert r["wrong"] <= 0.1 * r["two_link"], r
    # where a joint separates the two links, the currents pick the right one (ftc bench isolation,
    # 2000 cases: ur5e 96 %, dxl-arm 99.8 %); welded parts (rigid) would have nothing to tell them apart
    assert r["jointed_right_share"] >= 0.9, r
    # dxl-arm's fingers ride on the gripper joint: no pair of its links is rigid (they were, welded)
    assert r["rigid"] == 0, r


def test_the_lag_error_sees_a_pulse_whose_ends_agree():
    """The acceleration estimate rises by 0.2 rad/s^2 and falls back within the 4 ms window: the
    change across the window is zero, the lag error is not (the estimate still lags by the pulse)."""
    scene = load_scene("leng2016")
    pipe = ContactPipeline(scene, settings(level="dynamics"))
    n = scene.n_joints
    pulse = [0.0, 0.1, 0.2, 0.1, 0.0]
    out = [pipe.motion._lag_errors(i * 1_000_000, np.full(n, a))[0] for i, a in enumerate(pulse)]
    assert out[0] is None  # nothing to compare with yet
    assert out[-1] is not None and np.allclose(out[-1], pipe.motion.lag_gain * 0.2)
    # a still arm: no lag error, no inverse dynamics spent on it
    still = ContactPipeline(scene, settings(level="dynamics"))
    assert all(still.motion._lag_errors(i * 1_000_000, np.zeros(n)) == (None, None) for i in range(10))
    # a sparse stream (100 Hz, longer than the window) still compares with its previous sample
    sparse = ContactPipeline(scene, settings(level="dynamics"))
    sparse.motion._lag_errors(0, np.zeros(n))
    assert np.allclose(sparse.motion._lag_errors(10_000_000, np.full(n, 0.5))[0], sparse.motion.lag_gain * 0.5)


def test_the_detector_s_lag_window_holds_three_samples_of_a_slow_sensor():
    """dxl-arm's F/T sensor samples at 100 Hz: a change of the acceleration estimate one sample back
    (a joint that stuck at a reversal) is still in the detector's lag error while the arm's wrench
    still shows it; a window of 2 tau (4 ms) forgot it one sample later and a stick raised a 7-sigma
    false alarm. The solver's lag error keeps 2 tau (a longer one cost localization)."""
    scene = load_scene("dxl-arm")
    assert scene.sensor.rate_hz == 100.0
    pipe = ContactPipeline(scene, settings(level="dynamics"))
    n = scene.n_joints
    step = [np.zeros(n)] + [np.full(n, 0.5)] * 5
    out = [pipe.motion._lag_errors(i * 10_000_000, a) for i, a in enumerate(step)]
    assert np.allclose(out[1][0], pipe.motion.lag_gain * 0.5) and np.allclose(out[1][1], pipe.motion.lag_gain * 0.5)
    for k in (2, 3, 4):  # one, two, three samples later: held (the window and the newest sample before it)
        assert out[k][1] is not None and np.allclose(out[k][1], pipe.motion.lag_gain * 0.5), k
        assert out[k][0] is None, k  # the solver's: the previous sample only
    assert out[5][1] is None  # the step has left the window: no lag left
    fast = ContactPipeline(load_scene("ur5e"), settings(level="dynamics"))  # 1 kHz: 2 tau holds three samples
    assert fast.motion._judge_window_ns == fast.motion.lag_window_ns


def test_the_compiled_per_frame_steps_give_numpy_s_numbers_to_the_bit():
    """The acceleration filter's step and the lag model's rows, against the numpy expressions they replaced
    (a fused multiply-add or a reordering would show in the last bits; a row's sign of zero too)."""
    import math

    from ftc_hw.compensation.kernels import lag_rows, qdd_step

    rng = np.random.default_rng(1)
    for _ in range(2000):
        a, qd_prev = rng.normal(0, 10, 6) * 10.0 ** rng.integers(-6, 4), rng.normal(0, 1, 6)
        qd = qd_prev + rng.normal(0, 1e-3, 6)
        dt = float(rng.uniform(1e-5, 1e-2))
        alpha = math.exp(-dt / 0.002)
        want = alpha * a + (1.0 - alpha) * (qd - qd_prev) / dt
        state, prev, out = a.copy(), qd_prev.copy(), np.empty(6)
        qdd_step(state, prev, qd, alpha, dt, out)
        assert np.array_equal(want.view(np.int64), out.view(np.int64))
        assert np.array_equal(state, out) and np.array_equal(prev, qd)
        g, lag = rng.normal(0, 1, (6, 6)), rng.normal(0, 0.05, 6)
        rows = np.ascontiguousarray((g * np.where(np.abs(lag) >= 0.02, lag, 0.0)).T)
        got = lag_rows(np.ascontiguousarray(g.T), lag, 0.02)
        assert got.flags.c_contiguous and np.array_equal(rows.view(np.int64), got.view(np.int64))
