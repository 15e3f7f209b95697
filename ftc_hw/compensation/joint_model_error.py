"""What the identified model may still get wrong in the joint torques: the identification's parameter
covariance (``PipelineSettings.corrections.model_error``) carried through the joint-torque regressor,
``cov = Y Sigma Y^T`` (n x n), the joint-signal sibling of :mod:`.model_error` (which carries it to the
sensor's wrench).

The regressor: by virtual work the joint torques of the motion are ``sum_b J_b^T w_b`` over the bodies,
``w_b`` body b's wrench for its own motion (force and moment about its origin, gravity included), linear in
its 10 parameters (:func:`ftc_hw.model.inertials.body_wrench_rows`), ``J_b`` its origin's Jacobian.
Recomputed at most every ``refresh_ns`` (a few hundred microseconds).

Where identification fitted per-joint terms with the inertials (``joints``: torque constants, friction,
rotor inertia, torque sensor offsets), their columns join the regressor, ``G = [Y, dr/dkt, ...]`` with the
residual's own derivatives (``r = tau_model + b qd + f_c tanh(qd / v) + I_r qdd - kt i``, or ``- (tau_J -
offset)``): from the currents alone a common scale of the torque constants and the inertials is not told
(joint_ident's notes), and along it the residual does not change (every term scales, and r is about 0
without contact). The inertials' block alone would count that scale's uncertainty on the gravity torques
(measured, ur10e, typical world: 1.6-2.2 N m on the shoulder and elbow joints against a residual's 0.34
and 0.14 N m actual spread).
"""
from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from ..model import ArmModel
from ..model.arm import GRAVITY_OFF
from ..model.inertials import N_PARAMS, body_wrench_rows
from .model_error import REFRESH_NS

# per-joint terms identification may fit with the inertials (the keys of Corrections.joints)
JOINT_TERMS = ("torque_constant", "friction_viscous", "friction_coulomb", "rotor_inertia", "torque_offset")


class JointModelError:
    """``cov(t_ns, q, qd, qdd)``: the joint torques' covariance (n x n, N^2 m^2) from the parameters'
    covariance ``cov`` of ``bodies`` (10 per body; a fitted sensor gain's 36 more columns, if ``gain``,
    are left out: no joint signal goes through the F/T sensor)."""

    def __init__(self, arm: ArmModel, bodies: Sequence[str], cov: np.ndarray, gain: bool,
                 refresh_ns: int = REFRESH_NS, joints: Sequence[str] = (), source: str = "currents",
                 v_eps: float = 0.01) -> None:
        """``joints``: the per-joint terms ``cov`` holds after the bodies' (and the gain's) block, n each
        (``JOINT_TERMS``), of which the residual of ``source`` ("currents" or "joint_torques") depends on
        its own only (the torque sensors' offsets, or the motors' terms); ``v_eps`` rad/s the Coulomb
        term's smoothing, as the residual's friction has it."""
        m = arm.model
        self.arm = arm
        self.body_ids = [m.body(b).id for b in bodies]
        n_par = N_PARAMS * len(bodies)
        n = arm.n_joints
        cov = np.asarray(cov, dtype=float)
        unknown = set(joints) - set(JOINT_TERMS)
        if unknown:
            raise ValueError(f"model error covariance: unknown joint terms {sorted(unknown)} (known: {JOINT_TERMS})")
        skip = 36 if gain else 0
        want = n_par + skip + n * len(joints)
        if cov.shape != (want, want):
            raise ValueError(f"model error covariance: expected {want} x {want} for {len(bodies)} bodies"
                             f"{' and the gain' if gain else ''}{' and ' + ', '.join(joints) if joints else ''}, "
                             f"got {cov.shape}")
        keep = np.r_[0:n_par, n_par + skip:want]
        self.param_cov = cov[np.ix_(keep, keep)]
        self.joints = tuple(joints)
        self.n_par = n_par
        self.source = source
        self.v_eps = float(v_eps)
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

    def cov(self, t_ns: int, q, qd, qdd, current=None) -> np.ndarray:
        """The joint torques' covariance at this state (n x n), the last one within ``refresh_ns``;
        ``current`` (n,) A the motor currents where the torque constants are among ``joints``."""
        if self._t is not None and t_ns - self._t < self.refresh_ns:
            return self._cov
        self._cov = self.cov_now(q, qd, qdd, current)
        self._t = t_ns
        return self._cov

    def cov_now(self, q, qd, qdd, current=None) -> np.ndarray:
        """:meth:`cov` computed afresh (no cache)."""
        y = self.regressor(q, qd, qdd)
        if self.joints:
            y = np.hstack([y, *(np.diag(self._column(k, qd, qdd, current)) for k in self.joints)])
        return y @ self.param_cov @ y.T

    def _column(self, key: str, qd, qdd, current) -> np.ndarray:
        """dr/d(term) per joint: the residual's derivative with respect to one joint term."""
        n = self.arm.n_joints
        if (key == "torque_offset") != (self.source == "joint_torques"):
            return np.zeros(n)  # a term the other signal's residual holds
        if key == "torque_constant":
            return -np.asarray(current, dtype=float) if current is not None else np.zeros(n)
        if key == "friction_viscous":
            return np.asarray(qd, dtype=float)
        if key == "friction_coulomb":
            return np.tanh(np.asarray(qd, dtype=float) / self.v_eps)
        if key == "rotor_inertia":
            return np.asarray(qdd, dtype=float)
        return np.ones(n)  # torque_offset: r = model - (tau_J - offset)
