"""The contact solver: exact on clean data, flags when it cannot be, same answers in batch."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ftc_hw.model import ArmModel, Contact
from ftc_hw.scene import builtin_names, load_scene
from ftc_hw.solver import ContactSolver

# the F/T solver on the scenes whose base sensor sees a contact anywhere on the arm (a flange sensor
# sees only its tool: its solver's cases are the sensing's own tests)
BASE_FT_SCENES = [name for name in builtin_names() if load_scene(name).sensing.ft == "base"]


@pytest.fixture(scope="module", params=BASE_FT_SCENES)
def scene_setup(request):
    scene = load_scene(request.param)
    model = ArmModel(scene)
    return scene, model, ContactSolver(scene)


def test_noise_free_exact_or_flagged(scene_setup, contacts, reading):
    scene, model, solver = scene_setup
    q = np.array(scene.robot.home)
    cases = contacts(model, q, 400, seed=11)
    accurate = flagged = 0
    for sp, force in cases:
        e = solver.solve(reading(model, q, sp, force), q)
        pos_err = np.linalg.norm(e.point - sp.point)
        force_err = np.linalg.norm(e.force - force) / np.linalg.norm(force)
        if pos_err <= 1e-6 and force_err <= 1e-6 and e.contact:
            accurate += 1
        else:
            assert e.flags, f"wrong answer without a flag: {sp.link} error {pos_err:.3g} m"
            flagged += 1
    assert accurate >= 0.75 * len(cases), (accurate, flagged)


def test_batch_gives_the_same_answers(scene_setup, contacts, reading):
    scene, model, solver = scene_setup
    rng = np.random.default_rng(5)
    qs, ws = [], []
    for k in range(40):
        q = np.array(scene.robot.home) + rng.uniform(-0.3, 0.3, scene.n_joints)
        sp, force = contacts(model, q, 1, seed=k)[0]
        qs.append(q)
        ws.append(reading(model, q, sp, force))
    ws[3] = np.full(6, np.nan)
    batch = solver.solve_batch(np.array(ws), np.array(qs))
    for i, (w, q) in enumerate(zip(ws, qs, strict=True)):
        e = solver.solve(w, q)
        assert batch.contact[i] == e.contact
        assert solver.links[batch.link[i]] == e.link if e.link else batch.link[i] == -1
        np.testing.assert_allclose(batch.point[i], e.point, atol=1e-10)
        np.testing.assert_allclose(batch.force[i], e.force, atol=1e-8)
        np.testing.assert_allclose(batch.cov[i], e.cov, rtol=1e-6, atol=1e-14)
        from ftc_hw.solver import flag_names

        assert flag_names(int(batch.flags[i])) == e.flags
        kept = min(len(e.candidates), batch.candidate_link.shape[1])
        assert [solver.links[k] for k in batch.candidate_link[i, :kept]] == [c.link for c in e.candidates[:kept]]
        for j in range(kept):
            np.testing.assert_allclose(batch.candidate_data[i, j, :3], e.candidates[j].point, atol=1e-10)


def test_nan_and_inf_are_flagged_never_propagated():
    scene = load_scene("leng2016")
    solver = ContactSolver(scene)
    q = np.array(scene.robot.home)
    for bad in (np.nan, np.inf, -np.inf):
        w = np.array([1.0, 2.0, bad, 0.0, 0.0, 0.0])
        e = solver.solve(w, q)
        assert not e.contact and "invalid_input" in e.flags
        assert np.all(np.isfinite(e.point)) and np.all(np.isfinite(e.force))
        e = solver.solve(np.ones(6), np.array([0.0, bad, 0.0]))
        assert "invalid_input" in e.flags


def test_float32_input_is_as_accurate_as_float32_allows(contacts, reading):
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    solver = ContactSolver(scene)
    q = np.array(scene.robot.home)
    for sp, force in contacts(model, q, 50, seed=3, max_angle_deg=60):
        w32 = reading(model, q, sp, force).astype(np.float32)
        e = solver.solve(w32, q.astype(np.float32))
        if "ambiguous" in e.flags:
            continue
        # float32 rounding of the wrench (~6e-8 relative) moves the line by ~1e-7 of the lever arm
        assert np.linalg.norm(e.point - sp.point) < 1e-4


def _grazing_case(model, q, angle_deg):
    """A push on link2's side at angle_deg to the surface (0 = tangent, 90 = along the normal)."""
    links = model.kinematics(q)
    b_T = links["link2"]
    point = b_T[:3, :3] @ np.array([0.12, 0.0, 0.04]) + b_T[:3, 3]
    normal = b_T[:3, :3] @ np.array([0.0, 0.0, 1.0])
    tangent = b_T[:3, :3] @ np.array([0.0, 1.0, 0.0])  # around the cylinder: the line stays on link2
    a = math.radians(angle_deg)
    return point, 50.0 * (-math.sin(a) * normal + math.cos(a) * tangent)


@pytest.mark.parametrize("angle", [0.1, 0.5, 1.0, 3.0, 5.5, 10.0, 30.0, 60.0, 89.9])
def test_grazing_forces(angle):
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    solver = ContactSolver(scene)
    q = np.array(scene.robot.home)
    point, force = _grazing_case(model, q, angle)
    e = solver.solve(model.predicted_wrench(q, level="bias", contacts=[Contact("link2", point, force)]), q)
    err = np.linalg.norm(e.point - point)
    if angle < 5.0:
        assert "grazing" in e.flags
        # the crossing is ill-conditioned like 1/sin(angle), but still near the truth
        assert err < 1e-12 / math.sin(math.radians(angle)) + 1e-9 or "ambiguous" in e.flags
    else:
        assert "grazing" not in e.flags
        assert err < 1e-9


def test_force_along_the_cylinder_axis_hits_the_cap():
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    solver = ContactSolver(scene)
    q = np.array([0.0, 0.0, 0.0])  # link2 and link3 horizontal along +x: push the tip along -x
    tip = model.base_T_site(q, "tip")[:3, 3]
    point = tip + np.array([0.04, 0.0, 0.0])
    force = np.array([-30.0, 0.0, 0.0])
    e = solver.solve(model.predicted_wrench(q, level="bias", contacts=[Contact("link3", point, force)]), q)
    np.testing.assert_allclose(e.point, point, atol=1e-12)
    np.testing.assert_allclose(e.force, force, atol=1e-9)
    assert e.link == "link3" and not e.flags


def test_seam_between_cylinder_and_hemisphere():
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    solver = ContactSolver(scene)
    q = np.array(scene.robot.home)
    b_T = model.kinematics(q)["link3"]
    for phi in np.linspace(0, 2 * np.pi, 13):
        local = np.array([0.2, 0.04 * np.cos(phi), 0.04 * np.sin(phi)])  # exactly on the seam
        n_local = np.array([0.0, np.cos(phi), np.sin(phi)])
        point = b_T[:3, :3] @ local + b_T[:3, 3]
        force = -40.0 * (b_T[:3, :3] @ (n_local + np.array([0.3, 0.0, 0.0])))
        e = solver.solve(model.predicted_wrench(q, level="bias", contacts=[Contact("link3", point, force)]), q)
        assert e.link == "link3"
        np.testing.assert_allclose(e.point, point, atol=1e-9)


def test_force_through_the_sensor_origin():
    """Zero moment: the line passes through the base origin."""
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    solver = ContactSolver(scene)
    q = np.array([0.0, -0.5, 0.3])
    target = model.kinematics(q)["link2"][:3, 3] + model.kinematics(q)["link2"][:3, :3] @ np.array([0.1, 0, 0])
    u = target / np.linalg.norm(target)
    w = np.concatenate([-(-20.0 * u), np.zeros(3)])  # base_on_arm reading of a pull/push along u
    e = solver.solve(w, q)
    assert abs(e.residual) < 1e-12
    assert e.contact
    line_dist = np.linalg.norm(np.cross(e.point, u))
    assert line_dist < 1e-12  # on the line through the origin


def test_line_through_two_links_is_ambiguous_without_torques_and_resolved_with_them(contacts, reading):
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    solver = ContactSolver(scene)
    q = np.array([0.0, -0.6, 2.2])  # link3 folded back above link2
    rng = np.random.default_rng(0)
    resolved = ambiguous = 0
    for sp, force in contacts(model, q, 300, seed=4):
        w = reading(model, q, sp, force)
        e = solver.solve(w, q)
        if len({c.link for c in e.candidates}) < 2:
            continue
        assert "ambiguous" in e.flags or e.link == sp.link
        ambiguous += "ambiguous" in e.flags
        tau = model.joint_torques(q, level="bias", contacts=[Contact(sp.link, sp.point, force)])
        tau_ext = -tau + rng.normal(0, 0.02, 3)  # J^T p, measured through the currents
        e2 = solver.solve(w, q, tau_ext=tau_ext)
        resolved += e2.link == sp.link and np.linalg.norm(e2.point - sp.point) < 1e-6
    assert ambiguous > 5
    assert resolved >= 0.95 * ambiguous


def test_low_force_is_flagged_not_called_contact(contacts, reading):
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    solver = ContactSolver(scene)
    q = np.array(scene.robot.home)
    sp, force = contacts(model, q, 1, seed=1)[0]
    tiny = force / np.linalg.norm(force) * 0.5 * solver.low_force
    e = solver.solve(reading(model, q, sp, tiny), q)
    assert "low_force" in e.flags and not e.contact


def test_saturated_input_is_flagged(contacts, reading):
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    solver = ContactSolver(scene)
    q = np.array(scene.robot.home)
    sp, force = contacts(model, q, 1, seed=2)[0]
    e = solver.solve(reading(model, q, sp, force), q, saturated=True)
    assert "saturated" in e.flags


@pytest.mark.parametrize("reports", ["base_on_arm", "arm_on_base"])
@settings(max_examples=40, deadline=None)
@given(aspect=st.floats(-3.0, 3.0), seed=st.integers(0, 10_000))
def test_ellipsoids_from_needles_to_plates(tmp_path_factory, reports, aspect, seed, contacts, reading, custom_scene):
    ratio = 10.0 ** aspect  # 1e-3 .. 1e3
    a = 0.05
    c = a * ratio
    tmp = tmp_path_factory.mktemp("ell")
    scene = custom_scene(tmp, "ell", "ellipsoid", f"{a} {a} {c}", "sphere", "0.05", reports=reports)
    model = ArmModel(scene)
    solver = ContactSolver(scene)
    q = np.array(scene.robot.home)
    sp, force = contacts(model, q, 1, seed=seed, max_angle_deg=60)[0]
    e = solver.solve(reading(model, q, sp, force), q)
    if e.flags:
        assert set(e.flags) <= {"ambiguous", "grazing"}
        return
    scale = max(a, c)
    assert np.linalg.norm(e.point - sp.point) <= 1e-9 * max(1.0, scale / 0.05)


@pytest.mark.parametrize("kinds", [("box", "0.05 0.08 0.2", "capsule", "0.04 0.2"),
                                   ("cylinder", "0.05 0.2", "box", "0.03 0.04 0.2")])
def test_boxes_capsules_cylinders(tmp_path, kinds, contacts, reading, custom_scene):
    scene = custom_scene(tmp_path, "prims", *kinds)
    model = ArmModel(scene)
    solver = ContactSolver(scene)
    q = np.array(scene.robot.home)
    for sp, force in contacts(model, q, 200, seed=9, max_angle_deg=70):
        e = solver.solve(reading(model, q, sp, force), q)
        if not e.flags:
            assert np.linalg.norm(e.point - sp.point) < 1e-9


def test_points_far_from_the_origin(tmp_path, contacts, reading, custom_scene):
    scene = custom_scene(tmp_path, "far", "capsule", "0.05 0.2", "sphere", "0.06", offset="1000 -2000 500")
    model = ArmModel(scene)
    solver = ContactSolver(scene)
    q = np.array(scene.robot.home)
    for sp, force in contacts(model, q, 50, seed=2, max_angle_deg=60):
        e = solver.solve(reading(model, q, sp, force), q)
        if not e.flags:
            # the moment is ~2000 m x force: relative rounding ~1e-16 of that
            assert np.linalg.norm(e.point - sp.point) < 1e-9


def test_a_fit_without_a_covariance_reports_it_unbounded_not_nan():
    """Wrenches at and far below the noise floor: a noise-floor frame (leng2016 moving, recorded by
    the world, which once gave NaN) is reported, never as NaN; a force so small that the information
    matrix underflows gets infinite variances, never NaN."""
    scene = load_scene("leng2016")
    w = [-0.0324992568942859, -0.0535156713121836, 0.14389945623012357, 0.06789793417013712,
         -0.022826336623266635, -0.010874950040109077]
    q = [0.961067417830331, -0.34150750990290396, -0.7855338333201762]
    solver = ContactSolver(scene)
    e = solver.solve(w, q)
    assert not e.contact and "low_force" in e.flags
    assert not np.isnan(e.cov).any()
    assert np.all(np.isfinite(e.point)) and np.all(np.isfinite(e.force))
    b = solver.solve_batch(np.array([w, w]), np.array([q, q]))
    assert not np.isnan(b.cov).any()
    tiny = np.array([1e-160, 2e-160, -1e-160, 0.0, 0.0, 0.0])
    e = solver.solve(tiny, q)
    assert not e.contact and "low_force" in e.flags
    assert not np.isnan(e.cov).any() and np.isinf(np.diag(e.cov)).all()
    b = solver.solve_batch(np.array([tiny]), np.array([q]))
    assert not np.isnan(b.cov).any() and np.isinf(np.diagonal(b.cov, axis1=1, axis2=2)).all()


def test_the_compensation_uncertainty_weighs_on_the_fit_and_its_covariance(contacts, reading):
    """An extra covariance equal to the sensor's doubles the wrench covariance: on a noise-free
    reading the point stays and the reported covariance doubles; a broken one is invalid input."""
    scene = load_scene("ur5e")
    model = ArmModel(scene)
    solver = ContactSolver(model)
    q = np.array(scene.robot.home)
    sp, force = contacts(model, q, 1, seed=4, max_angle_deg=20, f_range=(50.0, 50.0))[0]
    w = reading(model, q, sp, force)
    plain = solver.solve(w, q)
    doubled = solver.solve(w, q, extra_cov=scene.sensor.noise_cov)
    assert plain.contact and doubled.contact and doubled.link == plain.link
    assert np.allclose(doubled.point, plain.point, atol=1e-9)
    assert np.allclose(doubled.cov, 2.0 * plain.cov, rtol=1e-6, atol=1e-18)
    broken = solver.solve(w, q, extra_cov=np.full((6, 6), np.nan))
    assert not broken.contact and "invalid_input" in broken.flags
