"""What a calibration file tells the pipeline, beyond bias and payload: every fitted correction as a
``ContactPipeline`` keyword, so nothing ``ftc calibrate`` or ``ftc identify`` estimates is only saved.

- ``mount_yaw`` (rad, about the sensor's z): the sensor reads in a frame turned by it:
  ``frame = diag(Rz(yaw)^T, Rz(yaw)^T)``, undone on every reading;
- ``gravity_tilt_x``/``_y`` (rad, about the base x and y): the pipeline's gravity vector, tilted;
- ``arm_gravity_k``: the identifiable corrections to the links' masses and first moments
  (:class:`ArmGravityBasis`), as link inertial corrections that keep each link's inertia about its
  centre of mass;
- ``[identification]`` (``ftc identify``): link inertial corrections and the sensor's linear error on
  the arm's loads (``gain``).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ftc_hw.model import ArmModel
from ftc_hw.model.inertials import body_params, keep_com_inertia
from ftc_hw.scene import Scene

from .arm_gravity import ArmGravityBasis
from .regressor import GeometryModel, rot_z, tilt_rotation


def frame_of_yaw(yaw: float) -> np.ndarray:
    r = rot_z(yaw).T
    out = np.zeros((6, 6))
    out[:3, :3] = out[3:, 3:] = r
    return out


def extra_corrections(extras: dict[str, Any], scene: Scene) -> dict[str, Any]:
    """The pipeline's corrections (:class:`~ftc_hw.pipeline.Corrections` fields) of ``ftc calibrate``'s
    optional fits (those that are not zero)."""
    out: dict[str, Any] = {}
    yaw = float(extras.get("mount_yaw", 0.0) or 0.0)
    if yaw:
        out["frame"] = frame_of_yaw(yaw)
    tilt = (float(extras.get("gravity_tilt_x", 0.0) or 0.0), float(extras.get("gravity_tilt_y", 0.0) or 0.0))
    if any(tilt):
        out["gravity"] = tilt_rotation(tilt) @ np.asarray(scene.gravity, dtype=float)
    betas = sorted((k for k in extras if k.startswith("arm_gravity_")), key=lambda k: int(k.rsplit("_", 1)[1]))
    if betas and any(float(extras[k]) for k in betas):
        out["inertials"] = arm_gravity_inertials(scene, np.array([float(extras[k]) for k in betas]))
    return out


def arm_gravity_inertials(scene: Scene, beta: np.ndarray) -> dict[str, np.ndarray]:
    """Link inertial corrections (10 per body) of arm-gravity base parameters ``beta``."""
    gm = GeometryModel(ArmModel(scene))
    basis = ArmGravityBasis(gm)
    if len(beta) != basis.v.shape[1]:
        raise ValueError(f"{len(beta)} arm_gravity parameters, but this scene has {basis.v.shape[1]}")
    delta = basis.delta(beta).reshape(-1, 4)
    m = gm.arm.model
    out = {}
    for name, d4 in zip(gm.body_names, delta, strict=True):
        if np.any(d4):
            out[name] = keep_com_inertia(body_params(m, m.body(name).id), d4[0], d4[1:])
    return out


def merge_inertials(*tables: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for t in tables:
        for k, v in t.items():
            out[k] = out.get(k, 0.0) + np.asarray(v, dtype=float)
    return out
