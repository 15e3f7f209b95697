"""Where a probe meets a true arm's mesh shell: the point the model's surface point would be pressed
at, found along the model's outward normal (MuJoCo's ray-mesh test, the mesh's own triangles), and
the shell's normal there (the contact's true normal)."""
from __future__ import annotations

import mujoco
import numpy as np

from ftc_hw.model.mesh_fit import SURFACE_GROUP

_REACH_M = 0.05  # how far outside the model's surface the ray starts


def shell_meshes(m: mujoco.MjModel, body: int) -> list[int]:
    """The body's mesh geoms in the surface group: its true shell (none: the shell is its primitives)."""
    return [g for g in range(m.ngeom) if m.geom_bodyid[g] == body and m.geom_group[g] == SURFACE_GROUP
            and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH]


def mesh_point(m: mujoco.MjModel, d: mujoco.MjData, body: int, point_link: np.ndarray,
               outward_link: np.ndarray) -> np.ndarray | None:
    """The first shell point a ray meets coming in along ``-outward_link`` from outside ``point_link``
    (body frame in and out; ``d`` posed by a forward pass); None when it misses every mesh."""
    hit = mesh_hit(m, d, body, point_link, outward_link)
    return None if hit is None else hit[0]


def mesh_hit(m: mujoco.MjModel, d: mujoco.MjData, body: int, point_link: np.ndarray,
             outward_link: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`mesh_point` and the shell's outward unit normal there (its triangle's), both in the body
    frame; None when the ray misses every mesh."""
    rot, pos = d.xmat[body].reshape(3, 3), d.xpos[body]
    n = rot @ (outward_link / np.linalg.norm(outward_link))
    start = rot @ point_link + pos + _REACH_M * n
    best, normal, facet = -1.0, np.zeros(3), np.zeros(3)
    for g in shell_meshes(m, body):
        h = mujoco.mj_rayMesh(m, d, g, start, -n, facet)
        if h >= 0.0 and (best < 0.0 or h < best):
            best, normal = h, facet.copy()
    if best < 0.0:
        return None
    normal = normal if normal @ n >= 0.0 else -normal  # the triangle's side the ray came from: outward
    return rot.T @ (start - best * n - pos), rot.T @ normal
