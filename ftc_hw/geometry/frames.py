"""A primitive's pose: its centre ``pos`` (3) and rotation ``mat`` (9, row-major, as MuJoCo stores
geom_xmat), mapping local coordinates to the base frame. ``_s`` variants take and return scalars."""
from __future__ import annotations

from numba import njit

from .jit import JIT


@njit(inline="always", **JIT)
def to_local_s(pos, mat, x0, x1, x2):
    """mat^T (x - pos): a base-frame point in the primitive's frame."""
    dx, dy, dz = x0 - pos[0], x1 - pos[1], x2 - pos[2]
    return (mat[0] * dx + mat[3] * dy + mat[6] * dz, mat[1] * dx + mat[4] * dy + mat[7] * dz,
            mat[2] * dx + mat[5] * dy + mat[8] * dz)


@njit(**JIT)
def to_local(pos, mat, x, out):
    out[0], out[1], out[2] = to_local_s(pos, mat, x[0], x[1], x[2])


@njit(**JIT)
def dir_to_local(mat, v, out):
    out[0] = mat[0] * v[0] + mat[3] * v[1] + mat[6] * v[2]
    out[1] = mat[1] * v[0] + mat[4] * v[1] + mat[7] * v[2]
    out[2] = mat[2] * v[0] + mat[5] * v[1] + mat[8] * v[2]


@njit(inline="always", **JIT)
def to_base_s(pos, mat, x0, x1, x2):
    """pos + mat x: a local point in the base frame."""
    return (pos[0] + mat[0] * x0 + mat[1] * x1 + mat[2] * x2, pos[1] + mat[3] * x0 + mat[4] * x1 + mat[5] * x2,
            pos[2] + mat[6] * x0 + mat[7] * x1 + mat[8] * x2)


@njit(**JIT)
def to_base(pos, mat, x, out):
    out[0], out[1], out[2] = to_base_s(pos, mat, x[0], x[1], x[2])


@njit(**JIT)
def dir_to_base(mat, v, out):
    for i in range(3):
        out[i] = mat[3 * i] * v[0] + mat[3 * i + 1] * v[1] + mat[3 * i + 2] * v[2]
