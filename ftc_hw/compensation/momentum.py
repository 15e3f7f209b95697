"""The generalized-momentum observer: the external joint torques from the joint signals, without the
joint accelerations (De Luca & Mattone, ICRA 2005; Haddadin, De Luca & Albu-Schaeffer, T-RO 2017, sec. IV).

With ``p = M(q) qd`` the arm's generalized momentum, ``pdot = tau_in + tau_ext - beta + Mdot qd``, where
``tau_in`` is the torque the joints put into the links (motor torque less friction, or the link-side
torque sensors' reading), ``beta = C(q, qd) qd + g(q)`` (MuJoCo's ``qfrc_bias``) and ``tau_ext = J^T f``
the contact's. The observer ``r = K (p - p0 - int(tau_in - beta + Mdot qd + r) dt)`` follows ``tau_ext``
through a first-order lag of bandwidth K.

Discrete form (sample k-1 to k, interval dt, any dt: gaps and jitter are exact): the momentum's change
less the trapezoid integral of ``tau_in - beta``, and of ``Mdot qd`` as ``(M_k - M_{k-1}) (qd_k + qd_{k-1}) / 2``.
The two M qd products then collapse to ``M_mid (qd_k - qd_{k-1})`` with ``M_mid`` the mean of the two mass
matrices, so one sample's estimate of ``tau_ext`` is

    e_k = M_mid (qd_k - qd_{k-1}) / dt - mean(tau_in - beta)        and  r_k = a r_{k-1} + (1 - a) e_k,  a = exp(-K dt)

Why this form: MuJoCo gives M and ``C qd + g`` but neither C nor Mdot, so the continuous form's
``C^T qd`` would need the Christoffel symbols (n + 1 mass matrices a sample by finite differences); the
difference of consecutive mass matrices needs none beyond the one p needs anyway, and is second-order
accurate in dt. The exponential update is the exact zero-order-hold discretization of the observer's lag.

Covariance of r (n x n), per sample: the white part of ``tau_in`` (current noise x torque constant, or
the torque sensors' noise) through the filter (variance factor (1 - a) / 2 for the trapezoid's mean of
two samples), the joint velocities' noise through ``M_mid / dt`` (factor 2 (1 - a)^2 / ((1 + a) dt^2)),
and what passes the filter unattenuated because it changes slowly: the friction model's error (a share
of the modelled friction, and at standstill the static friction, unknown within +-f_c), the rigid-body
model's (a share of the model torque, or the identified parameters' covariance through the joint-torque
regressor where given).
"""
from __future__ import annotations

import math

import mujoco
import numpy as np
from numba import njit

from ..model import ArmModel
from ..model.arm import GRAVITY_OFF


class MomentumObserver:
    """The observer on ``arm`` (its model, gravity and joint couplings). ``gain`` 1/s: K, the bandwidth
    (per joint or one for all). Not thread-safe: one per pipeline."""

    def __init__(self, arm: ArmModel, *, gain: float | np.ndarray = 150.0) -> None:
        self.arm = arm
        self.n = arm.n_joints
        self.gain = np.broadcast_to(np.asarray(gain, dtype=float), (self.n,)).copy()
        if not np.all(self.gain > 0):
            raise ValueError(f"observer gain must be > 0 1/s, got {gain!r}")
        m = arm.model
        self._data = mujoco.MjData(m)
        self._full = np.zeros((m.nv, m.nv))
        self._c = arm.joints.matrix  # model dofs x scene joints
        self.mass = np.zeros((self.n, self.n))  # M(q) of the last sample, scene joints
        self.bias = np.zeros(self.n)  # C qd + g of the last sample
        self.r = np.zeros(self.n)
        self._prev: tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self.e = np.zeros(self.n)  # the last sample's unfiltered estimate
        self.qdd = np.zeros(self.n)  # the last interval's mean acceleration, rad/s^2
        self.factors = np.zeros((2, self.n))  # per joint, the white and the velocity noise's variance factors

    def reset(self) -> None:
        """Start afresh (a stream lost): the next sample is the first."""
        self._prev = None
        self.r[:] = 0.0
        self.e[:] = 0.0

    @property
    def started(self) -> bool:
        return self._prev is not None

    @property
    def last_t_ns(self) -> int:
        """The time of the last sample taken (ns; -1 before any)."""
        return -1 if self._prev is None else self._prev[0]

    def dynamics(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(M(q), C(q, qd) qd + g(q)) on the scene's joints: mass matrix (n, n), bias (n,)."""
        arm, m, d = self.arm, self.arm.model, self._data
        arm.joints.set_qpos(q, d.qpos)
        arm.joints.set_dofs(qd, d.qvel)
        flags = m.opt.disableflags
        if flags & GRAVITY_OFF:
            m.opt.disableflags = flags & ~GRAVITY_OFF
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_crb(m, d)
        mujoco.mj_comVel(m, d)
        bias = np.zeros(m.nv)
        mujoco.mj_rne(m, d, 0, bias)
        if m.opt.disableflags != flags:
            m.opt.disableflags = flags
        mujoco.mj_fullM(m, d, self._full)
        c = self._c
        if arm.joints.coupled:
            return c.T @ self._full @ c, c.T @ bias
        idx = arm.joints.dadr
        return self._full[np.ix_(idx, idx)], bias[idx]

    def update(self, t_ns: int, q, qd, tau_in) -> np.ndarray:
        """One sample at time ``t_ns`` (ns, the steadiest clock at hand): joint angles q, velocities qd
        (n,) rad, rad/s, and ``tau_in`` (n,) N m the torque the joints put into the links. Returns r
        (n,) N m, the external joint torques' estimate (``J^T f`` of the contact; zeros on the first
        sample). The inputs must be finite (the pipeline checks)."""
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        tau_in = np.asarray(tau_in, dtype=float)
        mass, bias = self.dynamics(q, qd)
        self.mass, self.bias = mass, bias
        prev = self._prev
        self._prev = (t_ns, qd.copy(), tau_in.copy(), bias, mass)
        if prev is None:
            return self.r
        dt = (t_ns - prev[0]) * 1e-9
        if not dt > 0:
            self._prev = prev  # a repeated or older time: nothing new
            return self.r
        observer_step(mass, prev[4], qd, prev[1], tau_in, prev[2], bias, prev[3], dt, self.gain,
                       self.r, self.e, self.qdd, self.factors)
        return self.r

    def model_torque(self) -> np.ndarray:
        """The rigid-body model's torque of the last interval, ``M qdd + C qd + g`` (n,) N m."""
        return self.mass @ self.qdd + self.bias


@njit(cache=True, nogil=True)
def observer_step(m1, m0, qd1, qd0, tau1, tau0, b1, b0, dt, gain, r, e, qdd, factors):
    """One discrete observer step in place (see the module's notes): ``e`` the interval's estimate,
    ``r`` the filtered residual, ``qdd`` the mean acceleration; ``factors`` (2, n) per joint the variance
    factors of white torque noise (the trapezoid's mean of two samples through the lag: (1 - a) / 2) and
    of white velocity noise (its difference over dt through the lag: 2 (1 - a)^2 / ((1 + a) dt^2))."""
    n = r.shape[0]
    for i in range(n):
        qdd[i] = (qd1[i] - qd0[i]) / dt
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += 0.5 * (m1[i, j] + m0[i, j]) * qdd[j]
        e[i] = acc - 0.5 * (tau1[i] + tau0[i]) + 0.5 * (b1[i] + b0[i])
        a = math.exp(-gain[i] * dt)
        r[i] = a * r[i] + (1.0 - a) * e[i]
        factors[0, i] = 0.5 * (1.0 - a)
        factors[1, i] = 2.0 * (1.0 - a) ** 2 / ((1.0 + a) * dt * dt)
