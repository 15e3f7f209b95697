"""What the pipeline and the tools need of a contact solver. ContactSolver (ours) and Leng2016Solver
(the paper's method) both satisfy it; ``make_solver`` returns one."""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from ..model import ArmModel
from ..scene import Scene
from .solver import BatchEstimate, ContactEstimate

BodyPoses = tuple[np.ndarray, np.ndarray]  # every body's position (nbody, 3), quaternion (nbody, 4): MuJoCo's layout


@runtime_checkable
class Solver(Protocol):
    model: ArmModel
    scene: Scene
    links: tuple[str, ...]  # the model's body names: BatchEstimate's link indices

    def solve(self, wrench_sensor, q, tau_ext=None, saturated: bool = False, tau_std=None,
              extra_cov=None) -> ContactEstimate:
        """The contact from the compensated wrench (sensor frame) at joint angles q. ``tau_ext``: per-joint
        external torques; ``tau_std``: their standard deviations for this frame; ``extra_cov``: the
        compensation's own uncertainty (6x6, sensor frame). A method may ignore what it has no use for."""
        ...

    def solve_batch(self, wrenches_sensor, qs, tau_ext=None, saturated=None) -> BatchEstimate:
        ...

    def body_poses(self, q) -> BodyPoses:
        """Every body's pose at joint angles q (valid until the next call or solve)."""
        ...

    def solved_body_poses(self) -> BodyPoses | None:
        """The body poses of the last solve's q when the solver computed them itself (no second
        kinematics pass), else None: the caller then asks ``body_poses``."""
        ...
