"""What the identified model may still get wrong, as wrench covariance rows for detection and the
solver: the identification's parameter covariance (what the motion could not tell keeps its prior's)
carried through the regressor of the current state, less its share at the tare's state (which the
tare absorbs), so it grows with the distance from the tare's pose, the speed and the acceleration.

``rows`` is recomputed at most every ``refresh_ns`` (the regressor costs a few hundred microseconds);
it returns six rows ``u_k`` with ``sum u_k u_k^T`` the covariance (the detector's and solver's form).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import mujoco
import numpy as np

from ..model import ArmModel
from ..model.inertials import N_PARAMS, model_rows

REFRESH_NS = 10_000_000


class ModelError:
    def __init__(self, arm: ArmModel, bodies: Sequence[str], cov: np.ndarray, gain: bool,
                 refresh_ns: int = REFRESH_NS) -> None:
        m = arm.model
        self.arm = arm
        self.body_ids = [m.body(b).id for b in bodies]
        self.gain = gain
        n = N_PARAMS * len(bodies) + (36 if gain else 0)
        cov = np.asarray(cov, dtype=float)
        if cov.shape != (n, n):
            raise ValueError(f"model error covariance: expected {n} x {n} for {len(bodies)} bodies"
                             f"{' and the gain' if gain else ''}, got {cov.shape}")
        vals, vecs = np.linalg.eigh((cov + cov.T) / 2)
        keep = vals > max(vals.max(), 0.0) * 1e-12
        self.factor = vecs[:, keep] * np.sqrt(vals[keep])  # cov = factor factor^T
        self.refresh_ns = refresh_ns
        self._data = mujoco.MjData(m)
        self._tare: np.ndarray | None = None  # the regressor at the tare's state
        self._rows = np.zeros((6, 6))
        self._t = None

    @staticmethod
    def from_kwargs(arm: ArmModel, spec: Mapping[str, Any]) -> ModelError:
        """From the pipeline keyword ``model_error``: ``{"bodies", "cov", "gain"}``."""
        return ModelError(arm, list(spec["bodies"]), np.asarray(spec["cov"], dtype=float), bool(spec["gain"]))

    def _regressor(self, q, qd, qdd) -> np.ndarray:
        return model_rows(self.arm, self._data, self.body_ids, q, qd, qdd, self.gain)[0]

    def set_tare(self, q) -> None:
        z = np.zeros_like(np.asarray(q, dtype=float))
        self._tare = self._regressor(q, z, z)
        self._t = None

    def rows_regressor(self, q, qd, qdd) -> np.ndarray:
        """The regressor of this state less the tare's (6 x parameters): the reading's change with the
        parameters, as the tared pipeline sees it."""
        a = self._regressor(q, qd, qdd)
        return a if self._tare is None else a - self._tare

    def rows(self, t_ns: int, q, qd, qdd) -> np.ndarray:
        """Six covariance rows (6 x 6) of the model's wrench error at this state."""
        if self._t is not None and t_ns - self._t < self.refresh_ns:
            return self._rows
        d = self.rows_regressor(q, qd, qdd) @ self.factor  # 6 x r
        cov = d @ d.T
        vals, vecs = np.linalg.eigh(cov)
        self._rows = np.ascontiguousarray((vecs * np.sqrt(np.maximum(vals, 0.0))).T)
        self._t = t_ns
        return self._rows
