"""Which pipeline a scene's sensing takes: F/T-driven where a base F/T sensor is used, else driven by
the joint samples (motor currents, joint torques, a flange F/T sensor)."""
from __future__ import annotations

from ftc_hw.scene import Scene

from .contact import ContactPipeline
from .settings import PipelineSettings


def pipeline_for(scene: Scene, settings: PipelineSettings | None = None):
    """The pipeline for ``scene.sensing``."""
    if scene.sensing.ft == "base":
        return ContactPipeline(scene, settings)
    raise NotImplementedError("TEMP: the joint-driven pipeline lands from the jointsignals branch")
