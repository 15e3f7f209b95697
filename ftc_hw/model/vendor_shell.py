"""The vendor's meshes as a touched surface: each mapped body's visual meshes placed in our body frame.
The world's true shell (``[world] vendor_shell``: its probes press them, its obstacles collide with
them, each body's meshes shifted by the drawn ``vendor_shell_shift``), and the pipeline's surface where
the scene names them (``[robot] vendor_shell``: :func:`ftc_hw.model.mesh_surface.pipeline_mesh_shell`).
MuJoCo collides a mesh as the convex hull of each of its parts (about 1 s to compute for UR's); the
replaced primitives leave the surface and stop colliding.

The placement comes from the two models' kinematics at the joints' zero: a vendor body's pose, turned
from the vendor's base frame into ours (``VendorShell.base_yaw``), relative to our body's pose.
"""
from __future__ import annotations

from collections.abc import Mapping

import mujoco
import numpy as np

from ..scene import Scene, SceneError
from ..scene.vendor import VENDOR_SHELLS, shell_model
from .arm import pose
from .mesh_fit import SURFACE_GROUP, quat_matrix

_MESH = mujoco.mjtGeom.mjGEOM_MESH
_OFF_GROUP = 3  # where a replaced primitive goes: out of the surface


def attach_vendor_shell(spec: mujoco.MjSpec, scene: Scene, name: str, *, collide: bool = True,
                        shifts: Mapping[str, np.ndarray] | None = None) -> None:
    """Put shell ``name``'s visual meshes (what a hand touches) on ``spec``'s bodies (in place).
    ``collide``: the meshes, not the primitives they replace, meet obstacles (the world; the pipeline
    only follows lines into them); ``shifts``: per body, m in its frame, where the real shell lies off
    the vendor's drawing."""
    shell = VENDOR_SHELLS[name]
    path = shell_model(name)
    if not path.is_file():
        raise SceneError(scene.path, "world.vendor_shell",
                         f"the {name} meshes are not on this machine ({path}): run `ftc scenes meshes` "
                         f"(it fetches {shell.requirement}, {shell.licence})")
    for body in shifts or {}:
        if body not in shell.bodies:
            raise SceneError(scene.path, f"world.vendor_shell_shift_m.{body}",
                             f"{name} has no meshes on body {body!r} (it covers {', '.join(shell.bodies)})")
    vendor = mujoco.MjSpec.from_file(str(path))
    files = {m.name: path.parent / vendor.meshdir / m.file for m in vendor.meshes}
    visuals = [(g.parent.name, g.meshname, _pose(g.pos, g.quat)) for g in vendor.geoms
               if g.type == _MESH and not (g.contype or g.conaffinity)]
    vendor_poses = _zero_pose_bodies(vendor, strip_meshes=True)
    our_poses = _zero_pose_bodies(spec.copy(), strip_meshes=False)
    turn = _pose(np.zeros(3), [np.cos(shell.base_yaw / 2), 0.0, 0.0, -np.sin(shell.base_yaw / 2)])
    for ours, theirs in shell.bodies.items():
        body = spec.body(ours)
        if body is None:
            raise SceneError(scene.path, "world.vendor_shell", f"{name} maps onto body {ours!r}, which the arm lacks")
        for g in spec.geoms:  # no longer the surface
            if g.parent.name == ours and g.group == SURFACE_GROUP:
                g.group = _OFF_GROUP
                if collide:
                    g.contype = g.conaffinity = 0
        shift = np.asarray((shifts or {}).get(ours, np.zeros(3)), dtype=float)
        for k, (_, mesh, geom_pose) in enumerate(v for v in visuals if v[0] == theirs):
            mesh_name = f"vendor_{ours}_{k}"
            spec.add_mesh(name=mesh_name, file=str(files[mesh]))
            t = np.linalg.inv(our_poses[ours]) @ turn @ vendor_poses[theirs] @ geom_pose
            quat = np.empty(4)
            mujoco.mju_mat2Quat(quat, t[:3, :3].ravel())
            # contype 1 / conaffinity 2: the obstacles' (2 / 1) meet it, the arm's own geoms never do
            body.add_geom(name=mesh_name, type=_MESH, meshname=mesh_name, pos=t[:3, 3] + shift, quat=quat,
                          group=SURFACE_GROUP, contype=int(collide), conaffinity=2 * int(collide), density=0.0)


def _zero_pose_bodies(spec: mujoco.MjSpec, strip_meshes: bool) -> dict[str, np.ndarray]:
    """Every body's pose (4x4, world) with every joint at zero."""
    if strip_meshes:  # kinematics only: no need to load (and hull) the meshes
        for g in [g for g in spec.geoms if g.type == _MESH]:
            spec.delete(g)
        for m in list(spec.meshes):
            spec.delete(m)
    m = spec.compile()
    d = mujoco.MjData(m)
    d.qpos[:] = 0.0
    mujoco.mj_kinematics(m, d)
    return {m.body(b).name: _pose(d.xpos[b], d.xquat[b]) for b in range(m.nbody)}


def _pose(pos, quat) -> np.ndarray:
    return pose(quat_matrix(quat), np.asarray(pos, dtype=float))

