"""The Cramer-Rao bound of a contact: what the sensor noise allows any unbiased estimator, for the
6-D wrench measurement with the point constrained to the surface (base frame, m and N)."""
from __future__ import annotations

import math

import numpy as np

from ..geometry.vec import tangent_basis
from . import kernels as K


def _crlb(solver, point, normal, force) -> tuple[np.ndarray, np.ndarray]:
    """Cramer-Rao bound (J^T W J)^-1 at the truth for the 6-D wrench measurement with the point
    constrained to the surface, over (two tangent coordinates, force); and the tangent basis."""
    t1, t2 = np.empty(3), np.empty(3)
    tangent_basis(np.asarray(normal, dtype=float), t1, t2)
    jac = np.empty((6, 5))
    K._jacobian(np.asarray(point, dtype=float), np.asarray(force, dtype=float), t1, t2, jac)
    return np.linalg.inv(jac.T @ solver._W0 @ jac), np.stack([t1, t2], axis=1)


def crlb_point_cov(solver, point, normal, force) -> np.ndarray:
    """Cramer-Rao bound of the contact point (3x3, base frame, rank 2)."""
    cov, tb = _crlb(solver, point, normal, force)
    return tb @ cov[:2, :2] @ tb.T


def crlb_magnitude_std(solver, point, normal, force) -> tuple[float, float]:
    """Standard deviations (N) of the force magnitude: at the Cramer-Rao bound, and from the force
    reading alone (|f_measured|, the paper's magnitude). They differ only where the moment tells
    something about the force's scale: where the point's constraint is not perpendicular to the
    force in the noise's metric. With isotropic force noise they are equal, and no unbiased
    estimator from this wrench can beat |f_measured| on magnitude."""
    cov, _ = _crlb(solver, point, normal, force)
    u = np.asarray(force, dtype=float) / np.linalg.norm(force)
    force_only = np.linalg.inv(solver._W0)[:3, :3]
    return math.sqrt(float(u @ cov[2:, 2:] @ u)), math.sqrt(float(u @ force_only @ u))
