"""Localizing on a link's meshes: where a contact's line of action enters the link's shell, and the
shell's normal there.

The solver works on primitives; given its estimate (a point on the line of action and the force), the
contact on a mesh shell is where that line, followed along the force from outside, first meets the
link's mesh triangles (MuJoCo's ray-mesh test). The pipeline answers on the meshes where the scene has
them (``[robot] vendor_shell``, or a user's model with mesh collision geoms): :func:`pipeline_mesh_model`.
"""
from __future__ import annotations

from collections.abc import Mapping

import mujoco
import numpy as np

from ..scene import Scene
from ..scene.vendor import VENDOR_SHELLS, shell_fetched
from .build import load_spec
from .joint_map import JointMap
from .mesh_fit import SURFACE_GROUP
from .vendor_shell import attach_vendor_shell

_REACH_M = 0.3  # the line is followed from this far before the estimate


class MeshShell:
    """The touchable mesh geoms of a compiled model; one per thread (it poses its own MjData)."""

    def __init__(self, model: mujoco.MjModel, scene: Scene, tolerance: Mapping[str, float] | None = None) -> None:
        """``tolerance``: per link, 1 sigma (m) of the real shell's distance from its meshes (default: the
        scene's ``surface_tolerance_m``)."""
        self.model = model
        self.data = mujoco.MjData(model)
        self.joints = JointMap(model, scene)
        self.meshes: dict[str, list[int]] = {}
        for g in range(model.ngeom):
            if model.geom_group[g] == SURFACE_GROUP and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
                self.meshes.setdefault(model.body(int(model.geom_bodyid[g])).name, []).append(g)
        given = tolerance or {}
        self.tolerance = {link: given.get(link, scene.robot.surface_tolerance) for link in self.meshes}
        self._facet = np.zeros(3)  # mj_rayMesh's normal out

    def entry(self, link: str, q: np.ndarray, point: np.ndarray, force: np.ndarray) -> np.ndarray | None:
        """Where the line ``point + s force`` (base frame), coming along the force, enters ``link``'s
        meshes at joint positions ``q``; None when the link has no mesh or the line misses it."""
        line = self._line(link, q, point, force)
        if line is None:
            return None
        geoms, start, u = line
        hits = [h for h in (mujoco.mj_rayMesh(self.model, self.data, g, start, u) for g in geoms) if h >= 0.0]
        return start + min(hits) * u if hits else None

    def normal(self, link: str, q: np.ndarray, point: np.ndarray, force: np.ndarray) -> np.ndarray | None:
        """The outward unit normal (base frame) of the first of ``link``'s mesh triangles that the line
        :meth:`entry` follows meets: the surface's normal where the contact is; None when the link has no
        mesh or the line misses it."""
        line = self._line(link, q, point, force)
        if line is None:
            return None
        geoms, start, u = line
        best, normal, facet = -1.0, None, self._facet
        for g in geoms:
            h = mujoco.mj_rayMesh(self.model, self.data, g, start, u, facet)
            if h >= 0.0 and (best < 0.0 or h < best):
                best, normal = h, facet.copy()
        if normal is None:
            return None
        return normal if normal @ u <= 0.0 else -normal  # the side the line came from: outward

    def _line(self, link: str, q: np.ndarray, point: np.ndarray,
              force: np.ndarray) -> tuple[list[int], np.ndarray, np.ndarray] | None:
        """The link's meshes posed at q, and the line's start outside them and its unit direction."""
        geoms = self.meshes.get(link)
        f = np.linalg.norm(force)
        if not geoms or not f > 0.0:
            return None
        self.joints.set_qpos(np.asarray(q, dtype=float), self.data.qpos)
        mujoco.mj_kinematics(self.model, self.data)
        u = np.asarray(force, dtype=float) / f
        return geoms, np.asarray(point, dtype=float) - _REACH_M * u, u


def pipeline_mesh_shell(scene: Scene) -> MeshShell | None:
    """The meshes the pipeline localizes on: the scene's model with its touchable meshes unfitted and
    the vendor's meshes it names, where fetched (as drawn: the pipeline knows no real arm's shift);
    None without any."""
    vendor = scene.robot.vendor_shell if shell_fetched(scene.robot.vendor_shell or "") else None
    key = (str(scene.path), str(scene.robot.model_path), vendor)
    if key not in _MODELS:
        _MODELS[key] = _mesh_model(scene, vendor)
    model = _MODELS[key]
    if model is None:
        return None
    v = VENDOR_SHELLS.get(vendor or "")
    return MeshShell(model, scene, {body: v.tolerance_m for body in v.bodies} if v else None)


_MODELS: dict[tuple[str, str, str | None], mujoco.MjModel | None] = {}  # compiled once per process


def _mesh_model(scene: Scene, vendor: str | None) -> mujoco.MjModel | None:
    """The compiled model with its touchable meshes; None (nothing compiled) when it has none."""
    spec = load_spec(scene, fit_meshes=False)
    if vendor is not None:
        attach_vendor_shell(spec, scene, vendor, collide=False)
    if not any(g.group == SURFACE_GROUP and g.type == mujoco.mjtGeom.mjGEOM_MESH for g in spec.geoms):
        return None
    return spec.compile()
