"""The torque the joints put into the links, from the motor currents or the joint torque sensors, with
its uncertainty split by how it behaves in time (the momentum observer filters the two differently).

- ``currents``: ``tau_in = kt current - friction(qd)`` (the torque constants and the friction model of
  :class:`~.residuals.JointResiduals`). White: the current noise times kt, and a floor. Slow: the friction
  model's error (a share ``friction_rel_std`` of the modelled friction while the joint slides) and at
  standstill the static friction, anything within +-f_c (taken as 1 sigma f_c, as ``JointResiduals`` does).
- ``joint_torques``: ``tau_in = tau_J`` (link side of the gears: no joint friction between the sensor
  and the link). White: the sensors' noise. Slow: none here (an offset is identification's, or the tare's;
  what is left of it and its drift are tracked while the arm is free: :mod:`.joint_offset`).

Both: the rigid-body model's error, a share ``model_rel_std`` of the model torque (slow).
"""
from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numba import njit

from ..scene import Scene
from .residuals import JointResiduals

Source = Literal["currents", "joint_torques"]


class JointSignals:
    """``tau_in`` and its variances for one scene and source (see the module's notes)."""

    def __init__(self, scene: Scene, source: Source, *, friction_rel_std: float = 0.25,
                 model_rel_std: float = 0.02, floor: float = 0.02, offset=None, identified_std=None) -> None:
        """``offset`` (n,) N m: the joint torque sensors' offsets (identified, or tared at rest), taken off
        their reading. ``identified_std`` (n,) N m: identification's post-fit residual of this signal: the
        slow error while the joints move, in place of the friction and rigid-body models' assumed shares."""
        if source not in ("currents", "joint_torques"):
            raise ValueError(f"source: 'currents' or 'joint_torques', got {source!r}")
        self.source = source
        n = scene.n_joints
        self.model_rel_std = float(model_rel_std)
        self.residuals = JointResiduals(scene, floor=floor, friction_rel_std=friction_rel_std)
        self.friction_rel_std = float(friction_rel_std)
        if source == "currents":
            res = self.residuals
            self._white = (res.kt * res.current_std) ** 2 + floor**2
            self._viscous, self._coulomb = res.viscous, res.coulomb
        else:
            if scene.joint_torque is None:
                raise ValueError(f"scene {scene.name!r} has no joint torque sensors ([joint_torque])")
            self._white = np.asarray(scene.joint_torque.noise_std, dtype=float) ** 2 + floor**2
            self._viscous = self._coulomb = np.zeros(n)
        self.v_eps = self.residuals.v_eps
        self.offset = np.zeros(n) if offset is None else np.asarray(offset, dtype=float).copy()
        self._identified = np.zeros(n) if identified_std is None else np.asarray(identified_std, dtype=float)
        if identified_std is not None:
            self.friction_rel_std = self.model_rel_std = 0.0

    @property
    def white_var(self) -> np.ndarray:
        """(n,) N^2 m^2: the per-sample white variance of tau_in."""
        return self._white

    def torque(self, qd: np.ndarray, current=None, tau_j=None) -> np.ndarray:
        """tau_in (n,) N m from this sample's currents (A) or joint torques (N m)."""
        if self.source == "currents":
            return self.residuals.kt * np.asarray(current, dtype=float) - self.residuals.friction(qd)
        return np.asarray(tau_j, dtype=float) - self.offset

    @property
    def sticks(self) -> bool:
        """Whether any joint's signal carries static friction (motor currents; not link-side torque sensors)."""
        return bool(np.any(self._coulomb))

    def stuck_std(self, qd: np.ndarray) -> np.ndarray:
        """(n,) N m: the static friction's share of :meth:`slow_std` (f_c where a joint stands still, 0 where
        it slides, the same ``tanh`` blend): the most a stuck joint's friction can hold."""
        return self._coulomb * (1.0 - np.abs(np.tanh(np.asarray(qd, dtype=float) / self.v_eps)))

    def slow_std(self, qd: np.ndarray, model_tau: np.ndarray, out: np.ndarray) -> np.ndarray:
        """(n,) N m into ``out``: 1 sigma of tau_in's slowly varying error (friction model, static friction,
        rigid-body model) at joint velocities qd and model torque ``model_tau``."""
        _slow_std(np.asarray(qd, dtype=float), model_tau, self._viscous, self._coulomb, self.v_eps,
                  self.friction_rel_std, self.model_rel_std, self._identified, out)
        return out


@njit(cache=True, nogil=True)
def _slow_std(qd, model_tau, viscous, coulomb, v_eps, friction_rel, model_rel, identified, out):
    for j in range(qd.shape[0]):
        slip = abs(math.tanh(qd[j] / v_eps))
        sliding = friction_rel * (coulomb[j] * slip + abs(viscous[j] * qd[j]))
        stuck = coulomb[j] * (1.0 - slip)
        rel = model_rel * model_tau[j]
        out[j] = math.sqrt(sliding * sliding + stuck * stuck + rel * rel + identified[j] * identified[j])
