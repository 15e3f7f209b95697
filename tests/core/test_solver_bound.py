"""The force magnitude's Cramer-Rao bound, and our estimate reaching it.

The moment constrains the force only through tau . f = 0, so it says little about the force's scale:
|f_measured| is all there is, except where the force noise is anisotropic (ur5e: fz noisier than
fx, fy). There, the constraint's correction has a component along f, and the fit must use it.
"""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.bench.solver import median_abs_normal
from ftc_hw.model import ArmModel
from ftc_hw.scene import load_scene
from ftc_hw.solver import make_solver
from ftc_hw.solver.bound import crlb_magnitude_std


def _setup(name: str):
    scene = load_scene(name)
    model = ArmModel(scene)
    q = np.array(scene.robot.home)
    return scene, model, q, make_solver(scene, "ours")


def _informative_case(model, q, solver, contacts, reading, n=200):
    """The well-posed contact where the moment tells the most about the force's magnitude."""
    best = None
    for sp, f in contacts(model, q, n, seed=3, max_angle_deg=45.0):
        e = solver.solve(reading(model, q, sp, f), q)
        if e.flags:
            continue
        bound, force_only = crlb_magnitude_std(solver, sp.point, e.normal, f)
        if best is None or bound / force_only < best[0]:
            best = (bound / force_only, sp, f, bound, force_only)
    return best


def test_median_abs_normal_matches_the_half_normal_median():
    assert median_abs_normal(np.full(50, 2.0)) == pytest.approx(2.0 * 0.6744897501960817, rel=1e-9)
    # a 50/50 mix of 1 and 3: P(|e| < m) = (erf(m/sqrt2) + erf(m/(3 sqrt2)))/2 = 1/2 at m = 1.2019...
    from math import erf, sqrt

    m = median_abs_normal(np.array([1.0, 3.0]))
    assert (erf(m / sqrt(2)) + erf(m / (3 * sqrt(2)))) / 2 == pytest.approx(0.5, abs=1e-12)


def test_isotropic_force_noise_leaves_the_magnitude_to_the_force_reading(contacts, reading):
    _scene, model, q, solver = _setup("dxl-arm")  # force noise 0.1 N on every axis
    for sp, f in contacts(model, q, 30, seed=1, max_angle_deg=45.0):
        e = solver.solve(reading(model, q, sp, f), q)
        if not e.flags:
            bound, force_only = crlb_magnitude_std(solver, sp.point, e.normal, f)
            assert bound == pytest.approx(force_only, rel=1e-6)


def test_our_magnitude_reaches_the_bound_where_the_moment_informs_it(contacts, reading):
    scene, model, q, solver = _setup("ur5e")
    ratio, sp, f, bound, force_only = _informative_case(model, q, solver, contacts, reading)
    assert ratio < 0.92  # the moment carries real information on the scale here
    clean = reading(model, q, sp, f)
    rng = np.random.default_rng(7)
    noise_std = np.sqrt(np.diag(scene.sensor.noise_cov))
    ours, measured = [], []
    for _ in range(3000):
        w = clean + rng.normal(size=6) * noise_std
        e = solver.solve(w, q)
        assert e.contact
        ours.append(np.linalg.norm(e.force))
        measured.append(np.linalg.norm(solver.external_wrench_base(w, q)[:3]))
    fn = np.linalg.norm(f)
    ours_std, measured_std = np.std(np.array(ours) - fn), np.std(np.array(measured) - fn)
    assert measured_std == pytest.approx(force_only, rel=0.04)  # the simulation matches the bound's model
    assert ours_std == pytest.approx(bound, rel=0.04)
    assert ours_std < measured_std * (1 - 0.5 * (1 - ratio))


def test_the_leng2016_method_reports_the_measured_force_s_magnitude(contacts, reading):
    """What lets ``ftc bench solver --magnitude-cases`` compare with |f_measured| instead of running
    the (slow) leng2016 solver on 100 000 cases."""
    scene, model, q, _ = _setup("leng2016")
    leng = make_solver(scene, "leng2016")
    rng = np.random.default_rng(5)
    std = np.sqrt(np.diag(scene.sensor.noise_cov))
    checked = 0
    for sp, f in contacts(model, q, 20, seed=4, max_angle_deg=45.0):
        w = reading(model, q, sp, f) + rng.normal(size=6) * std
        e = leng.solve(w, q)
        if e.contact:
            assert np.linalg.norm(e.force) == pytest.approx(np.linalg.norm(w[:3]), rel=1e-12)
            checked += 1
    assert checked >= 15
