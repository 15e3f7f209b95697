"""A contact's normal: the arm's outward surface normal where a force presses a link.

The contact normal of the two-body model (ISO/TS 15066 A.3.3; the effective mass ``1 / (n^T J M^-1 J^T n)``)
is the touched surface's normal, not the line of the force: a push with friction leans off it by up to
``atan(mu)``. It is taken on the surface the pipeline answers on: a link's meshes
(:meth:`~ftc_hw.model.mesh_surface.MeshShell.normal`) or else its primitives (the solver's surfaces: the
normal at their point nearest the contact's). A few millimetres of localization can put the point past an
edge, where the surface turns away from the force by more than friction allows: such a normal is pulled
back into the force's friction cone.
"""
from __future__ import annotations

import math

import numpy as np

from ..geometry import normals, project
from .arm import ArmModel, PosedSurface
from .mesh_surface import MeshShell


def primitive_normal(surfaces: list[PosedSurface], link: str, point: np.ndarray) -> np.ndarray | None:
    """The outward unit normal (base frame) of ``link``'s primitives at their surface point nearest to
    ``point`` (m, base frame); ``surfaces`` posed at the contact's q (``ArmModel.posed_surfaces``). None
    when the link has no primitive."""
    p = np.asarray(point, dtype=float)
    best, normal = np.inf, None
    for ps in surfaces:
        if ps.surface.link != link:
            continue
        rot, origin = ps.base_T_geom[:3, :3], ps.base_T_geom[:3, 3]
        local = rot.T @ (p - origin)
        on = project(ps.surface.kind, ps.surface.size, local)[0]
        dist = float(np.linalg.norm(on - local))
        if dist < best:
            best, normal = dist, rot @ normals(ps.surface.kind, ps.surface.size, on)[0]
    return normal


def within_cone(normal: np.ndarray, axis: np.ndarray, half_angle: float) -> np.ndarray:
    """The unit ``normal`` if it lies within ``half_angle`` (rad) of the unit ``axis``, else the direction on
    the cone's boundary nearest to it (``axis`` itself when ``normal`` is opposite to it)."""
    cos_a = float(normal @ axis)
    if cos_a >= math.cos(half_angle):
        return normal
    across = normal - cos_a * axis
    k = float(np.linalg.norm(across))
    if k < 1e-9:
        return axis.copy()
    return math.cos(half_angle) * axis + math.sin(half_angle) * across / k


def contact_normal(*, arm: ArmModel, shell: MeshShell | None, link: str, q: np.ndarray, point: np.ndarray,
                   force: np.ndarray, mu: float) -> np.ndarray:
    """The outward unit surface normal (base frame) where ``force`` (N, base frame, applied to the arm,
    non-zero) presses ``point`` (m, base frame) of ``link`` at joint positions ``q``: the meshes' (``shell``,
    where it has the link) or else ``arm``'s primitives', within the friction cone of ``mu`` about the
    force's line; the force's line itself on a link with neither."""
    outward = -np.asarray(force, dtype=float) / float(np.linalg.norm(force))
    normal = None if shell is None else shell.normal(link, q, point, force)
    if normal is None:
        normal = primitive_normal(arm.posed_surfaces(q), link, point)
    if normal is None:
        return outward
    return within_cone(normal, outward, math.atan(mu))
