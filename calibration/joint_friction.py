"""Joint friction and motor torque constants from free motion: per joint, from the motor current and
the model's joint torque (with the identified inertials),

    kt0 s i = tau_model(q, qd, qdd) + b qd + f_c tanh(qd / v_eps)

linear in (s, b, f_c): ``s`` corrects the scene's torque constant ``kt0``. Samples near standstill
(|qd| < ``MIN_SPEED``) are left out: there the Coulomb friction holds anything within +-f_c. The
joint residuals (:class:`ftc_hw.compensation.JointResiduals`) and the solver's link isolation use the
result.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..model import ArmModel
from .free_motion import HUBER_K, MotionData, prepare

MIN_SPEED = 0.05  # rad/s
V_EPS = 0.01  # rad/s: the Coulomb term's smoothing, as the joint residuals use it
MIN_MOVING = 50  # thinned samples in motion a joint needs to be fitted
# a fitted torque constant is kept only within this factor of the scene's and told to this relative
# std: a joint whose load is mostly its own friction (a vertical axis: no gravity torque) cannot tell
# the current's scale from the friction's, and the fit slides toward zero for all three
KT_RANGE = (0.5, 2.0)
KT_REL_STD = 0.1


@dataclass
class JointFit:
    torque_constant: np.ndarray  # N m / A, per scene joint
    friction_viscous: np.ndarray  # N m s / rad
    friction_coulomb: np.ndarray  # N m
    std: np.ndarray  # (n, 3): of the torque constant, viscous and Coulomb terms
    fitted: np.ndarray  # (n,) bool: the joint moved enough to be fitted (else the scene's values)
    residual_rms_before: np.ndarray  # N m per joint, scene's values
    residual_rms: np.ndarray  # N m per joint
    untold: np.ndarray | None = None  # (n,) bool: it moved, but its torque constant was not told (scene's kept)


def fit_joint_friction(arm: ArmModel, segments: Sequence[MotionData]) -> JointFit:
    r = arm.scene.robot
    kt0, b0, fc0 = (np.asarray(v, dtype=float) for v in (r.torque_constant, r.friction_viscous, r.friction_coulomb))
    rows: list[tuple[np.ndarray, ...]] = []
    for seg in segments:
        if seg.current is None:
            raise ValueError("joint friction needs the motor currents")
        _, _, q, qd, qdd, cur = prepare(seg, with_current=True)
        for k in range(len(q)):
            rows.append((qd[k], cur[k], arm.joint_torques(q[k], qd[k], qdd[k])))
    qd = np.array([x[0] for x in rows])
    cur = np.array([x[1] for x in rows])
    tau = np.array([x[2] for x in rows])
    n = len(kt0)
    out = JointFit(kt0.copy(), b0.copy(), fc0.copy(), np.zeros((n, 3)), np.zeros(n, bool), np.zeros(n), np.zeros(n),
                   np.zeros(n, bool))
    for j in range(n):
        moving = np.abs(qd[:, j]) > MIN_SPEED
        v = qd[moving, j]
        before = kt0[j] * cur[moving, j] - tau[moving, j] - b0[j] * v - fc0[j] * np.tanh(v / V_EPS)
        out.residual_rms_before[j] = out.residual_rms[j] = _rms(before)
        if moving.sum() < MIN_MOVING:
            continue
        a = np.column_stack([kt0[j] * cur[moving, j], -v, -np.tanh(v / V_EPS)])
        x, cov, resid = _huber_ls(a, tau[moving, j])
        if not (KT_RANGE[0] <= x[0] <= KT_RANGE[1]) or np.sqrt(cov[0, 0]) > KT_REL_STD * abs(x[0]):
            out.untold[j] = True
            continue
        out.torque_constant[j] = kt0[j] * x[0]
        out.friction_viscous[j], out.friction_coulomb[j] = x[1], x[2]
        out.std[j] = np.sqrt(np.diag(cov)) * np.array([kt0[j], 1.0, 1.0])
        out.fitted[j] = True
        out.residual_rms[j] = _rms(resid)
    return out


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x))) if len(x) else 0.0


def _huber_ls(a: np.ndarray, y: np.ndarray, iters: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    w = np.ones(len(y))
    x = cov = r = None
    for _ in range(iters):
        sw = np.sqrt(w)
        x, *_ = np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)
        r = y - a @ x
        scale = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 1e-9)
        u = np.abs(r) / scale
        w = np.where(u <= HUBER_K, 1.0, HUBER_K / u)
        cov = np.linalg.pinv((a * w[:, None]).T @ a) * scale**2
    return x, cov, r
