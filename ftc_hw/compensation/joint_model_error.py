"""What the identified model may still get wrong in the joint torques: the identification's parameter
covariance (``PipelineSettings.corrections.model_error``) carried through the joint-torque regressor,
``cov = Y Sigma Y^T`` (n x n), the joint-signal sibling of :mod:`.model_error` (which carries it to the
sensor's wrench).

The regressor: by virtual work the joint torques of the motion are ``sum_b J_b^T w_b`` over the bodies,
``w_b`` body b's wrench for its own motion (force and moment about its origin, gravity included), linear in
its 10 parameters (:func:`ftc_hw.model.inertials.body_wrench_rows`), ``J_b`` its origin's Jacobian.
Recomputed at most every ``refresh_ns`` (a few hundred microseconds).
"""
from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from ..model import ArmModel
from ..model.arm import GRAVITY_OFF
from ..model.inertials import N_PARAMS, body_wrench_rows
from .model_error import REFRESH_NS


class JointModelError:
    """``cov(t_ns, q, qd, qdd)``: the joint torques' covariance (n x n, N^2 m^2) from the parameters'
    covariance ``cov`` of ``bodies`` (10 per body; a fitted sensor gain's 36 more columns, if ``gain``,
    are left out: no joint signal goes through the F/T sensor)."""

    def __init__(self, arm: ArmModel, bodies: Sequence[str], cov: np.ndarray, gain: bool,
                 refresh_ns: int = REFRESH_NS) -> None:
        m = arm.model
        self.arm = arm
        self.body_ids = [m.body(b).id for b in bodies]
        n_par = N_PARAMS * len(bodies)
        cov = np.asarray(cov, dtype=float)
        want = n_par + (36 if gain else 0)
        if cov.shape != (want, want):
            raise ValueError(f"model error covariance: expected {want} x {want} for {len(bodies)} bodies"
                             f"{' and the gain' if gain else ''}, got {cov.shape}")
        self.param_cov = cov[:n_par, :n_par]
        self.refresh_ns = refresh_ns
        self._data = mujoco.MjData(m)
        self._jacp, self._jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        self._vel, self._acc = np.zeros(6), np.zeros(6)
        self._cov = np.zeros((arm.n_joints, arm.n_joints))
        self._t: int | None = None

    def regressor(self, q, qd, qdd) -> np.ndarray:
        """Y (n x 10 len(bodies)): the joint torques' derivatives with respect to the bodies' parameters."""
        arm, m, d = self.arm, self.arm.model, self._data
        arm.joints.set_qpos(np.asarray(q, dtype=float), d.qpos)
        arm.joints.set_dofs(np.asarray(qd, dtype=float), d.qvel)
        arm.joints.set_dofs(np.asarray(qdd, dtype=float), d.qacc)
        flags = m.opt.disableflags
        if flags & GRAVITY_OFF:
            m.opt.disableflags = flags & ~GRAVITY_OFF
        for stage in (mujoco.mj_kinematics, mujoco.mj_comPos, mujoco.mj_comVel, mujoco.mj_rnePostConstraint):
            stage(m, d)
        m.opt.disableflags = flags
        out = np.zeros((arm.n_joints, N_PARAMS * len(self.body_ids)))
        for k, b in enumerate(self.body_ids):
            f, t = body_wrench_rows(m, d, b, self._vel, self._acc)
            mujoco.mj_jac(m, d, self._jacp, self._jacr, d.xpos[b], b)
            jv, jw = arm.joints.jacobian(self._jacp), arm.joints.jacobian(self._jacr)
            out[:, k * N_PARAMS:(k + 1) * N_PARAMS] = jv.T @ f + jw.T @ t
        return out

    def cov(self, t_ns: int, q, qd, qdd) -> np.ndarray:
        """The joint torques' covariance at this state (n x n), the last one within ``refresh_ns``."""
        if self._t is not None and t_ns - self._t < self.refresh_ns:
            return self._cov
        y = self.regressor(q, qd, qdd)
        self._cov = y @ self.param_cov @ y.T
        self._t = t_ns
        return self._cov
