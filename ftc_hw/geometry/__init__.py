"""The line-primitive geometry engine (compiled with numba): crossings of a line with a primitive or
an unbounded quadric, surface normals and projections, inside tests and depth, the closest point of
an ellipsoid, and the frame transforms between a primitive's pose and the base frame.

Compiled kernels work in the primitive's local frame (MuJoCo geom conventions: centre at the origin,
capsules and cylinders along z; kinds.py) and allocate nothing, so the solver can call them on
every frame; arrays.py wraps them for numpy callers. ``tests/geometry_reference.py`` is a slower,
vectorised numpy implementation the tests hold the engine against.
"""
from __future__ import annotations

from .arrays import crossings, inside, normals, project, quadric_closest, quadric_crossings, ray_distance
from .kinds import BOX, CAPSULE, CYLINDER, ELLIPSOID, KINDS, PLANE, SPHERE, kind_code

__all__ = ["BOX", "CAPSULE", "CYLINDER", "ELLIPSOID", "KINDS", "PLANE", "SPHERE", "crossings", "inside", "kind_code",
           "normals", "project", "quadric_closest", "quadric_crossings", "ray_distance"]
