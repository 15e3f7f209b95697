"""numpy-facing wrappers of the engine for callers that are not hot (the paper's method, the world,
tests, benches): arrays of points or lines in, arrays out, one compiled loop per call.

Points and lines are (N, 3) or (3,) arrays in the primitive's local frame (metres); a line is
``o + s d`` with d a unit vector (one of o, d may be a single row for all). ``kind`` is a name or a
code (kinds.py); ``size`` a MuJoCo ``geom_size`` row (shorter rows are padded with zeros).
"""
from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from .closest import quadric_closest_local
from .crossings import crossings_local, quadric_crossings_local
from .frames import dir_to_local, to_local
from .jit import JIT, JIT_ALLOC
from .kinds import kind_code
from .solid import inside_local
from .surface import normal_local, project_s

FloatArray = NDArray[np.float64]


def _rows(x: ArrayLike) -> FloatArray:
    return np.ascontiguousarray(np.asarray(x, dtype=np.float64).reshape(-1, 3))


def _line_rows(o: ArrayLike, d: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Lines' origins and directions as (N, 3) rows, one broadcast against the other."""
    o_b, d_b = np.broadcast_arrays(_rows(o), _rows(d))
    return np.ascontiguousarray(o_b), np.ascontiguousarray(d_b)


def _size_row(size: ArrayLike) -> FloatArray:
    s = np.zeros(3)
    flat = np.asarray(size, dtype=np.float64).reshape(-1)[:3]
    s[:flat.size] = flat
    return s


@njit(**JIT)
def _crossings_rows(kind, size, o, d, count, s):
    for i in range(o.shape[0]):
        count[i] = crossings_local(kind, size, o[i], d[i], s[i])


@njit(**JIT)
def _quadric_crossings_rows(k, o, d, count, s):
    for i in range(o.shape[0]):
        count[i] = quadric_crossings_local(k, o[i], d[i], s[i])


@njit(**JIT)
def _inside_rows(kind, size, x, tol, out):
    for i in range(x.shape[0]):
        out[i] = inside_local(kind, size, x[i], tol)


@njit(**JIT)
def _normal_rows(kind, size, x, out):
    for i in range(x.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = normal_local(kind, size, x[i, 0], x[i, 1], x[i, 2])


@njit(**JIT)
def _project_rows(kind, size, x, out):
    for i in range(x.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = project_s(kind, size, x[i, 0], x[i, 1], x[i, 2])


@njit(**JIT)
def _quadric_closest_rows(k, y, x, dist):
    for i in range(y.shape[0]):
        dist[i] = quadric_closest_local(k, y[i], x[i])


def crossings(kind: int | str, size: ArrayLike, o: ArrayLike, d: ArrayLike) -> tuple[NDArray[np.int64], FloatArray]:
    """Entry and exit of lines through a closed primitive: the count per line (0, 1 for a plane, 2
    otherwise; a tangent line gives a double root) and s (N, 2), sorted, NaN in unused slots."""
    o, d = _line_rows(o, d)
    count = np.zeros(len(o), dtype=np.int64)
    s = np.full((len(o), 2), np.nan)
    _crossings_rows(kind_code(kind), _size_row(size), o, d, count, s)
    return count, s


def quadric_crossings(k: ArrayLike, o: ArrayLike, d: ArrayLike) -> tuple[NDArray[np.int64], FloatArray]:
    """Crossings of lines with the quadric ``|k * x| = 1`` (k: inverse semi-axes, 0 for an infinite
    axis): the count per line (0 or 2) and s (N, 2), sorted, NaN when missed."""
    o, d = _line_rows(o, d)
    count = np.zeros(len(o), dtype=np.int64)
    s = np.full((len(o), 2), np.nan)
    _quadric_crossings_rows(_size_row(k), o, d, count, s)
    return count, s


def inside(kind: int | str, size: ArrayLike, points: ArrayLike, tol: float = 0.0) -> NDArray[np.bool_]:
    """Points strictly inside the solid by more than ``tol`` (m), (N,)."""
    x = _rows(points)
    out = np.zeros(len(x), dtype=np.bool_)
    _inside_rows(kind_code(kind), _size_row(size), x, float(tol), out)
    return out


def normals(kind: int | str, size: ArrayLike, points: ArrayLike) -> FloatArray:
    """Outward unit normals (N, 3) at surface points."""
    x = _rows(points)
    out = np.empty_like(x)
    _normal_rows(kind_code(kind), _size_row(size), x, out)
    return out


def project(kind: int | str, size: ArrayLike, points: ArrayLike) -> FloatArray:
    """Surface points (N, 3) near the points: the closest ones, except for ellipsoids (the radial
    retraction; see :func:`quadric_closest`)."""
    x = _rows(points)
    out = np.empty_like(x)
    _project_rows(kind_code(kind), _size_row(size), x, out)
    return out


def quadric_closest(k: ArrayLike, points: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """The points of ``|k * x| = 1`` nearest to the points (N, 3), and their signed distances (N,)
    (negative inside)."""
    y = _rows(points)
    x = np.empty_like(y)
    dist = np.empty(len(y))
    _quadric_closest_rows(_size_row(k), y, x, dist)
    return x, dist


@njit(**JIT_ALLOC)
def _ray_distance(kind, size, pos, mat, start, u):
    o, d, s = np.empty(3), np.empty(3), np.empty(2)
    to_local(pos, mat, start, o)
    dir_to_local(mat, u, d)
    for j in range(crossings_local(kind, size, o, d, s)):
        if s[j] >= 0.0:
            return s[j]
    return -1.0


def ray_distance(kind: int | str, size: ArrayLike, pos: ArrayLike, mat: ArrayLike, start: ArrayLike,
                 u: ArrayLike) -> float:
    """Distance along the unit direction u from ``start`` (base frame) to the first crossing of a
    posed primitive at or past it (its entry, or its exit from inside), -1 when there is none.
    ``pos``, ``mat``: the primitive's centre and row-major rotation (MuJoCo's geom_xpos, geom_xmat)."""
    return float(_ray_distance(kind_code(kind), _size_row(size), np.asarray(pos, dtype=np.float64),
                               np.asarray(mat, dtype=np.float64).reshape(9), np.asarray(start, dtype=np.float64),
                               np.asarray(u, dtype=np.float64)))
