"""The pipeline's timing hook: ``ContactPipeline.process`` tells its clock when a frame begins, when each
stage ends and when the frame ends. The default clock does nothing; ``ftc bench pipeline`` gives one
that times the stages (``ftc_hw.bench.pipeline_stages``)."""
from __future__ import annotations

STAGES = ("compensation", "detection", "localization", "events")


class StageClock:
    """Does nothing: the pipeline's default. A subclass times what it wants. ``lap(stage)`` ends
    ``stage`` (one of :data:`STAGES`; localization only in contact)."""

    def begin(self) -> None:
        pass

    def lap(self, stage: str) -> None:
        pass

    def end(self) -> None:
        pass


NO_CLOCK = StageClock()
