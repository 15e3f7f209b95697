"""Contact sensing from joint signals (issue 37): the momentum observer against the world's true external
joint torques, the n-dimensional detector, the localizer from joint torques (a distal contact found, a
proximal one flagged ambiguous), the joint pipeline's bad input, its settings and its choice by sensing."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from ftc_hw.compensation import JointResidual
from ftc_hw.compensation.joint_model_error import JointModelError
from ftc_hw.detection import JointDetector, chi2_isf, chi2_isf6, chi2_sf
from ftc_hw.detection.kernels import nested_quads
from ftc_hw.model import ArmModel
from ftc_hw.model.inertials import body_params
from ftc_hw.pipeline import (
    ContactPipeline,
    JointContactPipeline,
    JointSettings,
    PipelineSettings,
    pipeline_for,
)
from ftc_hw.scene import JointTorqueSpec, SceneError, load_scene
from ftc_hw.sim_devices.world import Probe, ScenarioSetup, Sinusoid, World
from ftc_hw.solver import JointContactSolver

EVERY = 4  # world steps (0.5 ms) per joint sample: UR's 500 Hz


@pytest.fixture(scope="module")
def ur5e_currents():
    return load_scene("ur5e").with_sensing(["currents"])


@pytest.fixture(scope="module")
def ur5e_model(ur5e_currents):
    return ArmModel(ur5e_currents)


@pytest.fixture(scope="module")
def solver(ur5e_model):
    return JointContactSolver(ur5e_model)


@pytest.fixture(scope="module")
def pressed(ur5e_currents, ur5e_model):
    """Every joint sweeping in the ideal world while a probe presses wrist_3 (30 N, 0.9-1.4 s): per joint
    sample, (t, q, qd, current, true J^T f, true contact or None, true qdd)."""
    return _pressed(ur5e_currents, ur5e_model, "wrist_3")[0]


def _pressed(scene, model, link):
    """(rows as ``pressed`` gives them, the world's F/T readings at them or None) for a probe on ``link``."""
    home = np.asarray(scene.robot.home, dtype=float)
    motion = Sinusoid(home, np.full(scene.n_joints, 0.3), 0.25, start_s=0.2)
    # a point on the link's side, pushed inward, within its surface (the link frame's primitive)
    surf = next(s for s in model.surfaces if s.link == link)
    r_geom = surf.link_T_geom[:3, :3]
    radial = r_geom @ np.array([1.0, 0.0, 0.0])
    point = surf.link_T_geom[:3, 3] + surf.size[0] * radial
    q_mid, _, _ = motion.reference(1.15)
    b_T_l = model.kinematics(q_mid)[link]
    direction = -(b_T_l[:3, :3] @ radial)
    probe = Probe(link, point, direction, 30.0, t_start=0.9, ramp_s=0.02, hold_s=0.5, normal_link=radial,
                  geom=surf.geom)
    world = World(scene, ScenarioSetup(motion, probes=(probe,)), seed=3)
    rows, readings = [], []
    for _ in range(int(1.6 / world.dt)):
        s = world.step()
        if world.steps % EVERY:
            continue
        tau = np.zeros(scene.n_joints)
        for c in s.contacts:
            tau += model.jacobian(s.q, c.link, c.point).T @ c.force
        rows.append((s.t, s.q, s.qd, world.read_current(s), tau, s.contacts[0] if s.contacts else None, s.qdd))
        readings.append(world.read_sensor(s).wrench if s.wrench is not None else None)
    return rows, readings


def test_observer_gives_the_true_external_torques_in_the_ideal_world(ur5e_currents, ur5e_model, pressed):
    gain = 60.0
    res = JointResidual(ur5e_currents, ur5e_model, "currents", gain=gain)
    out = []
    for t, q, qd, current, tau, *_ in pressed:
        r, cov, ready = res.update(int(round(t * 1e9)), q, qd, current=current)
        if ready:
            out.append((t, r.copy(), tau, qd, np.sqrt(np.diag(cov))))
    t = np.array([o[0] for o in out])
    r, tau, qd, std = (np.array([o[k] for o in out]) for k in (1, 2, 3, 4))
    # the observer follows tau_ext through a first-order lag of 1/K: the truth through the same lag (the
    # arm's motion turns the contact's torques by up to ~6 N m/s here, 0.1 N m over the lag)
    a = np.exp(-gain * np.diff(t, prepend=t[0]))
    for i in range(1, len(t)):
        tau[i] = a[i] * tau[i - 1] + (1 - a[i]) * 0.5 * (tau[i] + np.array(out[i - 1][2]))
    # in contact, 5 time constants after the ramp, while a joint slides (its friction known) and has for
    # 5 time constants (a joint stuck at a reversal hides a torque within +-f_c: the reported deviation
    # says so): r is J^T f (lagged), within 0.05 N m + 1 % of it
    held = (t > 0.92 + 5 / gain) & (t < 1.4)
    assert np.abs(tau[held]).max() > 3.0  # the contact is there to be seen
    for j in range(r.shape[1]):
        sliding = held & _slid_since(t, qd[:, j], 5 / gain)
        assert sliding.sum() > 30
        assert np.all(np.abs(r[sliding, j] - tau[sliding, j]) <= 0.05 + 0.01 * np.abs(tau[sliding, j]))
    assert np.all(np.abs(r[held] - tau[held]) <= 3.0 * std[held])
    # without contact, while a joint slides (its friction known): zero-mean, within 0.05 N m
    free = (t > 0.5) & (t < 0.88)
    for j in range(r.shape[1]):
        sliding = free & _slid_since(t, qd[:, j], 5 / gain)
        assert sliding.sum() > 20
        assert abs(r[sliding, j].mean()) < 0.02
        assert np.abs(r[sliding, j]).max() < 0.05
    # and the reported deviation covers it everywhere without contact (standstill's friction included)
    assert np.all(np.abs(r[free]) <= 3.0 * std[free])


def _slid_since(t: np.ndarray, qd: np.ndarray, span: float) -> np.ndarray:
    """Samples at which the joint has moved faster than 0.05 rad/s for the last ``span`` s."""
    out = np.zeros(len(t), dtype=bool)
    last_stuck = -np.inf
    for i in range(len(t)):
        if abs(qd[i]) <= 0.05:
            last_stuck = t[i]
        out[i] = t[i] - last_stuck > span
    return out


def test_joint_pipeline_finds_the_distal_contact(ur5e_currents, pressed):
    settings = PipelineSettings(joint=JointSettings(model_rel_std=0.005, friction_rel_std=0.05))
    pipe = JointContactPipeline(ur5e_currents, settings)
    onsets, events = [], []
    for t, q, qd, current, _, truth, _ in pressed:
        res = pipe.process_joints(int(round(t * 1e9)), q, qd, current=current)
        for e in res.events:
            onsets += [t] if e.kind == "onset" else []
            if e.kind in ("onset", "update") and truth is not None:
                events.append((e, truth))
    assert len(onsets) == 1 and 0.9 <= onsets[0] <= 0.93  # within 30 ms of the probe's first newton
    assert events
    for e, truth in events:
        assert e.link == "wrist_3"
        assert "ambiguous" not in e.flags
        assert np.linalg.norm(np.asarray(e.point) - truth.point) < 0.015


def _contact_torques(model, q, link, local_point, force_dir, magnitude):
    b_T_l = model.kinematics(q)[link]
    p = b_T_l[:3, :3] @ local_point + b_T_l[:3, 3]
    f = magnitude * np.asarray(force_dir, dtype=float)
    return p, f, model.jacobian(q, link, p).T @ f


def test_localizes_a_known_distal_contact_from_its_joint_torques(ur5e_model, solver):
    q = np.asarray(ur5e_model.scene.robot.home, dtype=float) + 0.15
    # a candidate point of wrist_3 (six joints move it: a point force is determined), 20 deg off its normal
    k = int(np.flatnonzero(solver.fine.link_of == solver.touch.index("wrist_3"))[7])
    rot = ur5e_model.kinematics(q)["wrist_3"][:3, :3]
    n = rot @ solver.fine.nrm[k]
    side = np.cross(n, [0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0])
    direction = -np.cos(0.35) * n + np.sin(0.35) * side / np.linalg.norm(side)
    p, f, tau = _contact_torques(ur5e_model, q, "wrist_3", solver.fine.loc[k], direction, 40.0)
    cov = np.diag(np.full(6, 0.05**2))
    e = solver.solve(tau, cov, q)
    assert e.contact and e.link == "wrist_3" and "ambiguous" not in e.flags
    assert np.linalg.norm(e.point - p) < 0.01
    assert np.linalg.norm(e.force - f) < 0.1 * 40.0
    # the reported covariance is a covariance, and puts the truth within reach
    assert np.all(np.linalg.eigvalsh(e.cov[:3, :3]) >= 0)
    assert np.linalg.norm(e.point - p) < 3 * np.sqrt(np.trace(e.cov[:3, :3]))


def test_a_contact_on_the_first_links_is_flagged_ambiguous_with_its_candidates(ur5e_model, solver):
    q = np.asarray(ur5e_model.scene.robot.home, dtype=float)
    b_T_l = ur5e_model.kinematics(q)["upper_arm"]
    k = int(np.flatnonzero(solver.coarse.link_of == solver.touch.index("upper_arm"))[3])
    n = b_T_l[:3, :3] @ solver.coarse.nrm[k]
    p, f, tau = _contact_torques(ur5e_model, q, "upper_arm", solver.coarse.loc[k], -n, 60.0)
    e = solver.solve(tau, np.diag(np.full(6, 0.05**2)), q)
    assert e.contact
    assert "ambiguous" in e.flags
    assert len(e.candidate_links) >= 2
    probs = solver.link_probabilities(e)
    assert 0.99 < sum(probs.values()) <= 1.0 + 1e-9 or len(probs) < len(e.candidate_links)
    assert np.isfinite(e.candidate_data).all()


def test_non_finite_input_is_a_flagged_frame(ur5e_currents, pressed):
    pipe = JointContactPipeline(ur5e_currents)
    t, q, qd, current, *_ = pressed[10]
    bad_q = q.copy()
    bad_q[2] = np.nan
    res = pipe.process_joints(int(t * 1e9), bad_q, qd, current=current)
    assert res.estimate is not None and res.estimate.flags == ("invalid_input",)
    assert res.events == () and not res.detection.active
    res = pipe.process_joints(int(t * 1e9) + 1, q, qd, current=None)  # a scene on currents without them
    assert res.estimate.flags == ("invalid_input",)
    assert pipe.invalid_frames == 2
    for t, q, qd, current, *_ in pressed[11:40]:  # and the stream goes on
        res = pipe.process_joints(int(round(t * 1e9)), q, qd, current=current)
        assert res.estimate is None and np.isfinite(res.detection.d2)


def test_chi_square_of_any_dimension():
    assert chi2_isf(1e-9, 6) == pytest.approx(chi2_isf6(1e-9), rel=1e-9)
    assert chi2_sf(3.841458820694124, 1) == pytest.approx(0.05, rel=1e-6)
    assert chi2_sf(14.067140449340169, 7) == pytest.approx(0.05, rel=1e-6)


def test_joint_detector_onset_and_offset():
    det = JointDetector(5, p_false=1e-6, n_on=2, n_off=3)
    cov = np.eye(5)
    big, small = np.full(5, 10.0), np.zeros(5)
    changes = [det.update(i, big if 2 <= i < 6 else small, cov).change for i in range(12)]
    assert changes.index("onset") == 3 and det.onset_t_ns == 2
    assert changes.index("offset") == 8
    with pytest.raises(ValueError):
        det.update(20, np.full(5, np.nan), cov)


def test_per_link_subspace_tests_see_a_proximal_torque_the_full_test_misses():
    full = JointDetector(6, p_false=1e-9)
    per_link = JointDetector(6, p_false=1e-9, subspaces=(1, 2, 3, 6))
    # thresholds: each test at p / 4 (any test firing stays at most p), its own degrees of freedom
    assert per_link.on_k == pytest.approx([chi2_isf(2.5e-10, k) for k in (1, 2, 3, 6)])
    assert per_link.on == pytest.approx(chi2_isf(2.5e-10, 6)) and per_link.on > full.on
    rng = np.random.default_rng(3)
    a = rng.normal(size=(6, 6))
    cov = a @ a.T + 6 * np.eye(6)
    # a torque on the first joint alone, 6.5 sigma (whitened by the whole covariance): d2 = 42.25, between
    # the 1-dof threshold (40.0) and the full test's (53.3): only the subspace test fires
    r = np.zeros(6)
    r[0] = 6.5 / np.sqrt(np.linalg.inv(cov)[0, 0])
    assert r @ np.linalg.solve(cov, r) == pytest.approx(42.25)
    assert full.statistic(r, cov) < full.on
    assert per_link.statistic(r, cov) > per_link.on
    # the same energy spread over all six joints: the full test's business, the subspace tests no help
    spread = np.linalg.cholesky(cov) @ np.full(6, 6.5 / np.sqrt(6))
    assert per_link.statistic(spread, cov) < per_link.on and full.statistic(spread, cov) < full.on
    # the subspace statistic is the matched-subspace detector's (H the first k unit vectors)
    quads = np.empty(6)
    noisy = r + np.linalg.cholesky(cov) @ rng.normal(size=6)
    assert nested_quads(noisy, cov, quads)
    p = np.linalg.inv(cov)
    u = p @ noisy
    assert quads == pytest.approx([u[:k] @ np.linalg.solve(p[:k, :k], u[:k]) for k in range(1, 7)])
    with pytest.raises(ValueError):
        JointDetector(6, subspaces=(0, 6))


def test_no_false_onset_from_any_subspace_under_gaussian_noise():
    det = JointDetector(6, p_false=1e-4, subspaces=(1, 2, 3, 4, 5, 6))
    rng = np.random.default_rng(0)
    a = rng.normal(size=(6, 6))
    cov = a @ a.T + np.eye(6)
    chol = np.linalg.cholesky(cov)
    fired = sum(det.statistic(chol @ rng.normal(size=6), cov) > det.on for _ in range(20000))
    assert fired <= 10  # at most p = 1e-4 a sample (2 expected from the union bound; nested tests share)


def test_joint_settings_round_trip_and_old_recordings():
    s = PipelineSettings(joint=JointSettings(observer_gain=40.0, localize_period_s=0.01))
    back = PipelineSettings.from_json(s.to_json())
    assert back.joint == s.joint
    old = json.loads(PipelineSettings().to_json())
    del old["joint"]  # a recording made before the joint section
    assert PipelineSettings.from_json(json.dumps(old)).joint == JointSettings()
    with pytest.raises(ValueError):
        JointSettings(localize_period_s=-1.0)


def test_pipeline_for_picks_by_sensing(ur5e_currents):
    assert isinstance(pipeline_for(load_scene("ur5e")), ContactPipeline)
    assert isinstance(pipeline_for(ur5e_currents), JointContactPipeline)
    with pytest.raises(ValueError):
        JointContactPipeline(load_scene("ur5e").with_sensing(["base_ft"]))


def test_a_flange_wrench_is_fused_for_the_bodies_beyond_it(ur5e_currents):
    scene = dataclasses.replace(ur5e_currents, sensor=dataclasses.replace(ur5e_currents.sensor, site="flange",
                                                                          mount="flange"))
    model = ArmModel(scene)
    solver = JointContactSolver(model)
    assert solver.flange_on[solver.touch.index("wrist_3")] and not solver.flange_on[solver.touch.index("forearm")]
    q = np.asarray(scene.robot.home, dtype=float) + 0.1
    k = int(np.flatnonzero(solver.fine.link_of == solver.touch.index("wrist_3"))[5])
    n = model.kinematics(q)["wrist_3"][:3, :3] @ solver.fine.nrm[k]
    p, f, tau = _contact_torques(model, q, "wrist_3", solver.fine.loc[k], -n, 20.0)
    b_T_s = model.base_T_site(q, "flange")
    rot, s = b_T_s[:3, :3], b_T_s[:3, 3]
    wrench = np.concatenate([rot.T @ f, rot.T @ np.cross(p - s, f)])  # on the arm, sensor frame
    noise = np.diag(np.full(6, 0.3**2))
    joints_only = solver.solve(tau, np.diag(np.full(6, 2.0**2)), q)
    fused = solver.solve(tau, np.diag(np.full(6, 2.0**2)), q, wrench=wrench, wrench_cov=noise)
    assert fused.link == "wrist_3" and np.linalg.norm(fused.point - p) < 0.01
    assert np.trace(fused.cov[:3, :3]) <= np.trace(joints_only.cov[:3, :3])


def test_a_scene_without_an_ft_sensor_runs_on_its_joint_signals(ur5e_currents, pressed):
    scene = dataclasses.replace(ur5e_currents, sensor=None)
    with pytest.raises(SceneError):
        ArmModel(scene).predicted_wrench(np.asarray(scene.robot.home, dtype=float))
    pipe = pipeline_for(scene, PipelineSettings(joint=JointSettings(model_rel_std=0.005, friction_rel_std=0.05)))
    assert isinstance(pipe, JointContactPipeline)
    events = []
    for t, q, qd, current, _, truth, _ in pressed:
        res = pipe.process_joints(int(round(t * 1e9)), q, qd, current=current)
        events += [(e, truth) for e in res.events if e.kind in ("onset", "update") and truth is not None]
    assert events and all(e.link == "wrist_3" for e, _ in events)
    assert np.linalg.norm(np.asarray(events[-1][0].point) - events[-1][1].point) < 0.015


def test_link_side_joint_torques_give_the_external_torques_without_friction(ur5e_currents, ur5e_model, pressed):
    """A torque sensor between gear and link reads the link-side torque: the rigid-body torque of the motion
    less the contact's, ``M qdd + c + g - J^T f`` (here from the world's true accelerations). The observer
    on it needs no friction model: r follows J^T f (lagged) at standstill too."""
    spec = JointTorqueSpec(noise_std=np.full(6, 0.05), range=np.full(6, 300.0), offset=np.zeros(6))
    scene = dataclasses.replace(ur5e_currents, joint_torque=spec, uses=frozenset({"joint_torques"}))
    gain = 150.0
    res = JointResidual(scene, ur5e_model, "joint_torques", gain=gain)
    rng = np.random.default_rng(0)
    lag, last, errs = np.zeros(6), None, []
    for t, q, qd, _, tau_ext, _, qdd in pressed:
        tau_j = ur5e_model.joint_torques(q, qd, qdd) - tau_ext + rng.normal(size=6) * 0.05
        r, cov, ready = res.update(int(round(t * 1e9)), q, qd, tau_j=tau_j)
        if last is not None:
            a = np.exp(-gain * (t - last[0]))
            lag = a * lag + (1 - a) * 0.5 * (tau_ext + last[1])
        last = (t, tau_ext)
        # the probe's ramps (0.90-0.92 s, 1.42-1.44 s) change J^T f within a few of these samples, which
        # this sensor reads at the sample instants only while the world integrates between them: left out
        ramp = 0.895 < t < 0.93 or 1.415 < t < 1.45
        if ready and t > 0.3 and not ramp:
            errs.append((r - lag) / np.sqrt(np.diag(cov)))
    errs = np.array(errs)
    assert np.abs(errs).max() < 4.0  # within its reported deviation everywhere, standstill included
    assert np.abs(errs.mean(axis=0)).max() < 0.5


def test_the_joint_pipeline_fuses_a_flange_sensor():
    """A flange F/T sensor (ur10e's own, between wrist 3 and its tool) joins detection and localization:
    a push on the tool is in its reading (the world's), which tells the point at once."""
    scene = load_scene("ur10e")
    model = ArmModel(scene)
    pipe = pipeline_for(scene)
    assert isinstance(pipe, JointContactPipeline) and pipe.detector.dof == 12
    rows, readings = _pressed(scene, model, "tool")
    events = []
    for (t, q, qd, current, _, truth, _), raw in zip(rows, readings, strict=True):
        res = pipe.process_joints(int(round(t * 1e9)), q, qd, current=current, wrench=raw)
        events += [(e, truth) for e in res.events if e.kind in ("onset", "update") and truth is not None]
    assert events and all(e.link == "tool" for e, _ in events)
    assert events[0][0].t_host_ns * 1e-9 < 0.915  # the flange's wrench sees the 30 N at once
    assert np.linalg.norm(np.asarray(events[-1][0].point) - events[-1][1].point) < 0.01


def test_the_observer_restarts_after_a_long_gap(ur5e_currents, ur5e_model, pressed):
    res = JointResidual(ur5e_currents, ur5e_model, "currents")
    ready = [res.update(int(round(t * 1e9)), q, qd, current=c)[2] for t, q, qd, c, *_ in pressed[:5]]
    assert ready == [False, True, True, True, True]
    t, q, qd, c, *_ = pressed[60]  # 110 ms later: the trapezoid would bridge the gap blind
    assert not res.update(int(round(t * 1e9)), q, qd, current=c)[2]
    t, q, qd, c, *_ = pressed[61]
    assert res.update(int(round(t * 1e9)), q, qd, current=c)[2]


def test_the_identified_parameters_covariance_reaches_the_joint_torques(ur5e_currents, ur5e_model, pressed):
    m = ur5e_model.model
    # the regressor over every body with mass, times their parameters, is the model's inverse dynamics
    every = [m.body(b).name for b in range(1, m.nbody) if m.body_mass[b] > 0]
    rng = np.random.default_rng(4)
    q, qd, qdd = (np.asarray(ur5e_model.scene.robot.home) + rng.normal(size=6) * 0.3, rng.normal(size=6),
                  rng.normal(size=6))
    y = JointModelError(ur5e_model, every, np.eye(10 * len(every)), False).regressor(q, qd, qdd)
    pi = np.concatenate([body_params(m, m.body(b).id) for b in every])
    tau = ur5e_model.joint_torques(q, qd, qdd)
    assert np.abs(y @ pi - tau).max() < 1e-9 * (1 + np.abs(tau).max())
    bodies = ("forearm", "wrist_1")
    jme = JointModelError(ur5e_model, bodies, np.eye(20) * 1e-4, False)
    with_error = JointResidual(ur5e_currents, ur5e_model, "currents", model_error=jme)
    without = JointResidual(ur5e_currents, ur5e_model, "currents")
    for t, q, qd, c, *_ in pressed[100:103]:
        _, cov_with, _ = with_error.update(int(round(t * 1e9)), q, qd, current=c)
        _, cov_without, _ = without.update(int(round(t * 1e9)), q, qd, current=c)
    extra = cov_with - cov_without
    assert np.all(np.linalg.eigvalsh(extra) > -1e-12) and np.trace(extra) > 0
    assert extra[1, 1] > 0 and extra[2, 2] > 0  # the shoulder's and elbow's torques carry those bodies


def test_the_currents_common_scale_leaves_the_residual_certain(ur5e_currents, ur5e_model, pressed):
    """The currents cannot tell a common scale of the torque constants, the inertials and the friction
    (joint_ident's notes): a covariance along that scale alone must leave the residual's covariance about
    zero without contact, while the inertials' block of it alone puts the scale on the gravity torques."""
    m = ur5e_model.model
    bodies = [m.body(b).name for b in range(1, m.nbody) if m.body_mass[b] > 0 and ur5e_model.moving_joints(b).any()]
    r = ur5e_currents.robot
    scale = np.concatenate([*(body_params(m, m.body(b).id) for b in bodies), r.torque_constant,
                            r.friction_viscous, r.friction_coulomb, np.zeros(6)])
    cov = np.outer(scale, scale) * 0.03**2  # a 3 % common scale, the joint terms in their order
    terms = ("torque_constant", "friction_viscous", "friction_coulomb", "rotor_inertia")
    joint = JointModelError(ur5e_model, bodies, cov, False, joints=terms)
    inertial = JointModelError(ur5e_model, bodies, cov[:10 * len(bodies), :10 * len(bodies)], False)
    t, q, qd, current, tau_ext, truth, qdd = pressed[300]
    assert truth is None and 0.5 < t < 0.85 and np.all(np.abs(qd) > 0.05)  # free motion, every joint moving
    sd_joint = np.sqrt(np.maximum(np.diag(joint.cov(0, q, qd, qdd, current)), 0.0))
    sd_inertial = np.sqrt(np.diag(inertial.cov(0, q, qd, qdd)))
    assert sd_inertial[1:3].min() > 0.15  # 3 % of the shoulder's and elbow's gravity torques
    assert np.all(sd_joint < 0.01 * sd_inertial.max())
    with pytest.raises(ValueError, match="unknown joint terms"):
        JointModelError(ur5e_model, bodies, cov, False, joints=("gear_ratio",))
    with pytest.raises(ValueError, match="expected"):
        JointModelError(ur5e_model, bodies, cov, False, joints=terms[:3])


def test_the_joint_pipeline_on_joint_torque_sensors(ur5e_currents, ur5e_model, pressed):
    spec = JointTorqueSpec(noise_std=np.full(6, 0.05), range=np.full(6, 300.0), offset=np.zeros(6))
    scene = dataclasses.replace(ur5e_currents, joint_torque=spec, uses=frozenset({"joint_torques"}))
    pipe = pipeline_for(scene, PipelineSettings(joint=JointSettings(model_rel_std=0.005)))
    assert pipe.source == "joint_torques"
    rng = np.random.default_rng(2)
    onsets, events = [], []
    for t, q, qd, current, tau_ext, truth, qdd in pressed:
        tau_j = ur5e_model.joint_torques(q, qd, qdd) - tau_ext + rng.normal(size=6) * 0.05
        res = pipe.process_joints(int(round(t * 1e9)), q, qd, tau_j=tau_j, current=current * np.nan)
        onsets += [t for e in res.events if e.kind == "onset"]
        events += [(e, truth) for e in res.events if e.kind in ("onset", "update") and truth is not None]
    assert len(onsets) == 1 and 0.9 <= onsets[0] <= 0.91  # no friction to hide the first newtons
    assert events and all(e.link == "wrist_3" for e, _ in events)
    assert all(np.linalg.norm(np.asarray(e.point) - tr.point) < 0.015 for e, tr in events)


def test_a_contact_on_a_joint_that_stalls_is_held_until_its_torque_is_within_the_static_friction(ur5e_currents,
                                                                                                 ur5e_model):
    """Joint 2 slides, a contact pushes it with 4 f_c, the joint stops (its static friction holding 0.6 f_c) and
    the contact is released at 1.0 s: the offset comes at the release, not when the joint stopped (the covariance's
    1-sigma f_c at standstill had called 13.6 N m of contact torque noise: the ur16e's clamps ended and began
    again, docs/contacts.md)."""
    scene, model = ur5e_currents, ur5e_model
    kt, fc, fv = (np.asarray(v, dtype=float) for v in (scene.robot.torque_constant, scene.robot.friction_coulomb,
                                                     scene.robot.friction_viscous))
    dt, t = 0.002, np.arange(0.0, 1.4, 0.002)
    v = np.where(t < 0.5, 0.2, np.where(t < 0.6, 0.1 * (1 + np.cos(np.pi * (t - 0.5) / 0.1)), 0.0))
    qd, qdd = np.zeros((t.size, 6)), np.zeros((t.size, 6))
    qd[:, 1], qdd[:, 1] = v, np.gradient(v, dt)
    q = np.asarray(scene.robot.home, dtype=float) + np.cumsum(qd, axis=0) * dt
    contact = np.clip((t - 0.2) / 0.1, 0.0, 1.0) * np.where(t < 1.0, 4.0 * fc[1], 0.0)
    offsets = {}
    for with_release in (False, True):
        res, det = JointResidual(scene, model, "currents"), JointDetector(6, p_false=1e-9)
        changes = []
        for i, ti in enumerate(t):
            friction = fv * qd[i] + fc * np.tanh(qd[i] / 0.01)
            if ti >= 0.6:
                friction[1] = 0.6 * fc[1]  # stuck: what the motor does not give, friction holds
            tau = model.joint_torques(q[i], qd[i], qdd[i], "dynamics") + friction
            tau[1] -= contact[i]
            r, cov, ready = res.update(int(round(ti * 1e9)), q[i], qd[i], current=tau / kt)
            if ready:
                release = res.release() if with_release and det.active else None
                change = det.update(int(round(ti * 1e9)), r, cov, release).change
                changes += [(change, ti)] if change else []
        assert [c for c, _ in changes] == ["onset", "offset"], changes
        assert 0.2 <= changes[0][1] <= 0.3
        offsets[with_release] = changes[1][1]
    assert 0.6 <= offsets[False] < 0.65  # without: ended as the joint stopped, with 13.6 N m on it
    assert 1.0 <= offsets[True] <= 1.05  # with: at the release, the joint still stuck
