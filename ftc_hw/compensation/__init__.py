"""Compensation: raw sensor wrench -> external contact wrench, and joint-current residuals."""
from .model_error import ModelError
from .pipeline import Compensator
from .qdd import QddEstimator, RecentPeak
from .residuals import JointResiduals

__all__ = ["Compensator", "JointResiduals", "ModelError", "QddEstimator", "RecentPeak"]
