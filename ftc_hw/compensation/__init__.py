"""Compensation: raw sensor wrench -> external contact wrench, and joint-current residuals."""
from .joint_residual import JointResidual
from .joint_signals import JointSignals
from .model_error import ModelError
from .momentum import MomentumObserver
from .online import Drift, OnlineRefiner
from .pipeline import Compensator
from .qdd import QddEstimator, RecentPeak
from .residuals import JointResiduals

__all__ = ["Compensator", "Drift", "JointResidual", "JointResiduals", "JointSignals", "ModelError", "MomentumObserver",
           "OnlineRefiner", "QddEstimator", "RecentPeak"]
