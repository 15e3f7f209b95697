"""The reference paper's method (Leng et al. 2016, section 5) as a baseline: exact on clean data at the
paper's pose (eqs. 25-28), the compatibility solution (5.5) near the truth on noisy data, the
current-mutation constraint (5.4) resolving ambiguity, and the same ContactEstimate type as ours."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ftc_hw.model import ArmModel, Contact
from ftc_hw.model.sampling import SurfacePoint, sample_local
from ftc_hw.pipeline import ContactPipeline
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world.scenarios import _cone, visible_filter
from ftc_hw.solver import BatchEstimate, ContactEstimate, ContactSolver, Solver, flag_names, make_solver
from ftc_hw.solver.leng2016 import Leng2016Solver, _inliers
from tests.conftest import settings
from tests.model import geometry_reference as G

PAPER_Q = np.array([math.pi / 6, -math.pi / 6, -math.pi / 4])  # section 6
FORCE_N = 100.0  # section 6
PER_GEOM = 60


@pytest.fixture(scope="module")
def setup():
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    return scene, model, Leng2016Solver(scene)


@pytest.fixture(scope="module")
def cases(setup, reading):
    """100 N pushes (within 60 degrees of the inward normal) at visible points of every touchable
    primitive (link 1, 2, 3 rods, their exposed caps, the tip hemisphere), with the joint torques."""
    scene, model, _ = setup
    rng = np.random.default_rng(2016)
    hidden = visible_filter(model, PAPER_Q)
    out = []
    for ps in model.posed_surfaces(PAPER_Q):
        got = 0
        while got < PER_GEOM:
            p_loc, n_loc = sample_local(ps.surface.kind, ps.surface.size, rng)
            rot, t = ps.base_T_geom[:3, :3], ps.base_T_geom[:3, 3]
            point, normal = rot @ p_loc + t, rot @ n_loc
            if hidden(point, normal, ps):
                continue
            sp = SurfacePoint(ps.surface.link, ps.surface.geom, point, normal)
            force = FORCE_N * _cone(-normal, math.radians(60.0), rng)
            contact = [Contact(sp.link, sp.point, force)]
            tau_ext = -model.joint_torques(PAPER_Q, level="bias", contacts=contact)  # J^T p
            out.append((sp, force, reading(model, PAPER_Q, sp, force), tau_ext))
            got += 1
    assert {sp.link for sp, *_ in out} == {"link1", "link2", "link3"}
    return out


def _exact(e: ContactEstimate, sp: SurfacePoint, force: np.ndarray) -> bool:
    return (e.contact and e.link == sp.link and np.linalg.norm(e.point - sp.point) <= 1e-6
            and np.linalg.norm(e.force - force) <= 1e-6 * np.linalg.norm(force))


def _on_surface(model: ArmModel, q, link: str, point: np.ndarray) -> float:
    """Distance (m) of a point to the nearest surface of a link's primitives."""
    best = math.inf
    for ps in model.posed_surfaces(q):
        if ps.surface.link != link:
            continue
        rot, t = ps.base_T_geom[:3, :3], ps.base_T_geom[:3, 3]
        sd = G.signed_distance(ps.surface.kind, ps.surface.size, rot.T @ (point - t))
        best = min(best, abs(float(sd.distance)))
    return best


def _mutation_decides(solver: Leng2016Solver, link: str, tau_ext: np.ndarray) -> bool:
    """5.4 can name the link: the link's own (most distal) joint carries a torque above threshold."""
    own = solver.model.joint_names.index(f"joint{link[-1]}")
    return abs(tau_ext[own]) > solver.mutation_threshold[own]


def test_same_api_as_ours(setup, cases):
    scene, _, solver = setup
    assert isinstance(make_solver(scene, "leng2016"), Leng2016Solver)
    sp, force, w, _ = cases[0]
    e = solver.solve(w, PAPER_Q)
    assert isinstance(e, ContactEstimate)
    assert e.cov.shape == (6, 6) and not e.cov.any()  # the paper has no uncertainty model
    assert e.candidate_data.shape == (len(e.candidate_links), 8)
    assert e.candidates[0].link == e.link


def test_noise_free_exact_or_ambiguous(setup, cases):
    """Clean readings: the point to 1e-6 m and the force to 1e-6 relative unless flagged ambiguous,
    and then the truth is among the candidates."""
    _, _, solver = setup
    exact = ambiguous = 0
    for sp, force, w, _ in cases:
        e = solver.solve(w, PAPER_Q)
        assert abs(e.residual) < 1e-9  # rank(M) = 5
        assert float(e.force @ e.normal) < 0.0  # eq. 28: never a pull
        if not e.flags:
            assert _exact(e, sp, force), (sp.geom, np.linalg.norm(e.point - sp.point), e.link)
            exact += 1
        else:
            assert e.flags == ("ambiguous",), e.flags
            assert any(c.link == sp.link and np.linalg.norm(c.point - sp.point) <= 1e-6 for c in e.candidates)
            ambiguous += 1
    assert exact >= 0.8 * len(cases), (exact, ambiguous)


def test_current_mutation_resolves_the_link(setup, cases):
    """5.4: with the joint torques every case whose own joint mutates is exact and unflagged; where
    it does not, the paper's rule names a more proximal link (or nothing), never a wrong point silently."""
    _, _, solver = setup
    decided = resolved = 0
    for sp, force, w, tau in cases:
        e = solver.solve(w, PAPER_Q, tau_ext=tau)
        if _mutation_decides(solver, sp.link, tau):
            decided += 1
            assert not e.flags and _exact(e, sp, force), (sp.geom, e.flags, e.link)
            resolved += 1
        else:
            assert e.link != sp.link or not e.contact or "ambiguous" in e.flags or _exact(e, sp, force)
    assert decided >= 0.9 * len(cases) and resolved == decided


def test_noisy_compatibility_solution_near_the_truth(setup, cases):
    """Scene sensor noise at 100 N: rank(M) = 6, the compatibility solution (5.5) lies on the
    link's surface within 20 mm of the truth; p = f measured (eq. 25). Ours is printed alongside."""
    scene, model, solver = setup
    ours = ContactSolver(scene)
    rng = np.random.default_rng(7)
    std = np.sqrt(np.diag(scene.sensor.noise_cov))
    err_l, err_o = [], []
    for sp, _, w, tau in cases:
        if not _mutation_decides(solver, sp.link, tau):
            continue
        wn = w + rng.normal(size=6) * std
        e = solver.solve(wn, PAPER_Q, tau_ext=tau)
        assert abs(e.residual) > 1e-9  # the noisy wrench is inconsistent: the 5.5 path
        assert e.contact and e.link == sp.link and not e.flags, (sp.geom, e.flags, e.link)
        assert _on_surface(model, PAPER_Q, e.link, e.point) <= 1e-9
        assert float(e.force @ e.normal) < 0.0
        err = float(np.linalg.norm(e.point - sp.point))
        assert err < 0.020, (sp.geom, err)
        f_meas = solver._ours.external_wrench_base(wn, PAPER_Q)[:3]
        np.testing.assert_allclose(e.force, f_meas, rtol=0, atol=1e-9)
        err_l.append(err)
        o = ours.solve(wn, PAPER_Q, tau_ext=tau)
        err_o.append(float(np.linalg.norm(o.point - sp.point)))
    assert len(err_l) >= 0.9 * len(cases)
    print(f"\nnoisy 100 N at the paper's pose, {len(err_l)} cases: median position error "
          f"ours {np.median(err_o) * 1e3:.3f} mm, leng2016 {np.median(err_l) * 1e3:.3f} mm "
          f"(p95 {np.percentile(err_o, 95) * 1e3:.3f} / {np.percentile(err_l, 95) * 1e3:.3f} mm)")


def test_inconsistent_moment_along_the_line(setup, cases):
    """A pure rank-6 disturbance (a moment along the force line, nothing else): every subsystem's
    solution moves by about that moment over the force, so the compatible answer stays within a few mm."""
    _, model, solver = setup
    for sp, force, _, tau in cases[::7]:
        if not _mutation_decides(solver, sp.link, tau):
            continue
        u = force / np.linalg.norm(force)
        wrench = np.concatenate([-force, -(np.cross(sp.point, force) + 0.01 * u)])  # base_on_arm, base = sensor
        e = solver.solve(wrench, PAPER_Q, tau_ext=tau)
        assert e.link == sp.link and not e.flags
        assert abs(abs(e.residual) - 0.01) < 1e-9
        assert np.linalg.norm(e.point - sp.point) < 0.005
        assert _on_surface(model, PAPER_Q, e.link, e.point) <= 1e-9


def test_singular_solutions_are_removed():
    """5.5: a subsystem solution far from the others (position) or tilted (normal) is dropped."""
    rng = np.random.default_rng(3)
    pts = np.array([0.1, 0.2, 0.3]) + 1e-4 * rng.normal(size=(6, 3))
    nrm = np.tile([0.0, 0.0, 1.0], (6, 1))
    pts[4] += [0.01, 0.0, 0.0]  # 10 mm off
    tilt = math.radians(30.0)
    nrm[1] = [math.sin(tilt), 0.0, math.cos(tilt)]  # same place, tilted normal
    keep = _inliers(pts, nrm, 3.0)
    assert keep.tolist() == [True, False, True, True, False, True]
    assert _inliers(pts[:2], nrm[:2], 3.0).all()  # two solutions: nothing to compare against


def test_invalid_and_degenerate_inputs(setup):
    _, _, solver = setup
    for bad in (np.nan, np.inf, -np.inf):
        e = solver.solve(np.array([1.0, 2.0, bad, 0.0, 0.0, 0.0]), PAPER_Q)
        assert not e.contact and "invalid_input" in e.flags
        assert np.all(np.isfinite(e.point)) and np.all(np.isfinite(e.force))
        assert "invalid_input" in solver.solve(np.ones(6), np.array([0.0, bad, 0.0])).flags
        assert "invalid_input" in solver.solve(np.ones(6), PAPER_Q, tau_ext=[0.0, bad, 0.0]).flags
    e = solver.solve(np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0]), PAPER_Q)  # a pure moment: no force line
    assert not e.contact and set(e.flags) == {"low_force", "no_candidate"}
    # 50 N along x on a line 2 m above the sensor, far from the arm (reading = -(p, c x p))
    e = solver.solve(-np.array([50.0, 0.0, 0.0, 0.0, 100.0, 0.0]), PAPER_Q, saturated=True)
    assert not e.contact and set(e.flags) == {"no_candidate", "saturated"}
    # noisy: the compatibility path finds nothing near the line either
    e = solver.solve(-np.array([50.0, 0.0, 0.0, 0.3, 100.0, 0.0]), PAPER_Q)
    assert not e.contact and e.flags == ("no_candidate",) and abs(e.residual) > 1e-3


def test_batch_gives_the_same_answers(setup, cases):
    _, _, solver = setup
    sub = cases[::9]
    ws = np.array([w for _, _, w, _ in sub])
    ws[2] = np.nan
    qs = np.repeat(PAPER_Q[None], len(sub), axis=0)
    taus = np.array([t for *_, t in sub])
    batch = solver.solve_batch(ws, qs, tau_ext=taus)
    assert isinstance(batch, BatchEstimate)
    for i in range(len(sub)):
        e = solver.solve(ws[i], qs[i], tau_ext=taus[i])
        assert batch.contact[i] == e.contact
        assert (solver.links[batch.link[i]] == e.link) if e.contact else batch.link[i] == -1
        np.testing.assert_array_equal(batch.point[i], e.point)
        np.testing.assert_array_equal(batch.force[i], e.force)
        assert flag_names(int(batch.flags[i])) == e.flags
    assert "invalid_input" in flag_names(int(batch.flags[2]))


def test_both_methods_are_solvers_and_either_drives_the_pipeline(setup, cases):
    """The Solver protocol: the paper's method takes the pipeline's per-frame inputs (torque noise,
    the compensation's own covariance) and its events carry its point."""
    scene, model, leng = setup
    assert isinstance(leng, Solver) and isinstance(make_solver(scene, "ours"), Solver)
    assert leng.solved_body_poses() is None
    sp, force, w, _ = cases[0]
    e = leng.solve(w, PAPER_Q, tau_std=np.ones(3), extra_cov=np.zeros((6, 6)))
    assert _exact(e, sp, force)
    assert "invalid_input" in leng.solve(w, PAPER_Q, extra_cov=np.full((6, 6), np.nan)).flags
    pipe = ContactPipeline(scene, settings(level="bias", bias=np.zeros(6), use_currents=False, method="leng2016"))
    assert isinstance(pipe.localization.solver, Leng2016Solver)
    std = np.sqrt(np.diag(scene.sensor.noise_cov))
    rng = np.random.default_rng(5)
    events = []
    for k in range(60):
        raw = (w if 10 <= k < 50 else np.zeros(6)) + rng.normal(size=6) * std
        events += pipe.process(k * 1_000_000, raw, PAPER_Q).events
    updates = [ev for ev in events if ev.kind == "update" and ev.link == sp.link]
    assert updates and min(np.linalg.norm(ev.point - sp.point) for ev in updates) < 0.01
