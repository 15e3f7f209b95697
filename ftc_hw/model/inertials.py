"""Link inertial parameters as identification sees them, and the base-wrench regressor.

A body's 10 standard parameters, in its own frame: ``pi = [m, hx, hy, hz, Ixx, Iyy, Izz, Ixy, Ixz, Iyz]``
with ``h = m c`` (first moments, c the centre of mass) and ``I`` the rotational inertia about the body
frame's origin. The wrench the moving bodies put on the sensor is linear in them:
``w = Y(q, qd, qdd) pi`` (:func:`wrench_regressor`), the classic base-wrench regressor; so are the
joint torques the motion needs (:func:`joint_regressor`, the joint-torque regressor).
"""
from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

N_PARAMS = 10
PARAM_LABELS = ("mass", "mx", "my", "mz", "Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")


class InertialsError(ValueError):
    """Parameters that no rigid body has (a non-positive mass, an inertia that is not positive definite)."""


def skew(v: np.ndarray) -> np.ndarray:
    """``[v]x``: the matrix of ``v x``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def inertia_at_com(pi: np.ndarray) -> np.ndarray:
    """The rotational inertia about the centre of mass (3 x 3, body frame) of parameters ``pi``."""
    mass, h = float(pi[0]), np.asarray(pi[1:4], dtype=float)
    i_o = np.array([[pi[4], pi[7], pi[8]], [pi[7], pi[5], pi[9]], [pi[8], pi[9], pi[6]]])
    return i_o - (h @ h * np.eye(3) - np.outer(h, h)) / mass


def body_params(m: mujoco.MjModel, b: int) -> np.ndarray:
    """The 10 standard parameters of body ``b`` of a compiled model."""
    mass = float(m.body_mass[b])
    c = np.array(m.body_ipos[b], dtype=float)
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, m.body_iquat[b])
    r = rot.reshape(3, 3)
    i_c = r @ np.diag(m.body_inertia[b]) @ r.T
    i_o = i_c + mass * (c @ c * np.eye(3) - np.outer(c, c))
    return np.array([mass, *(mass * c), i_o[0, 0], i_o[1, 1], i_o[2, 2], i_o[0, 1], i_o[0, 2], i_o[1, 2]])


def set_body_params(m: mujoco.MjModel, b: int, pi: np.ndarray, nearest: bool = False) -> None:
    """Give body ``b`` the parameters ``pi``; :class:`InertialsError` if no rigid body has them, or
    (``nearest``) the rigid body nearest in inertia: principal moments raised to a twentieth of the
    largest and to the triangle inequality."""
    mass = float(pi[0])
    if not mass > 0:
        raise InertialsError(f"body {m.body(b).name!r}: mass {mass:g} kg is not positive")
    c = np.asarray(pi[1:4], dtype=float) / mass
    i_c = inertia_at_com(pi)
    principal, axes = np.linalg.eigh(i_c)
    if nearest:
        principal = np.maximum(principal, 0.05 * max(principal[2], 1e-9))
        principal[0] = max(principal[0], principal[2] - principal[1])
    if principal[0] <= 0 or principal[0] + principal[1] < principal[2] * (1 - 1e-9):
        raise InertialsError(f"body {m.body(b).name!r}: the inertia about the centre of mass is not a rigid "
                             f"body's (principal moments {principal})")
    if np.linalg.det(axes) < 0:
        axes[:, 0] = -axes[:, 0]
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, axes.reshape(-1))
    m.body_mass[b] = mass
    m.body_ipos[b] = c
    m.body_iquat[b] = quat
    m.body_inertia[b] = principal


def keep_com_inertia(pi: np.ndarray, d_mass: float, d_first: np.ndarray) -> np.ndarray:
    """The 10-parameter correction that changes a body's mass and first moments by ``d_mass``,
    ``d_first`` and keeps its inertia about its (moved) centre of mass."""
    mass, h = float(pi[0]), np.asarray(pi[1:4], dtype=float)
    new_mass, new_h = mass + float(d_mass), h + np.asarray(d_first, dtype=float)

    def shift(m: float, first: np.ndarray) -> np.ndarray:
        s = (first @ first * np.eye(3) - np.outer(first, first)) / m
        return np.array([s[0, 0], s[1, 1], s[2, 2], s[0, 1], s[0, 2], s[1, 2]])

    out = np.zeros(N_PARAMS)
    out[0], out[1:4] = new_mass - mass, new_h - h
    out[4:] = shift(new_mass, new_h) - shift(mass, h)
    return out


def _inertia_rows(v: np.ndarray) -> np.ndarray:
    """``I v`` as a 3 x 6 matrix on (Ixx, Iyy, Izz, Ixy, Ixz, Iyz)."""
    x, y, z = v
    return np.array([[x, 0, 0, y, z, 0], [0, y, 0, x, 0, z], [0, 0, z, 0, x, y]], dtype=float)


def body_wrench_rows(m: mujoco.MjModel, d: mujoco.MjData, b: int, vel: np.ndarray,
                     acc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body ``b``'s wrench for its motion (force, torque about its origin; base axes) as 3 x 10 rows each on
    its parameters, at the state in ``d`` (as :func:`wrench_regressor` needs it); ``vel``, ``acc``: scratch (6,)."""
    # XBODY: the body frame (BODY would be its inertial frame); 1: local orientation
    mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_XBODY, b, vel, 1)
    mujoco.mj_objectAcceleration(m, d, mujoco.mjtObj.mjOBJ_XBODY, b, acc, 1)
    w, a = vel[:3], acc[3:]  # angular velocity; linear acceleration of the origin (minus gravity)
    dw = acc[:3]
    cols = np.zeros((6, N_PARAMS))  # the body's wrench about its origin, body frame
    cols[:3, 0] = a
    cols[:3, 1:4] = skew(dw) + skew(w) @ skew(w)  # m (dw x c + w x (w x c)) = [dw]x h + [w]x [w]x h
    cols[3:, 1:4] = -skew(a)  # h x a = -[a]x h
    cols[3:, 4:] = _inertia_rows(dw) + skew(w) @ _inertia_rows(w)
    r_b = d.xmat[b].reshape(3, 3)
    return r_b @ cols[:3], r_b @ cols[3:]


def wrench_regressor(m: mujoco.MjModel, d: mujoco.MjData, bodies: Sequence[int], site: int,
                     sign: float) -> np.ndarray:
    """``Y`` (6 x 10 len(bodies)): the sensor reading (site frame, about the site, ``sign`` the scene's
    reading sign) of each body's parameters, at the state in ``d``, which must have had
    ``mj_kinematics``, ``mj_comPos``, ``mj_comVel`` and ``mj_rnePostConstraint`` (its accelerations
    include minus gravity, as MuJoCo's recursive Newton-Euler counts it)."""
    rot_s = d.site_xmat[site].reshape(3, 3)
    p_s = d.site_xpos[site]
    out = np.zeros((6, N_PARAMS * len(bodies)))
    vel, acc = np.empty(6), np.empty(6)
    for k, b in enumerate(bodies):
        f, t = body_wrench_rows(m, d, b, vel, acc)
        t = t + skew(d.xpos[b] - p_s) @ f  # about the sensor origin
        out[:3, k * N_PARAMS:(k + 1) * N_PARAMS] = rot_s.T @ f
        out[3:, k * N_PARAMS:(k + 1) * N_PARAMS] = rot_s.T @ t
    return sign * out


def joint_regressor(m: mujoco.MjModel, d: mujoco.MjData, bodies: Sequence[int]) -> np.ndarray:
    """``Y`` (nv x 10 len(bodies)): the generalized forces on the model's dofs that each body's
    parameters need for the motion in ``d`` (prepared as for :func:`wrench_regressor`), i.e. MuJoCo's
    inverse dynamics less the armature's and passive forces, as ``sum_b J_b^T Y_b pi_b`` with ``J_b``
    the body origin's Jacobian."""
    out = np.zeros((m.nv, N_PARAMS * len(bodies)))
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    vel, acc = np.empty(6), np.empty(6)
    for k, b in enumerate(bodies):
        f, t = body_wrench_rows(m, d, b, vel, acc)
        mujoco.mj_jacBody(m, d, jacp, jacr, b)
        out[:, k * N_PARAMS:(k + 1) * N_PARAMS] = jacp.T @ f + jacr.T @ t
    return out


def model_rows(arm, data: mujoco.MjData, bodies: Sequence[int], q, qd, qdd,
               gain: bool) -> tuple[np.ndarray, np.ndarray]:
    """``(A, nominal)`` at one state: the reading's derivatives with respect to the bodies' parameters
    (6 x 10 len(bodies)) and, with ``gain``, to the sensor's 6 x 6 linear error on the loads (36 more
    columns, row-major), and the model's reading (no bias). ``arm``: an :class:`~.arm.ArmModel`;
    ``data``: a scratch ``MjData`` of its model."""
    m = arm.model
    nominal = arm.predicted_wrench(q, qd, qdd, "dynamics")
    arm.joints.set_qpos(q, data.qpos)
    arm.joints.set_dofs(qd, data.qvel)
    arm.joints.set_dofs(qdd, data.qacc)
    for stage in (mujoco.mj_kinematics, mujoco.mj_comPos, mujoco.mj_comVel, mujoco.mj_rnePostConstraint):
        stage(m, data)
    a = wrench_regressor(m, data, bodies, arm.site_id, arm.sign)
    if gain:
        a = np.hstack([a, np.kron(np.eye(6), nominal)])  # row i: nominal_j at column 6 i + j
    return a, nominal
