"""Online refinement (``MotionSettings(refine=True)``, ``ftc monitor --refine``): while the arm moves
free, recursive least squares with forgetting keeps refining the identified link parameters; an arm
that is not the calibration's (a link 20 % heavier) is explained better and reported as drifted, the
calibration's own arm is not, and a contact's frames are never learned from."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.model import ArmModel, Contact
from ftc_hw.model.inertials import N_PARAMS
from ftc_hw.pipeline import ContactPipeline, ModelErrorSpec
from ftc_hw.scene import load_scene
from tests.conftest import settings

SCENE = load_scene("dxl-arm")
HOME = np.asarray(SCENE.robot.home)
BODIES = ["link2", "link3", "link4", "link5"]
# the identification's posterior: each link's mass known to 10 g, its first moments to 1 g m, inertia 1e-5
PRIOR_STD = np.tile([0.01, 0.001, 0.001, 0.001] + [1e-5] * 6, len(BODIES))


def _model_error() -> ModelErrorSpec:
    return ModelErrorSpec(tuple(BODIES), np.diag(PRIOR_STD**2), False)


def _run(true_arm: ArmModel, refine: bool, seconds: float = 60.0, touch_at: float | None = None):
    """The pipeline on ``seconds`` of every joint swinging (100 Hz), read through ``true_arm``; the
    moment residual's RMS over the last 20 s, and the pipeline."""
    pipe = ContactPipeline(SCENE, settings(level="dynamics", model_error=_model_error(), refine=refine,
                                           use_currents=False))
    rng = np.random.default_rng(0)
    w = 2 * np.pi * np.array([0.11, 0.17, 0.23, 0.29, 0.0])
    amp = np.array([0.9, 0.4, 0.5, 0.6, 0.0])
    pipe.tare(true_arm.predicted_wrench(HOME), HOME, 100, 0)
    resid = []
    for k in range(int(seconds * SCENE.sensor.rate_hz)):
        t = k / SCENE.sensor.rate_hz
        q = HOME + amp * np.sin(w * t)
        qd, qdd = amp * w * np.cos(w * t), -amp * w * w * np.sin(w * t)
        contacts = ([Contact("link5", np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.0, -3.0]))]
                    if touch_at is not None and touch_at <= t < touch_at + 10.0 else [])
        raw = true_arm.predicted_wrench(q, qd, qdd, contacts=contacts) + rng.normal(size=6) * SCENE.sensor.noise_std
        r = pipe.process(int(t * 1e9), raw, q, qd, qdd=qdd)
        if t >= seconds - 20.0:
            resid.append(r.external[3:])
    return float(np.sqrt(np.mean(np.sum(np.square(resid), axis=1)))), pipe


def test_a_heavier_link_is_refined_and_reported_as_drift():
    delta = np.zeros(N_PARAMS)
    delta[0] = 0.2 * 0.139  # link3 20 % heavier, its centre of mass where it was
    delta[1:4] = delta[0] * ArmModel(SCENE).model.body_ipos[ArmModel(SCENE).model.body("link3").id]
    heavier = ArmModel(SCENE, inertials={"link3": delta})
    fixed, _ = _run(heavier, refine=False)
    refined, pipe = _run(heavier, refine=True)
    drift = pipe.motion.refiner.drift()
    assert refined < 0.7 * fixed, (refined, fixed)
    assert drift.drifted and drift.rms_refined < 0.95 * drift.rms_file, drift.summary()
    assert "DRIFTED" in drift.summary() and drift.applied >= 50


def test_the_calibrations_own_arm_is_not_drift_and_a_contact_is_never_learned():
    """The file's own arm, pushed by 3 N for 10 s: the refinement stops while the contact is open (it
    would otherwise take the push for a heavier arm) and reports no drift."""
    _, pipe = _run(ArmModel(SCENE), refine=True, seconds=40.0, touch_at=10.0)
    drift = pipe.motion.refiner.drift()
    assert not drift.drifted and drift.frames >= drift.MIN_FRAMES, drift.summary()
    assert drift.frames < 0.8 * 40.0 * 50  # at most 50 frames a second; none of the 10 s of contact
    assert drift.rms_refined == pytest.approx(drift.rms_file, rel=0.05)
    assert all(abs(drift.mass_change_kg[b]) < 3 * drift.mass_std_kg[b] for b in BODIES), drift.summary()
