"""From the scene's joints to the robot model's: which model joint each scene joint sets, and how.

A scene joint is a model joint (ratio 1), or a coupling that drives several model joints at fixed
ratios (a gripper servo's pinion turning both fingers' racks). With C the (model dofs x scene
joints) matrix of those ratios, the model's coordinates are ``qpos = C q`` (and ``qvel = C qd``,
``qacc = C qdd``), and by virtual work a generalized force ``tau_dof`` on the model's dofs is the
scene torque ``C^T tau_dof``: Jacobians become ``J C``, the mass matrix ``C^T M C``.
"""
from __future__ import annotations

import mujoco
import numpy as np

from ..scene import Scene, SceneError

_ONE_DOF = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


class JointMap:
    """The scene's joints on one compiled MuJoCo model (which may hold other joints too, e.g. the
    simulated world's obstacles: those are left alone)."""

    def __init__(self, m: mujoco.MjModel, scene: Scene) -> None:
        robot = scene.robot
        coupled = {c.joint: c for c in robot.couplings}
        names, joint, ratio = [], [], []
        for i, name in enumerate(robot.joints):
            c = coupled.get(name)
            for model_joint, r in zip(c.drives, c.ratios, strict=True) if c else ((name, 1.0),):
                names.append(model_joint)
                joint.append(i)
                ratio.append(r)
        qadr, dadr, jids = [], [], []
        for name, i in zip(names, joint, strict=True):
            try:
                jnt = m.joint(name)
            except KeyError:
                key = "robot.couplings" if robot.joints[i] in coupled else "robot.joints"
                raise SceneError(scene.path, key, f"no joint {name!r} in {robot.model_path.name}") from None
            if int(jnt.type[0]) not in _ONE_DOF:
                raise SceneError(scene.path, "robot.joints", f"joint {name!r} is not a 1-DoF hinge or slide")
            qadr.append(int(jnt.qposadr[0]))
            dadr.append(int(jnt.dofadr[0]))
            jids.append(int(jnt.id))
        self.n_joints = len(robot.joints)
        self.model_joints = tuple(names)  # the model joints the scene sets, in scene order
        self.jnt_ids = np.array(jids, dtype=np.int64)
        self.qadr = np.array(qadr, dtype=np.int64)
        self.dadr = np.array(dadr, dtype=np.int64)
        self.joint = np.array(joint, dtype=np.int64)  # scene joint of each model joint
        self.ratio = np.array(ratio, dtype=float)
        self.coupled = bool(robot.couplings)
        # C over all the model's dofs (rows of other joints stay zero)
        self.matrix = np.zeros((m.nv, self.n_joints))
        self.matrix[self.dadr, self.joint] = self.ratio
        # least squares back from the model's coordinates: q = (C^T C)^-1 C^T qpos
        self._back = np.linalg.pinv(self.matrix[self.dadr])
        # each scene joint's first model joint: where its motor acts (a coupling's others are tied to it)
        self.lead = np.unique(self.joint, return_index=True)[1]

    def set_qpos(self, q: np.ndarray, qpos: np.ndarray) -> None:
        """Write the model joints' coordinates for scene joint positions q into ``qpos``."""
        if len(q) != self.n_joints:
            raise ValueError(f"expected {self.n_joints} joint positions, got {len(q)}")
        if self.coupled:
            qpos[self.qadr] = self.ratio * q[self.joint]
        else:
            qpos[self.qadr] = q

    def set_dofs(self, v: np.ndarray, out: np.ndarray) -> None:
        """Write the model dofs' velocities (or accelerations) for the scene joints' v into ``out``."""
        if self.coupled:
            out[self.dadr] = self.ratio * v[self.joint]
        else:
            out[self.dadr] = v

    def from_dofs(self, tau_dof: np.ndarray) -> np.ndarray:
        """The scene joints' generalized forces (C^T tau) from forces on the model's dofs."""
        if self.coupled:
            return self.matrix.T @ tau_dof
        return tau_dof[self.dadr].copy()

    def to_dofs(self, tau: np.ndarray, out: np.ndarray) -> None:
        """Forces on the model's dofs that act as the scene joints' generalized forces ``tau``, put
        where a coupling's driver acts: each coupling's force goes on its first driven joint (the
        world ties the others to it), ``tau / ratio``."""
        if self.coupled:
            out[self.dadr[self.lead]] = tau / self.ratio[self.lead]
        else:
            out[self.dadr] = tau

    def joints_of(self, qpos_or_dofs: np.ndarray, adr: np.ndarray | None = None) -> np.ndarray:
        """Scene joint values from the model's coordinates (qpos with ``adr=qadr``) or dofs (qvel,
        qacc: the default): exact when the coupling holds, least squares when it is strained."""
        x = qpos_or_dofs[self.dadr if adr is None else adr]
        return self._back @ x if self.coupled else x.copy()

    def jacobian(self, jac_dofs: np.ndarray) -> np.ndarray:
        """A Jacobian over the model's dofs (k x nv) as one over the scene joints (k x n): J C."""
        return jac_dofs @ self.matrix if self.coupled else jac_dofs[:, self.dadr]

    def limits(self, m: mujoco.MjModel, unlimited: float = np.pi) -> tuple[np.ndarray, np.ndarray]:
        """Each scene joint's position range: its model joint's (-unlimited..unlimited when it has
        none); a coupling's the tightest its driven joints allow."""
        lo = np.full(self.n_joints, -np.inf)
        hi = np.full(self.n_joints, np.inf)
        for jid, i, r in zip(self.jnt_ids, self.joint, self.ratio, strict=True):
            a, b = (m.jnt_range[jid] if m.jnt_limited[jid] else (-unlimited * abs(r), unlimited * abs(r)))
            a, b = sorted((a / r, b / r))
            lo[i] = max(lo[i], a)
            hi[i] = min(hi[i], b)
        return lo, hi
