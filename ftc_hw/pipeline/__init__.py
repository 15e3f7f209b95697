"""The per-frame contact pipeline (``ContactPipeline``): its stages, its settings and its timing hook."""
from .contact import ContactPipeline, FrameResult, corrected_scene
from .events import ContactEvents, PreviousFrame, gain_std_of
from .joint import JointContactPipeline, pipeline_for
from .localization import LocalizationStage
from .motion import Compensated, MotionStage
from .settings import (
    SECTION_TYPES,
    Corrections,
    DetectionSettings,
    EventSettings,
    JointSettings,
    LocalizationSettings,
    ModelErrorSpec,
    MotionSettings,
    PipelineSettings,
    SettingsError,
)
from .timing import NO_CLOCK, STAGES, StageClock

__all__ = [
    "NO_CLOCK", "SECTION_TYPES", "STAGES", "Compensated", "ContactEvents", "ContactPipeline", "Corrections",
    "DetectionSettings", "EventSettings", "FrameResult", "JointContactPipeline", "JointSettings",
    "LocalizationSettings", "LocalizationStage", "ModelErrorSpec", "MotionSettings", "MotionStage",
    "PipelineSettings", "PreviousFrame", "SettingsError", "StageClock", "corrected_scene", "gain_std_of",
    "pipeline_for",
]
