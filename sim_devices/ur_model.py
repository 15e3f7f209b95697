"""What a UR controller computes from its joints: TCP pose and speed, elbow, and its own estimate of the
external wrench at the TCP.

The estimate is the controller's kind (current-based, as on a CB3): the joint torques the motors
deliver beyond what the rigid-body model needs for the measured motion are external,
``J(q)^T w = M(q) qdd + c(q, qd) + f_viscous(qd) - tau_motor``, solved for ``w`` by damped least
squares with ``J`` the 6 x n geometric Jacobian of the TCP (the scene's ``[robot] flange`` site).
``w = (f, m)``: the wrench the environment applies to the arm at the TCP (N, N m), base frame.
Coulomb friction is not modelled (its sign is unknown at rest): it shows as up to the scene's
``friction_coulomb`` N m of spurious joint torque, about 5-10 N at the TCP of a UR5e -- the same order
as a real UR's current-based estimate. A payload not declared to the controller shows as a force.
"""
from __future__ import annotations

import mujoco
import numpy as np

from ftc_hw.model import ArmModel
from ftc_hw.scene import Scene


def rotation_vector(rot: np.ndarray) -> np.ndarray:
    """Axis-angle vector (rad) of a rotation matrix, the UR pose convention."""
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, rot.reshape(9))
    w, v = quat[0], quat[1:]
    if w < 0.0:
        w, v = -w, -v
    s = float(np.linalg.norm(v))
    if s < 1e-12:
        return 2.0 * v
    return v * (2.0 * np.arctan2(s, w) / s)


class URKinematics:
    def __init__(self, scene: Scene, damping: float = 1e-3) -> None:
        self.arm = ArmModel(scene)
        m = self.arm.model
        self.m, self.d = m, self.arm.data
        self.qadr = np.array([m.joint(j).qposadr[0] for j in scene.robot.joints])
        self.dadr = np.array([m.joint(j).dofadr[0] for j in scene.robot.joints])
        self.site = m.site(scene.robot.flange).id if scene.robot.flange else None
        elbow_joint = scene.robot.joints[min(2, len(scene.robot.joints) - 1)]
        self.elbow_body = int(m.jnt_bodyid[m.joint(elbow_joint).id])
        self.viscous = np.asarray(scene.robot.friction_viscous, dtype=float)
        self.gravity = np.asarray(scene.gravity, dtype=float)
        self.damping2 = damping * damping
        self._jacp = np.zeros((3, m.nv))
        self._jacr = np.zeros((3, m.nv))
        self._vel = np.zeros(6)

    def update(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> None:
        """Set the state (inverse dynamics and all kinematic quantities follow)."""
        d = self.d
        d.qpos[self.qadr] = q
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        d.qvel[self.dadr] = qd
        d.qacc[self.dadr] = qdd
        d.xfrc_applied[:] = 0.0
        self.m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_GRAVITY)
        mujoco.mj_inverse(self.m, d)
        if self.site is not None:
            mujoco.mj_jacSite(self.m, d, self._jacp, self._jacr, self.site)

    @property
    def jacobian(self) -> np.ndarray:
        return np.vstack([self._jacp[:, self.dadr], self._jacr[:, self.dadr]])

    def tcp_pose(self) -> np.ndarray:
        if self.site is None:
            return np.zeros(6)
        return np.concatenate([self.d.site_xpos[self.site], rotation_vector(self.d.site_xmat[self.site])])

    def tcp_rotation(self) -> np.ndarray:
        return self.d.site_xmat[self.site].reshape(3, 3) if self.site is not None else np.eye(3)

    def tcp_speed(self, qd: np.ndarray) -> np.ndarray:
        return self.jacobian @ qd

    def tcp_wrench(self, qd: np.ndarray, tau_motor: np.ndarray) -> np.ndarray:
        """The external wrench at the TCP (base frame), from the joint torques (see the module doc)."""
        tau_ext = self.d.qfrc_inverse[self.dadr] + self.viscous * qd - tau_motor
        jac = self.jacobian
        return np.linalg.solve(jac @ jac.T + self.damping2 * np.eye(6), jac @ tau_ext)

    def accelerometer(self) -> np.ndarray:
        """Tool accelerometer at rest: minus gravity in the flange frame (m/s^2); motion not included."""
        return self.tcp_rotation().T @ (-self.gravity)

    def elbow(self) -> tuple[np.ndarray, np.ndarray]:
        mujoco.mj_objectVelocity(self.m, self.d, mujoco.mjtObj.mjOBJ_BODY, self.elbow_body, self._vel, 0)
        return self.d.xpos[self.elbow_body].copy(), self._vel[3:].copy()
