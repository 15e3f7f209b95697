"""The static wrench model of a calibration: what the sensor reads at rest, linear in the parameters.

At rest the sensor reads its bias plus the weight of everything on its tool side (the arm's links
beyond the sensor, and the payload on the flange), in the sensor frame about the sensor origin and
with the scene's sign convention (docs/conventions.md):

    reading = b + s * [ R_s^T (-M g) ;  R_s^T (-(x - p_s) x M g) ]

with ``s`` = +1 for ``base_on_arm`` and -1 for ``arm_on_base``, ``M`` the mass and ``x`` the centre of
mass of the load. The payload's share is linear in ``(m, m c)`` (c in the flange frame):
``m (p_f - p_s) + R_f (m c)`` is its first moment about the sensor origin. That gives the 10 core
parameters below; the optional ones (the sensor's mount rotation about its z axis, a tilt of gravity,
corrections to the arm's own link masses and first moments) enter through :func:`predict`.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from ftc_hw.model import ArmModel, descends

PARAMS: tuple[str, ...] = (
    "force_bias_x", "force_bias_y", "force_bias_z", "torque_bias_x", "torque_bias_y", "torque_bias_z",
    "mass", "mass_com_x", "mass_com_y", "mass_com_z",
)
N_CORE = len(PARAMS)


@dataclass(frozen=True)
class PoseGeometry:
    """What the static model needs from the arm at joint angles ``q`` (base frame, SI)."""

    q: np.ndarray
    base_R_sensor: np.ndarray
    base_p_sensor: np.ndarray
    base_R_flange: np.ndarray
    base_p_flange: np.ndarray
    arm_mass: float  # kg beyond the sensor (without payload)
    arm_com: np.ndarray  # its centre of mass
    link_R: np.ndarray  # (k, 3, 3) orientation of each body beyond the sensor
    link_p: np.ndarray  # (k, 3) origin of each body


class GeometryModel:
    """Pose geometry from the scene's MuJoCo model (no payload: the payload is what we identify)."""

    def __init__(self, arm: ArmModel) -> None:
        if arm.payload is not None:
            raise ValueError("the calibration's arm model must not carry a payload")
        if arm.scene.robot.flange is None:
            raise ValueError(f"scene {arm.scene.name!r} names no flange site: a payload needs one")
        self.arm = arm
        self.scene = arm.scene
        m = arm.model
        self.flange_id = m.site(arm.scene.robot.flange).id
        sb = arm.sensor_body
        self.bodies = [b for b in range(1, m.nbody) if descends(m, b, sb)]
        self.body_names = [m.body(b).name for b in self.bodies]
        self.gravity = np.asarray(arm.scene.gravity, dtype=float)
        self.sign = arm.sign

    def at(self, q) -> PoseGeometry:
        arm = self.arm
        arm.kinematics(q)  # validates q, runs mj_kinematics on arm.data
        m, d = arm.model, arm.data
        mujoco.mj_comPos(m, d)
        b = self.bodies
        return PoseGeometry(
            q=np.asarray(q, dtype=float).copy(),
            base_R_sensor=d.site_xmat[arm.site_id].reshape(3, 3).copy(),
            base_p_sensor=d.site_xpos[arm.site_id].copy(),
            base_R_flange=d.site_xmat[self.flange_id].reshape(3, 3).copy(),
            base_p_flange=d.site_xpos[self.flange_id].copy(),
            arm_mass=float(arm.total_mass),
            arm_com=d.subtree_com[arm.sensor_body].copy(),
            link_R=d.xmat[b].reshape(-1, 3, 3).copy(),
            link_p=d.xpos[b].copy(),
        )


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def tilt_rotation(tilt) -> np.ndarray:
    """Small rotation of gravity about the base x and y axes (rad), exact (Rodrigues)."""
    v = np.array([tilt[0], tilt[1], 0.0])
    a = float(np.linalg.norm(v))
    if a == 0.0:
        return np.eye(3)
    k = v / a
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * kx + (1 - np.cos(a)) * kx @ kx


def core_rows(g: PoseGeometry, gravity: np.ndarray, sign: float, yaw: float = 0.0,
              tilt=(0.0, 0.0)) -> np.ndarray:
    """The 6 x 10 regressor of one pose: reading - arm's own load = rows @ theta (the reading is linear
    in theta: also :func:`predict`'s exact derivative in theta at that mount yaw and gravity tilt)."""
    grav = tilt_rotation(tilt) @ gravity
    rm = g.base_R_sensor @ rot_z(yaw)
    a = np.zeros((6, N_CORE))
    a[:, :6] = np.eye(6)
    a[:3, 6] = sign * (rm.T @ -grav)
    a[3:, 6] = sign * (rm.T @ -np.cross(g.base_p_flange - g.base_p_sensor, grav))
    # -(R_f h) x g = g x (R_f h) = [g]x R_f h
    gx = np.array([[0, -grav[2], grav[1]], [grav[2], 0, -grav[0]], [-grav[1], grav[0], 0]])
    a[3:, 7:10] = sign * (rm.T @ gx @ g.base_R_flange)
    return a


def arm_load(g: PoseGeometry, gravity: np.ndarray, sign: float) -> np.ndarray:
    """The arm's own static load on the sensor (sensor frame, scene convention), no payload, no bias."""
    w = g.arm_mass * gravity
    rs = g.base_R_sensor
    return sign * np.concatenate([rs.T @ -w, rs.T @ -np.cross(g.arm_com - g.base_p_sensor, w)])


def arm_param_rows(g: PoseGeometry, gravity: np.ndarray, sign: float, yaw: float = 0.0,
                   tilt=(0.0, 0.0)) -> np.ndarray:
    """6 x 4k: d(reading)/d(link mass, link first moment in the link frame) for each body beyond the
    sensor (the reading is linear in them: :func:`predict`'s exact derivative at that yaw and tilt)."""
    grav = tilt_rotation(tilt) @ gravity
    rm = g.base_R_sensor @ rot_z(yaw)
    k = len(g.link_p)
    out = np.zeros((6, 4 * k))
    gx = np.array([[0, -grav[2], grav[1]], [grav[2], 0, -grav[0]], [-grav[1], grav[0], 0]])
    for i in range(k):
        out[:3, 4 * i] = sign * (rm.T @ -grav)
        out[3:, 4 * i] = sign * (rm.T @ -np.cross(g.link_p[i] - g.base_p_sensor, grav))
        out[3:, 4 * i + 1:4 * i + 4] = sign * (rm.T @ gx @ g.link_R[i])
    return out


def predict(g: PoseGeometry, theta: np.ndarray, gravity: np.ndarray, sign: float, yaw: float = 0.0,
            tilt=(0.0, 0.0), arm_delta: np.ndarray | None = None) -> np.ndarray:
    """The full static reading at one pose: bias + arm + payload, with a mount yaw (rad, about the
    sensor's z), a gravity tilt (rad about base x, y) and link mass-parameter corrections (4 per body)."""
    grav = tilt_rotation(tilt) @ gravity
    rm = g.base_R_sensor @ rot_z(yaw)
    m, h = float(theta[6]), np.asarray(theta[7:10])
    mass = g.arm_mass + m
    first = g.arm_mass * (g.arm_com - g.base_p_sensor) + m * (g.base_p_flange - g.base_p_sensor) + g.base_R_flange @ h
    if arm_delta is not None:
        dm = arm_delta[0::4]
        mass += float(dm.sum())
        first = first + dm @ (g.link_p - g.base_p_sensor)
        first = first + np.einsum("kij,kj->i", g.link_R, arm_delta.reshape(-1, 4)[:, 1:])
    f = -mass * grav
    t = -np.cross(first, grav)
    return np.asarray(theta[:6]) + sign * np.concatenate([rm.T @ f, rm.T @ t])
