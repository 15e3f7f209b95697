"""Contact onset and offset from the external joint torques: the F/T detector's test (chi-square against
the residual's covariance, hysteresis, debounce) on an n-dimensional statistic whose covariance changes
every sample (the friction's and the model's share follow the motion).

Without contact the momentum observer's residual r (n,) is noise with covariance ``cov`` (n x n), so
d2 = r^T cov^-1 r follows a chi-square law with n degrees of freedom: onset when d2 exceeds the quantile
for a per-sample false-alarm probability ``p_false`` for ``n_on`` samples (the onset time the first of
them), offset when it stays below ``release`` x that for ``n_off`` samples -- the settings of
:class:`~ftc_hw.detection.ContactDetector`, which is fixed to a 6-D wrench.

Per-link subspaces (``subspaces``): a contact on a link puts torque only on the joints that move it, the
first k of a serial chain (k = 1 for a UR's shoulder, turned by the pan joint alone). The matched-subspace
detector (Scharf & Friedlander, "Matched subspace detectors", IEEE T-SP 42(8), 1994) tests the residual's
energy in that subspace, whitened by the whole covariance: ``d2_k = (H^T C^-1 r)^T (H^T C^-1 H)^-1 (H^T
C^-1 r)`` with H the first k unit vectors, a chi-square with k degrees of freedom without contact: its
threshold is lower than the full test's, so a contact on a proximal link needs less torque to be seen.
One test per distinct k; each at ``p_false / (number of tests)`` (a union bound: the per-sample false-
alarm probability of "any test fires" stays at most ``p_false``). The statistic handed to the hysteresis
is ``on x max_k (d2_k / on_k)``, ``on`` the largest subspace's threshold: above ``on`` when any test
fires, below ``release x on`` when every d2_k is below ``release x on_k``.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .detector import ContactDetector, Detection
from .kernels import chol_quad, nested_quads


def _gamma_q(a: float, x: float) -> float:
    """The regularized upper incomplete gamma function Q(a, x) (series below a + 1, Lentz's continued
    fraction above: Numerical Recipes' gammq)."""
    if x <= 0.0:
        return 1.0
    log_front = a * math.log(x) - x - math.lgamma(a)
    if x < a + 1.0:
        term = total = 1.0 / a
        ap = a
        for _ in range(1000):
            ap += 1.0
            term *= x / ap
            total += term
            if abs(term) < abs(total) * 1e-15:
                break
        return max(0.0, 1.0 - total * math.exp(log_front))
    tiny = 1e-300
    b = x + 1.0 - a
    c = 1.0 / tiny
    d = 1.0 / b
    h = d
    for i in range(1, 1000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = tiny if abs(d) < tiny else d
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-15:
            break
    return math.exp(log_front) * h


def chi2_sf(x: float, dof: int) -> float:
    """Survival function of the chi-square law with ``dof`` degrees of freedom."""
    return _gamma_q(0.5 * dof, 0.5 * x)


def chi2_isf(p: float, dof: int) -> float:
    """The x with chi2_sf(x, dof) = p (bisection; p in (0, 1))."""
    if not 0.0 < p < 1.0:
        raise ValueError("p must be in (0, 1)")
    lo, hi = 0.0, 10.0 + dof
    while chi2_sf(hi, dof) > p:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if chi2_sf(mid, dof) > p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def mahalanobis_n(r: np.ndarray, cov: np.ndarray) -> float:
    """r^T cov^-1 r for r (n,) and cov (n, n); inf when cov is not positive definite or r is not finite."""
    d2 = chol_quad(r, cov.copy())
    return d2 if math.isfinite(d2) else math.inf


class JointDetector(ContactDetector):
    """The chi-square test with hysteresis on an n-dimensional residual (see the module's notes): the
    F/T detector's state machine, its statistic r^T cov^-1 r with a covariance given every sample, or the
    per-link matched-subspace tests' combined statistic."""

    def __init__(self, n: int, *, p_false: float = 1e-9, release: float = 0.25, n_on: int = 2,
                 n_off: int = 5, subspaces: Sequence[int] | None = None) -> None:
        """``subspaces``: the sizes k of the leading blocks of r to test (each 1..n; None: n alone, the
        full test)."""
        if n < 1:
            raise ValueError("the residual needs at least one joint")
        ks = sorted(set(subspaces)) if subspaces else [n]
        if ks[0] < 1 or ks[-1] > n:
            raise ValueError(f"subspaces must lie in 1..{n}, got {ks}")
        self.n = self.dof = n
        self.subspaces = tuple(ks)
        each = p_false / len(ks)
        self.on_k = np.array([chi2_isf(each, k) for k in ks])
        self._k_index = np.array(ks) - 1
        self._quads = np.empty(n)
        self._hysteresis(float(self.on_k[-1]), release, n_on, n_off, 0.0)

    def statistic(self, r, cov) -> float:
        """d2 = r^T cov^-1 r, or with subspaces ``on x max_k (d2_k / on_k)`` (inf: a broken covariance or a
        non-finite residual)."""
        r = np.asarray(r, dtype=float)
        cov = np.asarray(cov, dtype=float)
        if self.subspaces == (self.n,):
            return mahalanobis_n(r, cov)
        if not nested_quads(r, cov, self._quads):
            return math.inf
        d2 = self.on * float(np.max(self._quads[self._k_index] / self.on_k))
        return d2 if math.isfinite(d2) else math.inf

    def update(self, t_ns: int, r, cov, release=None) -> Detection:
        """One sample's residual r (n,) N m and its covariance cov (n, n) N^2 m^2. ``release``: in contact,
        the (r, cov) the offset is judged on instead (``JointResidual.release``: a stuck joint's static
        friction as the bound it is); None: r and cov. ``ValueError`` when d2 is not finite (the pipeline
        checks its inputs before)."""
        d2 = self.statistic(r, cov)
        if not math.isfinite(d2):
            raise ValueError("joint residual or its covariance holds NaN or Inf, or the covariance is singular")
        d2_release = d2 if release is None or not self.active else self.statistic(*release)
        change, _ = self._judge(t_ns, d2, None, d2_release)
        return Detection(self.active, d2, False, 1.0 - chi2_sf(d2, self.dof), change, self.onset_t_ns)
