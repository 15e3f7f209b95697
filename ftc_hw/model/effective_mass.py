"""A point's effective mass and velocity along a direction, from a MuJoCo model's mass matrix and point Jacobian.

The effective (reflected) mass of the arm at a point ``p`` of a body, along the unit direction ``n`` (base
frame), is the mass a force along ``n`` at ``p`` meets at once (Khatib's operational-space inertia,
projected on ``n``):

    m_eff = 1 / (n^T J M^-1 J^T n)

``J`` (3 x n, m/rad) the point's positional Jacobian over the scene's joints, ``M`` (n x n) the joint space
mass matrix (a coupling's motor sees ``C^T M C``; MuJoCo's ``qM`` holds the joints' armature, the motors'
reflected rotor inertia, too). The same function serves the pipeline's (identified) model and the world's
true arm: both are a compiled ``MjModel`` with a :class:`~ftc_hw.model.joint_map.JointMap` of the scene's
joints on it (other joints of the model, such as the world's obstacles, are left out).
"""
from __future__ import annotations

import mujoco
import numpy as np

from .joint_map import JointMap


def pose_for_inertia(m: mujoco.MjModel, d: mujoco.MjData, joints: JointMap, q: np.ndarray) -> None:
    """Set ``d`` to the scene joints' q (rad) and compute what :func:`effective_mass` reads: the kinematics,
    the bodies' centres and the composite inertias (MuJoCo's ``qM``)."""
    joints.set_qpos(np.asarray(q, dtype=float), d.qpos)
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    mujoco.mj_crb(m, d)


def point_jacobian(m: mujoco.MjModel, d: mujoco.MjData, joints: JointMap, body: int,
                   point: np.ndarray) -> np.ndarray:
    """The positional Jacobian (3 x n, m/rad) of ``point`` (m, base frame) moving with ``body`` over the
    scene's joints, at the pose ``d`` holds (:func:`pose_for_inertia`)."""
    jac = np.zeros((3, m.nv))
    mujoco.mj_jac(m, d, jac, None, np.asarray(point, dtype=float), int(body))
    return joints.jacobian(jac)


def effective_mass(m: mujoco.MjModel, d: mujoco.MjData, joints: JointMap, body: int, point: np.ndarray,
                   direction: np.ndarray) -> float:
    """kg: ``1 / (n^T J M^-1 J^T n)`` at ``point`` (m, base frame) of ``body`` along ``direction`` (base
    frame, any length > 0), at the pose ``d`` holds (:func:`pose_for_inertia`). ``inf`` where the joints
    cannot move the point along ``direction`` (the base, or a singular direction); ValueError for a zero
    direction."""
    n = np.asarray(direction, dtype=float)
    norm = float(np.linalg.norm(n))
    if not norm > 0.0:
        raise ValueError(f"direction: expected a non-zero vector, got {n.tolist()}")
    row = (n / norm) @ point_jacobian(m, d, joints, body, point)  # (n,) n^T J
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    c = joints.matrix
    mass = c.T @ full @ c
    inverse = float(row @ np.linalg.solve(mass, row))
    return 1.0 / inverse if inverse > 1e-12 else float("inf")


def point_speed(m: mujoco.MjModel, d: mujoco.MjData, joints: JointMap, body: int, point: np.ndarray,
                direction: np.ndarray, qd: np.ndarray) -> float:
    """m/s: the velocity of ``point`` of ``body`` along the unit ``direction`` (base frame) at joint velocities
    ``qd`` (rad/s), at the pose ``d`` holds: ``n^T J qd``."""
    n = np.asarray(direction, dtype=float)
    norm = float(np.linalg.norm(n))
    if not norm > 0.0:
        return 0.0
    return float((n / norm) @ point_jacobian(m, d, joints, body, point) @ np.asarray(qd, dtype=float))
