"""Everything a calibration estimates reaches the pipeline: its mount yaw, gravity tilt, arm-gravity
corrections and identification predict, through the pipeline's compensator, what the calibration's
own static model predicts."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ftc_hw.calibration.arm_gravity import ArmGravityBasis
from ftc_hw.calibration.file import (
    Calibration,
    CalibrationError,
    Identification,
    load_calibration,
    save_calibration,
)
from ftc_hw.calibration.regressor import GeometryModel, predict
from ftc_hw.model import ArmModel, Payload
from ftc_hw.pipeline import ContactPipeline, PipelineSettings
from ftc_hw.scene import load_scene
from tests.conftest import settings


@pytest.mark.parametrize("name", ["ur5e", "dxl-arm"])
def test_calibrated_extras_reach_the_compensator(name):
    scene = load_scene(name)
    gm = GeometryModel(ArmModel(scene))
    basis = ArmGravityBasis(gm)
    beta = np.linspace(0.01, 0.03, basis.v.shape[1])
    payload = Payload(0.4, (0.0, 0.01, 0.04))
    bias = np.array([1.0, -2.0, 3.0, 0.1, -0.2, 0.05])
    extras = {"mount_yaw": 0.02, "gravity_tilt_x": 0.004, "gravity_tilt_y": -0.003}
    extras.update({name_k: float(b) for name_k, b in zip(basis.names, beta, strict=True)})
    cal = Calibration(scene=scene.name, sensor_serial=None, date="2026-11-26T00:00:00Z", bias=bias, payload=payload,
                      extras=extras)
    corrections = cal.corrections(scene)
    assert all(getattr(corrections, k) is not None for k in ("frame", "gravity", "inertials"))
    pipe = ContactPipeline(scene, PipelineSettings(corrections=corrections).with_level("gravity"))
    theta = np.concatenate([bias, [payload.mass], payload.mass * np.asarray(payload.com)])
    rng = np.random.default_rng(0)
    lo, hi = gm.arm.joint_limits()
    for _ in range(5):
        q = rng.uniform(np.maximum(lo, -2), np.minimum(hi, 2))
        expected = predict(gm.at(q), theta, gm.gravity, gm.sign, extras["mount_yaw"],
                           (extras["gravity_tilt_x"], extras["gravity_tilt_y"]), basis.delta(beta))
        # what the pipeline leaves of that reading is nothing: it predicts the same load
        np.testing.assert_allclose(pipe.motion.compensator.external(expected, q), np.zeros(6), atol=1e-9)
    plain = ContactPipeline(scene, settings(level="gravity", bias=bias, payload=payload))
    assert np.abs(plain.motion.compensator.external(expected, q)).max() > 1e-3  # the corrections matter


def test_identification_round_trips_through_the_file_and_the_recording(tmp_path):
    scene = load_scene("ur5e")
    gain = np.eye(6)
    gain[3, 4] = 0.004
    ident = Identification("2026-11-26T00:00:00Z", "run.mcap", "poorly_excited", ["why"], gain,
                           {"forearm": np.arange(10) * 1e-3}, ["wrist_3.Ixx"], {"samples": 100})
    cal = Calibration(scene="ur5e", sensor_serial=None, date="2026-11-26T00:00:00Z", bias=np.zeros(6), payload=None,
                      identification=ident)
    back = load_calibration(save_calibration(cal, tmp_path / "cal.toml"), scene=scene)
    np.testing.assert_allclose(back.identification.gain, gain)
    np.testing.assert_allclose(back.identification.inertials["forearm"], np.arange(10) * 1e-3)
    assert back.identification.untold == ["wrist_3.Ixx"]
    restored = PipelineSettings.from_json(PipelineSettings(corrections=back.corrections(scene)).to_json())
    pipe = ContactPipeline(scene, restored)
    np.testing.assert_allclose(pipe.motion.compensator.gain, gain)
    # the contact's wrench: the file's contact_gain undone (the identified gain where the data told it);
    # a file without one (written before): a wholly told gain undone, one with an untold term left as read
    partly = np.eye(6)
    partly[3, 3] = 1.003
    kept = dataclasses.replace(ident, contact_gain=partly)
    back_kept = load_calibration(save_calibration(dataclasses.replace(cal, identification=kept), tmp_path / "k.toml"))
    np.testing.assert_allclose(back_kept.identification.contact_gain, partly)
    told = dataclasses.replace(ident, untold=["gain[3,4]"])
    contact = np.array([5.0, -8.0, 12.0, 0.4, 2.0, -0.3])
    for ident_i, undone in ((ident, gain), (told, np.eye(6)), (back_kept.identification, partly)):
        corrections = dataclasses.replace(cal, identification=ident_i).corrections(scene)
        comp = ContactPipeline(scene, PipelineSettings(corrections=corrections)).motion.compensator
        np.testing.assert_allclose(comp.gain, gain)  # the arm's loads: the whole estimate either way
        np.testing.assert_allclose(comp.contact_wrench(gain @ contact, np.zeros(6)),
                                   np.linalg.solve(undone, gain @ contact), atol=1e-12)
    bad = dataclasses.replace(cal, identification=dataclasses.replace(ident, gain=np.zeros((6, 6))))
    with pytest.raises(CalibrationError, match="load_gain"):
        load_calibration(save_calibration(bad, tmp_path / "bad.toml"))
    bad = dataclasses.replace(cal, identification=dataclasses.replace(ident, contact_gain=np.zeros((6, 6))))
    with pytest.raises(CalibrationError, match="contact_gain"):
        load_calibration(save_calibration(bad, tmp_path / "bad2.toml"))
