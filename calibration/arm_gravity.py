"""The arm's gravity base parameters: the combinations of link masses and first moments that the
sensor can see, once the bias and the payload are estimated too.

Each body beyond the sensor has 4 gravity parameters (mass, and mass times centre of mass in its own
frame). Their regressor columns, stacked over many random poses, span a subspace; the part that the
bias and payload columns already span is absorbed by them (for a base-mounted sensor: every body's
mass shifts only the constant force and torque, and the last link's parameters are indistinguishable
from the payload). What remains, found by an SVD, are the identifiable corrections: ``arm_gravity_k``
= ``v_k . delta_pi`` with ``v_k`` orthonormal over the link parameters.
"""
from __future__ import annotations

import numpy as np

from .regressor import GeometryModel, arm_param_rows, core_rows

REL_TOL = 1e-6


def joint_limits(gm: GeometryModel) -> tuple[np.ndarray, np.ndarray]:
    """The ranges calibration poses are drawn from: each joint's limits, except that joints which do
    not move the flange (dxl-arm's gripper) stay at home: they change nothing the fit can use."""
    lo, hi = gm.arm.joint_limits()
    arm, flange = gm.arm, gm.scene.robot.flange
    if flange is not None:
        idle = ~arm.moving_joints(int(arm.model.site(flange).bodyid[0]))
        lo[idle] = hi[idle] = np.asarray(gm.scene.robot.home)[idle]
    return lo, hi


class ArmGravityBasis:
    def __init__(self, gm: GeometryModel, n_poses: int = 200, seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        lo, hi = joint_limits(gm)
        white = 1.0 / np.sqrt(np.diag(gm.scene.sensor.noise_cov))
        core, arm = [], []
        for _ in range(n_poses):
            g = gm.at(rng.uniform(lo, hi))
            core.append(core_rows(g, gm.gravity, gm.sign) * white[:, None])
            arm.append(arm_param_rows(g, gm.gravity, gm.sign) * white[:, None])
        a_core, a_arm = np.vstack(core), np.vstack(arm)
        q, _ = np.linalg.qr(a_core)
        resid = a_arm - q @ (q.T @ a_arm)
        _, s, vt = np.linalg.svd(resid, full_matrices=False)
        keep = s > REL_TOL * s[0] if len(s) and s[0] > 0 else np.zeros(0, bool)
        self.v = vt[keep].T  # (4k, r)
        self.singular_values = s[keep]
        labels = []
        for name in gm.body_names:
            labels += [f"{name}.mass", f"{name}.mx", f"{name}.my", f"{name}.mz"]
        self.labels = labels
        self.names = [f"arm_gravity_{k + 1}" for k in range(self.v.shape[1])]

    def delta(self, beta: np.ndarray) -> np.ndarray:
        """Link parameter corrections (4 per body) for base parameters ``beta``."""
        return self.v @ np.asarray(beta, dtype=float)

    def describe(self, k: int, top: int = 3) -> str:
        col = self.v[:, k]
        idx = np.argsort(-np.abs(col))[:top]
        return " ".join(f"{col[i]:+.2f} {self.labels[i]}" for i in idx)
