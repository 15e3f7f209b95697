"""Contact-free motion as the joints report it, prepared for :mod:`.joint_ident`: the good rows'
stretches (rows not finite or not after the one before left out and counted; a gap longer than
``MAX_GAP_S`` splits), each put on an even clock (jittered stamps), low-passed forward and back and
thinned as :mod:`.free_motion` does, qdd differentiated; the Coulomb column ``tanh(qd / V_EPS)`` is
low-passed with them (its step at a reversal would otherwise stand out of the low-passed current).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .free_motion import SMOOTH_S, IdentificationError, smooth

V_EPS = 0.01  # rad/s: the Coulomb term's smoothing, as the joint residuals use it
MAX_GAP_S = 0.05  # a longer gap between rows splits a stretch; shorter ones the even clock interpolates over


@dataclass
class JointMotionData:
    """Contact-free motion as the joints report it, in the scene's joint order: ``t`` (N,) s, ``q``,
    ``qd`` (N, n) rad, rad/s; ``current`` (N, n) A and/or ``tau_j`` (N, n) N m (None: not recorded).
    :class:`~.free_motion.MotionData` (with ``current``) is taken as it is."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    current: np.ndarray | None = None
    tau_j: np.ndarray | None = None


@dataclass
class Samples:
    """A prepared stretch: thinned, low-passed states and signals."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    sgn: np.ndarray  # tanh(qd / V_EPS) low-passed as the signals are: Coulomb friction's share of them
    signal: dict[str, np.ndarray]  # kind -> (M, n): currents in A, joint torques in N m


def _signals(seg, kinds: Sequence[str]) -> dict[str, np.ndarray]:
    out = {}
    for kind in kinds:
        v = getattr(seg, "current" if kind == "currents" else "tau_j", None)
        if v is None:
            raise IdentificationError(f"the motion has no {'motor currents' if kind == 'currents' else 'joint torques'}"
                                      " recorded: identify it with the sensing it has")
        out[kind] = np.asarray(v, dtype=float)
    return out


def _runs(t: np.ndarray, good: np.ndarray) -> list[np.ndarray]:
    """Index runs of good rows with strictly increasing times, split where a row is bad or a gap is
    longer than three typical steps and ``MAX_GAP_S`` (a loaded host's reader misses frames)."""
    idx = np.flatnonzero(good)
    if len(idx) < 2:
        return []
    keep = [idx[0]]
    for k in idx[1:]:
        if t[k] > t[keep[-1]]:
            keep.append(k)
    keep = np.array(keep)
    step = float(np.median(np.diff(t[keep])))
    bad_before = np.cumsum(~good)[keep]  # a bad row between two kept ones splits them; a repeated stamp does not
    breaks = np.flatnonzero((np.diff(bad_before) > 0) | (np.diff(t[keep]) > max(3 * step, MAX_GAP_S))) + 1
    return np.split(keep, breaks)


def prepare_joint_motion(seg, kinds: Sequence[str], smooth_s: float = SMOOTH_S) -> tuple[list[Samples], int]:
    """The segment's good runs: put on an even clock (jittered stamps), low-passed forward and back,
    qdd differentiated, thinned to one sample per window; and how many rows were left out."""
    t = np.asarray(seg.t, dtype=float)
    q, qd = np.asarray(seg.q, dtype=float), np.asarray(seg.qd, dtype=float)
    sig = _signals(seg, kinds)
    good = np.isfinite(t) & np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(qd), axis=1)
    for v in sig.values():
        good &= np.all(np.isfinite(v), axis=1)
    runs = _runs(t, good)
    used = sum(len(r) for r in runs)
    out = []
    for run in runs:
        if len(run) < 8:
            continue
        tr = t[run]
        dt = float(np.median(np.diff(tr)))
        n = max(1, int(round(smooth_s / dt)))
        if len(run) < 8 * n:
            continue
        grid = np.arange(tr[0], tr[-1], dt)
        on = {k: _interp(grid, tr, v[run]) for k, v in (("q", q), ("qd", qd), *sig.items())}
        on["sgn"] = np.tanh(on["qd"] / V_EPS)
        sm = {k: smooth(v, n) for k, v in on.items()}
        qdd = np.gradient(sm["qd"], grid, axis=0)
        keep = slice(2 * n, len(grid) - 2 * n, n)  # the ends see the padding
        out.append(Samples(sm["q"][keep], sm["qd"][keep], qdd[keep], sm["sgn"][keep],
                            {k: sm[k][keep] for k in kinds}))
    return out, len(t) - used


def _interp(grid: np.ndarray, t: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(grid, t, v[:, j]) for j in range(v.shape[1])], axis=1)


def noise_std(segments, kinds: Sequence[str], kt0: np.ndarray) -> dict[str, np.ndarray]:
    """Each signal's noise at its recorded rate, N m: the robust spread of its second differences
    (white noise of std s gives sqrt(6) s; a smooth motion adds almost nothing at these rates)."""
    out = {}
    for kind in kinds:
        d2 = []
        for seg in segments:
            v = np.asarray(getattr(seg, "current" if kind == "currents" else "tau_j"), dtype=float)
            v = v[np.all(np.isfinite(v), axis=1)]
            if len(v) > 3:
                d2.append(np.diff(v, 2, axis=0))
        if not d2:
            out[kind] = np.zeros(len(kt0))
            continue
        dd = np.concatenate(d2)
        s = 1.4826 * np.median(np.abs(dd - np.median(dd, axis=0)), axis=0) / np.sqrt(6.0)
        out[kind] = s * (kt0 if kind == "currents" else 1.0)
    return out
