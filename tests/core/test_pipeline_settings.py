"""The pipeline's settings: one typed object, to JSON and back whole; the flat keyword dict that
recordings held before it reads as the same settings; what cannot be read is named."""
from __future__ import annotations

import json

import numpy as np
import pytest

from ftc_hw.model import Payload
from ftc_hw.pipeline import (
    ContactPipeline,
    Corrections,
    DetectionSettings,
    ModelErrorSpec,
    MotionSettings,
    PipelineSettings,
    SettingsError,
)
from ftc_hw.scene import load_scene


def _full() -> PipelineSettings:
    gain = np.eye(6)
    gain[3, 4] = 0.004
    return PipelineSettings(
        corrections=Corrections(bias=np.arange(6.0), payload=Payload(0.4, (0.0, 0.01, 0.04)), gain=gain,
                                contact_gain=np.eye(6), inertials={"forearm": np.arange(10) * 1e-3},
                                gravity=np.array([0.0, 0.01, -9.81]), joints={"torque_constant": np.full(6, 0.1)},
                                model_error=ModelErrorSpec(("forearm",), np.eye(3) * 1e-4, True)),
        motion=MotionSettings(level="dynamics", refine=True, qdd_tau=0.003),
        detection=DetectionSettings(p_false=1e-6, extra_cov=np.eye(6) * 0.01, gap_hold_s=None))


def test_settings_go_to_json_and_back_whole():
    s = _full()
    back = PipelineSettings.from_json(s.to_json())
    assert back.to_json() == s.to_json()
    c = back.corrections
    assert isinstance(c.payload, Payload) and c.payload.com == (0.0, 0.01, 0.04)
    assert isinstance(c.model_error, ModelErrorSpec) and c.model_error.bodies == ("forearm",) and c.model_error.gain
    np.testing.assert_array_equal(c.gain, s.corrections.gain)
    np.testing.assert_array_equal(c.inertials["forearm"], np.arange(10) * 1e-3)
    assert back.motion == s.motion and back.detection.gap_hold_s is None
    np.testing.assert_array_equal(back.detection.extra_cov, np.eye(6) * 0.01)


def test_a_flat_keyword_dict_of_an_earlier_recording_reads_as_the_same_settings():
    flat = {"level": "dynamics", "bias": list(range(6)), "payload": {"mass": 0.4, "com": [0.0, 0.01, 0.04]},
            "refine": True, "model_error": {"bodies": ["forearm"], "cov": np.eye(3).tolist(), "gain": False}}
    s = PipelineSettings.from_json(json.dumps(flat))
    assert s.motion == MotionSettings(level="dynamics", refine=True)
    np.testing.assert_array_equal(s.corrections.bias, np.arange(6.0))
    assert s.corrections.payload == Payload(0.4, (0.0, 0.01, 0.04))
    assert s.corrections.model_error.bodies == ("forearm",)
    assert PipelineSettings.from_json("{}").to_json() == PipelineSettings().to_json()


@pytest.mark.parametrize("text, named", [
    ('{"level": "dynamics", "lag_floor": 0.1}', "lag_floor"),  # a flat key this version does not know
    ('{"schema": 3}', "schema 3"),
    ('not json', "not JSON"),
    ('[1, 2]', "JSON object"),
])
def test_settings_that_cannot_be_read_say_what(text, named):
    with pytest.raises(SettingsError, match=named):
        PipelineSettings.from_json(text)


def test_a_missing_or_unknown_field_is_named():
    data = json.loads(PipelineSettings().to_json())
    del data["detection"]["n_on"]
    with pytest.raises(SettingsError, match="detection.*n_on.*missing"):
        PipelineSettings.from_json(json.dumps(data))
    data = json.loads(PipelineSettings().to_json())
    data["motion"]["jerk_tau"] = 0.1
    with pytest.raises(SettingsError, match="motion.*jerk_tau.*unknown"):
        PipelineSettings.from_json(json.dumps(data))
    data = json.loads(PipelineSettings().to_json())
    data["localization"]["surface"] = "hull"
    with pytest.raises(SettingsError, match="surface"):
        PipelineSettings.from_json(json.dumps(data))
    data = json.loads(PipelineSettings().to_json())
    data["corrections"]["payload"] = {"mass": 1.0}
    with pytest.raises(SettingsError, match="corrections.payload"):
        PipelineSettings.from_json(json.dumps(data))


def test_the_pipeline_takes_its_settings_whole():
    scene = load_scene("leng2016")
    s = PipelineSettings(motion=MotionSettings(level="gravity", use_currents=False))
    pipe = ContactPipeline(scene, s)
    assert pipe.settings is s and pipe.level == "gravity" and pipe.localization.residuals is None
    assert ContactPipeline(scene).level == scene.compensation
