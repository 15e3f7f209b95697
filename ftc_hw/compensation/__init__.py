"""Compensation: raw sensor wrench -> external contact wrench, and joint-current residuals."""
from .model_error import ModelError
from .online import Drift, OnlineRefiner
from .pipeline import Compensator
from .qdd import QddEstimator, RecentPeak
from .residuals import JointResiduals

__all__ = ["Compensator", "Drift", "JointResiduals", "ModelError", "OnlineRefiner", "QddEstimator", "RecentPeak"]
