"""Calibration of the sensor bias and the payload (mass, centre of mass) from planned static poses:
identification with uncertainty and a verdict, D-optimal pose planning, stillness gating, the
calibration file, re-zero. ``ftc calibrate`` is the bench wizard on top (ftc_hw/app/calibration/calibrate.py)."""
from .acquire import PoseResult, take_sample, wait_still
from .file import Calibration, CalibrationError, calibration_from_fit, load_calibration, save_calibration
from .identify import Fit, FitOptions, Identifier
from .plan import CollisionChecker, Plan, expected_errors, plan_poses
from .regressor import PARAMS, GeometryModel
from .rezero import BiasUpdate, ReZero
from .samples import PoseSample
from .stillness import StillnessGate, StillnessReport

__all__ = [
    "PARAMS", "BiasUpdate", "Calibration", "CalibrationError", "CollisionChecker", "Fit",
    "FitOptions", "GeometryModel", "Identifier", "Plan", "PoseResult", "PoseSample", "ReZero",
    "StillnessGate", "StillnessReport", "calibration_from_fit", "expected_errors", "load_calibration",
    "plan_poses", "save_calibration", "take_sample", "wait_still",
]
