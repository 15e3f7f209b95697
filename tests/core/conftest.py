"""Fixtures of the core tests (solver, compensation, detection, tracking, pipeline, monitor): the sensor
reading of a contact."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.model import ArmModel, Contact
from ftc_hw.model.sampling import SurfacePoint


def _reading(model: ArmModel, q, sp: SurfacePoint, force) -> np.ndarray:
    """The compensated sensor reading (sensor frame, scene convention) of one contact."""
    return model.predicted_wrench(q, level="bias", contacts=[Contact(sp.link, sp.point, force)])


@pytest.fixture(scope="session")
def reading():
    """``reading(model, q, sp, force)``: the compensated sensor reading of one contact."""
    return _reading
