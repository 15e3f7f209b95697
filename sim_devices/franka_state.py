"""The robot state a Franka controller would send for one world joint sample: the protocol's record
(:mod:`ftc_hw.codecs.franka`) filled from the joint ring and the scene's model.

What is filled, and how (sim_devices/SOURCES.md, "Franka"):

- ``q``, ``dq`` the world's; ``theta``, ``dtheta`` (motor side) the same (rigid gears: the world
  has no joint elasticity); ``q_d``, ``dq_d``, ``ddq_d`` the world's too (the controller's desired
  trajectory is the world's scenario, which it tracks).
- ``tau_J``: the link-side joint torque sensors, the world's ``JointRecord.tau_j`` (the motor torque
  less the joint friction, with the sensors' offsets, noise and range: the scene's ``[joint_torque]``;
  zeros where a scene has none). ``tau_J_d`` = ``tau_J``; ``dtau_J`` its change per second between
  consecutive samples.
- ``tau_ext_hat_filtered``: Franka's controller does not publish its estimator (libfranka issues #39,
  #91). Modelled roughly as libfranka's own examples use it: ``tau_J`` minus the rigid-body model's
  torque for the measured motion (MuJoCo's inverse dynamics of the scene's model: gravity, Coriolis,
  inertia), low-passed at ``EXT_CUTOFF_HZ`` (ESTIMATE). The sign is the robot's torque on the
  environment: a push on the arm shows as minus its joint torques (libfranka issue #26 reports the
  wrench's sign so).
- ``O_F_ext_hat_K``: the wrench ``w`` with ``J^T w = tau_ext_hat_filtered`` at the stiffness frame (the
  scene's flange; ``EE_T_K``, ``F_T_EE`` identity), by damped least squares, base frame;
  ``K_F_ext_hat_K`` the same in the flange frame.
- ``O_T_EE`` (and its ``_d``, ``_c``): the flange's pose; ``O_ddP_O``: the scene's gravity vector (a
  resting base, as libfranka documents it); ``elbow`` ``(q3, sign of q4)``, libfranka's elbow
  configuration.
- Not modelled (zeros): the contact and collision flags, errors and reflex reasons, Cartesian
  velocities and accelerations, the end effector's and load's inertia (no gripper is declared), the
  accelerometers (version 10), ``control_command_success_rate`` (no client controls the arm).
"""
from __future__ import annotations

import math

import numpy as np

from ftc_hw.codecs import franka as F

from .link import JointRecord
from .ur_model import URKinematics  # the arm's kinematics and inverse dynamics from the scene (not UR-specific)

EXT_CUTOFF_HZ = 10.0  # ESTIMATE: the external torque's low-pass; Franka publishes none
_EYE16 = F.column_major(np.eye(4))


class StateBuilder:
    """Fills a protocol version's robot state record from world joint samples, one after the other."""

    def __init__(self, proto: F.ProtocolVersion, scene, period_s: float) -> None:
        if scene.n_joints != F.N_JOINTS:
            raise ValueError(f"a Franka arm has {F.N_JOINTS} joints; scene {scene.name!r} has {scene.n_joints}")
        self.proto = proto
        self.kin = URKinematics(scene)
        self.gravity = np.asarray(scene.gravity, dtype=float)
        self.alpha = 1.0 - math.exp(-2.0 * math.pi * EXT_CUTOFF_HZ * period_s)
        self.state = F.new_state(proto)
        for name in ("F_T_EE", "EE_T_K", "F_T_NE", "NE_T_EE"):
            self.state[name] = _EYE16
        self.state["O_ddP_O"] = self.gravity
        self.state["controller_mode"] = F.CONTROLLER_JOINT_IMPEDANCE
        self.state["motion_generator_mode"] = F.MOTION_IDLE
        self._tau_ext = np.zeros(F.N_JOINTS)
        self._last: tuple[float, np.ndarray] | None = None

    def build(self, message_id: int, joints: JointRecord, robot_mode: int) -> bytes:
        """The datagram for one sample (``message_id``: the controller's tick, ms)."""
        s = self.state
        q, qd, qdd = joints.q, joints.qd, joints.qdd
        tau_j = joints.tau_j
        s["message_id"] = message_id
        s["robot_mode"] = robot_mode
        for name, value in (("q", q), ("theta", q), ("q_d", q), ("dq", qd), ("dtheta", qd), ("dq_d", qd),
                            ("ddq_d", qdd), ("tau_J", tau_j), ("tau_J_d", tau_j)):
            s[name] = value
        s["dtau_J"] = self._rate(joints.t, tau_j)
        self.kin.update(q, qd, qdd)
        model = self.kin.d.qfrc_inverse[self.kin.dadr]
        self._tau_ext += self.alpha * (tau_j - model - self._tau_ext)
        s["tau_ext_hat_filtered"] = self._tau_ext
        self._wrenches()
        s["elbow"] = (q[2], math.copysign(1.0, q[3]))
        return F.encode_state(s)

    def _rate(self, t: float, tau: np.ndarray) -> np.ndarray:
        last, self._last = self._last, (t, np.array(tau, dtype=float))
        if last is None or t <= last[0]:
            return np.zeros(F.N_JOINTS)
        return (tau - last[1]) / (t - last[0])

    def _wrenches(self) -> None:
        s, kin = self.state, self.kin
        if kin.site is None:
            return
        jac = kin.jacobian
        w = np.linalg.solve(jac @ jac.T + kin.damping2 * np.eye(6), jac @ self._tau_ext)
        rot = kin.tcp_rotation()
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rot, kin.d.site_xpos[kin.site]
        s["O_F_ext_hat_K"] = w
        s["K_F_ext_hat_K"] = np.concatenate([rot.T @ w[:3], rot.T @ w[3:]])
        for name in ("O_T_EE", "O_T_EE_d", "O_T_EE_c"):
            s[name] = F.column_major(pose)
