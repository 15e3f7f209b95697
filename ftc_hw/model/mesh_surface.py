"""Localizing on a link's meshes: where a contact's line of action enters the link's true shell.

The solver works on primitives; given its estimate (a point on the line of action and the force), the
contact on a mesh shell is where that line, followed along the force from outside, first meets the
link's mesh triangles (MuJoCo's ray-mesh test). ``ftc bench reality`` measures this against the
fitted primitives (docs/reality.md: the primitives are kept)."""
from __future__ import annotations

import mujoco
import numpy as np

from .mesh_fit import SURFACE_GROUP

_REACH_M = 0.3  # the line is followed from this far before the estimate


class MeshShell:
    """The touchable mesh geoms of a compiled model (the true arm's, or a user's unfitted model)."""

    def __init__(self, model: mujoco.MjModel, joint_qpos: np.ndarray) -> None:
        """``joint_qpos``: for each scene joint, its qpos address in ``model`` (int array)."""
        self.model = model
        self.data = mujoco.MjData(model)
        self.qadr = np.asarray(joint_qpos, dtype=int)
        self.meshes: dict[str, list[int]] = {}
        for g in range(model.ngeom):
            if model.geom_group[g] == SURFACE_GROUP and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
                self.meshes.setdefault(model.body(int(model.geom_bodyid[g])).name, []).append(g)

    def entry(self, link: str, q: np.ndarray, point: np.ndarray, force: np.ndarray) -> np.ndarray | None:
        """Where the line ``point + s force`` (base frame), coming along the force, enters ``link``'s
        meshes at joint positions ``q``; None when the link has no mesh or the line misses it."""
        geoms = self.meshes.get(link)
        f = np.linalg.norm(force)
        if not geoms or f == 0.0:
            return None
        self.data.qpos[self.qadr] = q
        mujoco.mj_kinematics(self.model, self.data)
        u = np.asarray(force, dtype=float) / f
        start = np.asarray(point, dtype=float) - _REACH_M * u
        hits = [h for h in (mujoco.mj_rayMesh(self.model, self.data, g, start, u) for g in geoms) if h >= 0.0]
        return start + min(hits) * u if hits else None
