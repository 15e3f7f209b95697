"""Per-joint external torques from the motor currents: the paper's current-mutation constraint made
quantitative.

    tau_ext = model torque (gravity, dynamics) + friction(qd) - torque constant x current = J_c^T p

``tau_ext`` is the torque the external force p at the contact c exerts about each joint (sign: the
solver's ``tau_ext``); the motors push against it, so their torque is the model torque minus it.
Friction: viscous ``b qd`` plus Coulomb ``f_c sign(qd)``, smoothed over ``v_eps``; at rest the Coulomb
friction can hold anything within +-f_c, which the reported standard deviation carries.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..scene import Scene


class JointResiduals:
    def __init__(self, scene: Scene, v_eps: float = 0.01, floor: float = 0.02, friction_rel_std: float = 0.25,
                 model_rel_std: float = 0.02) -> None:
        r = scene.robot
        self.kt = np.asarray(r.torque_constant, dtype=float)
        self.viscous = np.asarray(r.friction_viscous, dtype=float)
        self.coulomb = np.asarray(r.friction_coulomb, dtype=float)
        self.current_std = np.asarray(r.current_noise_std, dtype=float)
        self.v_eps = v_eps
        self.floor = floor
        # friction models are rough (a quarter of the Coulomb level) and the rigid-body model a little
        self.friction_rel_std = friction_rel_std
        self.model_rel_std = model_rel_std
        self._var_fixed = (self.kt * self.current_std) ** 2 + floor**2 + (friction_rel_std * self.coulomb) ** 2

    def friction(self, qd) -> np.ndarray:
        qd = np.asarray(qd, dtype=float)
        return self.viscous * qd + self.coulomb * np.tanh(qd / self.v_eps)

    def external_torques(self, model_tau, current, qd) -> tuple[np.ndarray, np.ndarray]:
        """(tau_ext, its standard deviation), N m per joint."""
        model = np.asarray(model_tau, dtype=float)
        tau_ext, std = np.empty_like(model), np.empty_like(model)
        _external_torques(model, np.asarray(current, dtype=float), np.asarray(qd, dtype=float), self.kt,
                          self.viscous, self.coulomb, self._var_fixed, self.v_eps, self.model_rel_std, tau_ext, std)
        return tau_ext, std

    def most_distal_significant(self, tau_ext, std, k: float = 3.0) -> int:
        """Index of the most distal joint whose |tau_ext| exceeds k sigma, or -1: it bounds the
        touched link (the contact is on that joint's link or beyond)."""
        significant = np.flatnonzero(np.abs(tau_ext) > k * std)
        return int(significant[-1]) if significant.size else -1


@njit(cache=True, nogil=True)
def _external_torques(model, current, qd, kt, viscous, coulomb, var_fixed, v_eps, model_rel_std, tau_ext, std):
    # a loop over a handful of joints: a dozen numpy calls on 6-vectors cost 6 us a frame in contact
    for j in range(model.shape[0]):
        slip = math.tanh(qd[j] / v_eps)
        tau_ext[j] = model[j] + viscous[j] * qd[j] + coulomb[j] * slip - kt[j] * current[j]
        stuck = coulomb[j] * (1.0 - abs(slip))  # static friction: unknown within +-f_c
        rel = model_rel_std * model[j]
        std[j] = math.sqrt(var_fixed[j] + stuck * stuck + rel * rel)
