"""What a UR controller computes from its joints and its sensors: TCP pose and speed, elbow, and the
external wrench at the TCP.

Without a flange F/T sensor the wrench is the controller's current-based estimate (a CB3's kind): the
joint torques the motors deliver beyond what the rigid-body model needs for the measured motion are
external, ``J(q)^T w = M(q) qdd + c(q, qd) + f_viscous(qd) - tau_motor``, solved for ``w`` by damped least
squares with ``J`` the 6 x n geometric Jacobian of the TCP (the scene's ``[robot] flange`` site).
``w = (f, m)``: the wrench the environment applies to the arm at the TCP (N, N m), base frame.
Coulomb friction is not modelled (its sign is unknown at rest): it shows as up to the scene's
``friction_coulomb`` N m of spurious joint torque, about 5-10 N at the TCP of a UR5e -- the same order
as a real UR's current-based estimate. A payload not declared to the controller shows as a force.

With a flange sensor (an e-Series' built-in one: ``[sensor] mount = "flange"``, its site the tool flange
frame) the wrench is the sensor's (:func:`flange_wrench_base`): UR's RTDE guide calls ``actual_TCP_force``
the generalized forces at the TCP that compensate "the measurement" for the payload, and UR's own ROS
drivers read it on e-Series as a flange wrench in base axes (sim_devices/SOURCES.md, "UR F/T").
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


def flange_wrench_base(reading: np.ndarray, reading_sign: float, rotation: np.ndarray) -> np.ndarray:
    """The wrench the environment applies to the bodies beyond a flange sensor, base axes, about the sensor's
    origin (N, N m; shape (6,)), from its ``reading`` (shape (6,), sensor frame, the scene's convention:
    ``reading = reading_sign * (the mount's wrench on those bodies)``, which at rest is minus the external
    loads on them, their weight included). ``rotation``: base_R_sensor (3 x 3). The controller's declared
    payload (RTDE ``payload``, 0 here) would be subtracted; an undeclared one shows as a force, as on a UR."""
    external = -reading_sign * np.asarray(reading, dtype=float)
    return np.concatenate([rotation @ external[:3], rotation @ external[3:]])


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

    def check_flange_sensor(self, site: str) -> None:
        """ValueError unless ``site`` is the TCP's frame (the ``[robot] flange`` site: same body, position
        and axes): a UR's built-in sensor measures in the tool flange frame, which the emulator's
        ``ft_raw_wrench`` and the adapter's frames then share with the scene's sensor frame."""
        m = self.m
        sid = m.site(site).id  # the scene's sensor site: ArmModel checked that the model has it
        if self.site is None:
            raise ValueError("a flange F/T sensor needs the scene's [robot] flange site (the tool flange frame)")
        same_axes = abs(float(np.dot(m.site_quat[sid], m.site_quat[self.site]))) > 1.0 - 1e-12
        if (m.site_bodyid[sid] != m.site_bodyid[self.site] or not same_axes
                or not np.allclose(m.site_pos[sid], m.site_pos[self.site], rtol=0.0, atol=1e-9)):
            raise ValueError(f"flange sensor site {site!r} is not the tool flange frame "
                             f"({m.site(self.site).name!r}): a UR's built-in sensor measures in that frame")

    def accelerometer(self) -> np.ndarray:
        """Tool accelerometer at rest: minus gravity in the flange frame (m/s^2); motion not included."""
        return self.tcp_rotation().T @ (-self.gravity)

    def elbow(self) -> tuple[np.ndarray, np.ndarray]:
        mujoco.mj_objectVelocity(self.m, self.d, mujoco.mjtObj.mjOBJ_BODY, self.elbow_body, self._vel, 0)
        return self.d.xpos[self.elbow_body].copy(), self._vel[3:].copy()
