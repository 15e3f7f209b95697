"""Contact localization: where the arm was touched, how hard, and how sure we are."""
from __future__ import annotations

from typing import Literal

from ..model import ArmModel
from ..scene import Scene
from .joint import JointContactSolver
from .leng2016 import Leng2016Solver
from .protocol import BodyPoses, Solver
from .solver import BatchEstimate, Candidate, ContactEstimate, ContactSolver, flag_names

Method = Literal["ours", "leng2016"]


def make_solver(scene: Scene | ArmModel, method: Method = "ours") -> Solver:
    """``ours`` (ContactSolver) or ``leng2016`` (the reference paper's method, section 5.5)."""
    if method == "ours":
        return ContactSolver(scene)
    if method == "leng2016":
        return Leng2016Solver(scene)
    raise ValueError(f"unknown method {method!r} (ours, leng2016)")


__all__ = ["BatchEstimate", "BodyPoses", "Candidate", "ContactEstimate", "ContactSolver", "JointContactSolver",
           "Leng2016Solver",
           "Method", "Solver", "flag_names", "make_solver"]
