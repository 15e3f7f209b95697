"""One contact's point, fused over its frames.

A contact lasts many frames, and the touched point stays put on its link or slides slowly over it,
while each frame's estimate carries that frame's sensor noise. ``ContactTrack`` runs a Kalman
filter on the point in the link's frame (``link`` coordinates: the arm's own motion drops out):

* state: the point ``x_link`` (m) and its covariance ``P`` (m^2);
* motion: a random walk of ``slide`` m/sqrt(s) per axis (the point may slide; a fixed point is the
  special case). For a point sliding at speed v the filter lags by about v * sqrt(R dt) / slide,
  R being one frame's variance: with the defaults, under a millimetre at 1 cm/s on the built-in
  scenes;
* measurement: each frame's estimate (its point covariance turned into the link frame, plus
  ``(floor)^2`` on every axis: the solver's covariance has rank 2, on the surface);
* gate: an estimate whose innovation exceeds the chi-square quantile ``1 - p_gate`` (3 degrees of
  freedom) is left out, as is one on another link; after ``restart_after`` such estimates in a row
  the track restarts from the newest (the contact moved or the first estimates were wrong), or
  ends when that one carries a flag.

Errors shared from frame to frame do not average out: the bias's (a tare over n samples leaves
1/n of the noise's variance in every frame, and the scene's drift adds to it since the tare) and
the live chain's own (compensation model, clock alignment, the fit's nonlinearity at low force),
taken as ``chain_ratio`` of one frame's variance. They are carried apart from the filter's
covariance and added to the reported one, so fusing never claims more than they allow: with the
default 0.1, about a third of one frame's error at best. Measured on 30 s sweep-with-collision
runs (``docs/measurements/monitor.md``): the error per contact falls 3-6 fold against the single frames', and
the RMS of |error| / |point_std| stays below 1 in every contact (0.03-0.72; the single frames
0.03-1.15): the reported uncertainty errs on the safe side.

Only estimates the solver calls a contact, flagged at most ``grazing``, feed the track
(``FUSED_FLAGS``; not ``low_force`` ones, whose bound is centimetres anyway, nor ``ambiguous`` ones);
a track starts only from an estimate without a flag, and the others are still checked against it.
The filter's covariance shrinks as 1/n for a fixed point and levels off where the slide allowance
balances the frames' noise.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numba import njit

from .model import ArmModel
from .solver import ContactEstimate

# estimates with other flags are not fused: an ambiguous one may be another candidate's crossing; a
# pull where the link takes none, an off-surface, off-line or unconverged fit or a clipped
# (saturated) wrench is no measurement of the point
FUSED_FLAGS = frozenset({"grazing"})
# chi-square quantiles, 3 degrees of freedom
_CHI2_3 = {1e-2: 11.345, 1e-3: 16.266, 1e-4: 21.108, 1e-5: 25.902, 1e-6: 30.665}


@njit(cache=True, nogil=True)
def _matmul3(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += a[i, k] * b[k, j]
            out[i, j] = acc


@njit(cache=True, nogil=True)
def _rotate_cov(r: np.ndarray, c: np.ndarray, to_local: bool, out: np.ndarray) -> None:
    """out[:3, :3] = r^T c r (``to_local``: base to link frame) or r c r^T, for the rotation in
    r[:3, :3] and the covariance in c[:3, :3]."""
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                for n in range(3):
                    if to_local:
                        acc += r[k, i] * c[k, n] * r[n, j]
                    else:
                        acc += r[i, k] * c[k, n] * r[j, n]
            out[i, j] = acc


@njit(cache=True, nogil=True)
def link_pose(xpos: np.ndarray, xquat: np.ndarray, body: int, pose: np.ndarray) -> None:
    """pose (3x4: rotation, translation) = base_T_body from MuJoCo-layout body poses."""
    qw, qx, qy, qz = xquat[body, 0], xquat[body, 1], xquat[body, 2], xquat[body, 3]
    pose[0, 0] = 1.0 - 2.0 * (qy * qy + qz * qz)
    pose[0, 1] = 2.0 * (qx * qy - qw * qz)
    pose[0, 2] = 2.0 * (qx * qz + qw * qy)
    pose[1, 0] = 2.0 * (qx * qy + qw * qz)
    pose[1, 1] = 1.0 - 2.0 * (qx * qx + qz * qz)
    pose[1, 2] = 2.0 * (qy * qz - qw * qx)
    pose[2, 0] = 2.0 * (qx * qz - qw * qy)
    pose[2, 1] = 2.0 * (qy * qz + qw * qx)
    pose[2, 2] = 1.0 - 2.0 * (qx * qx + qy * qy)
    for i in range(3):
        pose[i, 3] = xpos[body, i]


@njit(cache=True, nogil=True)
def fuse_point(x: np.ndarray, p: np.ndarray, z_base: np.ndarray, cov: np.ndarray, xpos: np.ndarray,
               xquat: np.ndarray, body: int, q_add: float, r_add: float, gate: float, c_link: np.ndarray,
               pose: np.ndarray) -> float:
    """One filter step in place: predict ``p`` by ``q_add`` (m^2 per axis), then, when the
    measurement's Mahalanobis distance^2 is within ``gate``, update ``x``/``p`` with it. The
    measurement is a base-frame point ``z_base`` with covariance ``cov[:3, :3]`` (plus ``r_add`` per
    axis); the link is body ``body`` of the body poses ``xpos``/``xquat`` (MuJoCo's layout), whose
    pose goes to ``pose`` (3x4: rotation, translation). Returns the distance^2 (inf: broken input).
    ``c_link`` (4x3) receives the measurement's covariance in the link frame (rows 0-2) and, in row
    3, the gain along it: trace(K C) / trace(C), the weight this frame got in the fused point."""
    link_pose(xpos, xquat, body, pose)
    for i in range(3):
        p[i, i] += q_add
    z = np.empty(3)
    for i in range(3):
        s = 0.0
        for k in range(3):
            s += pose[k, i] * (z_base[k] - pose[k, 3])
        z[i] = s
    # S = P + R^T C R + r_add I
    _rotate_cov(pose, cov, True, c_link)
    s_m = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            s_m[i, j] = p[i, j] + c_link[i, j] + (r_add if i == j else 0.0)
    # inverse of the symmetric 3x3 by cofactors
    c00 = s_m[1, 1] * s_m[2, 2] - s_m[1, 2] * s_m[2, 1]
    c01 = s_m[1, 2] * s_m[2, 0] - s_m[1, 0] * s_m[2, 2]
    c02 = s_m[1, 0] * s_m[2, 1] - s_m[1, 1] * s_m[2, 0]
    det = s_m[0, 0] * c00 + s_m[0, 1] * c01 + s_m[0, 2] * c02
    if not (det > 0.0 and math.isfinite(det)):
        return np.inf
    inv = np.empty((3, 3))
    inv[0, 0] = c00 / det
    inv[0, 1] = (s_m[0, 2] * s_m[2, 1] - s_m[0, 1] * s_m[2, 2]) / det
    inv[0, 2] = (s_m[0, 1] * s_m[1, 2] - s_m[0, 2] * s_m[1, 1]) / det
    inv[1, 0] = c01 / det
    inv[1, 1] = (s_m[0, 0] * s_m[2, 2] - s_m[0, 2] * s_m[2, 0]) / det
    inv[1, 2] = (s_m[0, 2] * s_m[1, 0] - s_m[0, 0] * s_m[1, 2]) / det
    inv[2, 0] = c02 / det
    inv[2, 1] = (s_m[0, 1] * s_m[2, 0] - s_m[0, 0] * s_m[2, 1]) / det
    inv[2, 2] = (s_m[0, 0] * s_m[1, 1] - s_m[0, 1] * s_m[1, 0]) / det
    nu = np.empty(3)
    for i in range(3):
        nu[i] = z[i] - x[i]
    d2 = 0.0
    for i in range(3):
        for j in range(3):
            d2 += nu[i] * inv[i, j] * nu[j]
    if not math.isfinite(d2):
        return np.inf
    if d2 > gate:
        return d2
    # K = P S^-1; x += K nu; P -= K S K^T = P S^-1 P (symmetric by construction)
    gain = np.empty((3, 3))
    _matmul3(p, inv, gain)
    for i in range(3):
        acc = 0.0
        for k in range(3):
            acc += gain[i, k] * nu[k]
        x[i] += acc
    kc = 0.0
    tr = 0.0
    for i in range(3):
        tr += c_link[i, i]
        for k in range(3):
            kc += gain[i, k] * c_link[k, i]
    c_link[3, 0] = kc / tr if tr > 0.0 else 0.0
    kp = np.empty((3, 3))
    _matmul3(gain, p, kp)
    for i in range(3):
        for j in range(i, 3):
            p[i, j] = p[j, i] = p[i, j] - 0.5 * (kp[i, j] + kp[j, i])
    return d2


@njit(cache=True, nogil=True)
def report(x: np.ndarray, p: np.ndarray, c: np.ndarray, bias_rms: float, pose: np.ndarray, point: np.ndarray,
           cov: np.ndarray) -> None:
    """The fused point (base frame) and its covariance: the filter's ``p`` plus the bias's share
    ``bias_rms^2`` shaped as ``c`` (the newest fused frame's covariance, link frame, rows 0-2)."""
    tr = c[0, 0] + c[1, 1] + c[2, 2]
    m = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            m[i, j] = p[i, j] + (bias_rms * bias_rms * c[i, j] / tr if tr > 0.0 else
                                 (bias_rms * bias_rms / 3.0 if i == j else 0.0))
    for i in range(3):
        acc = pose[i, 3]
        for k in range(3):
            acc += pose[i, k] * x[k]
        point[i] = acc
    _rotate_cov(pose, m, False, cov)


class ContactTrack:
    """The fused point of the current contact (see the module's notes). ``update`` once per frame in
    contact, ``reset`` at its onset; ``point``/``point_std`` are in the base frame, at the link's pose
    in the newest frame."""

    def __init__(self, model: ArmModel, *, slide: float = 0.01, floor: float = 1e-4, p_gate: float = 1e-4,
                 restart_after: int = 3, chain_ratio: float = 0.1,
                 body_poses: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None) -> None:
        """``body_poses(q)``: every body's (xpos, xquat) at q, MuJoCo's layout (default the model's;
        the pipeline passes the solver's, which has the frame's kinematics at hand)."""
        if p_gate not in _CHI2_3:
            raise ValueError(f"p_gate: one of {sorted(_CHI2_3)}, got {p_gate!r}")
        if not (slide > 0 and floor > 0 and restart_after >= 1 and chain_ratio >= 0):
            raise ValueError("slide and floor must be > 0, restart_after >= 1 and chain_ratio >= 0")
        self.model = model
        self.body_poses = body_poses or model.body_poses
        self.slide_var_per_s = slide ** 2
        self.floor_var = floor ** 2
        self.gate = _CHI2_3[p_gate]
        self.restart_after = int(restart_after)
        spec = model.scene.sensor
        self._drift_ratio = (0.0 if spec is None else  # joint signals only: no F/T bias drifting since a tare
                             float(np.max((np.asarray(spec.drift_per_s) / np.sqrt(np.diag(spec.noise_cov))) ** 2)))
        self.bias_ratio = 0.0
        self.chain_ratio = float(chain_ratio)
        self._bias_t_ns: int | None = None
        self.x = np.zeros(3)
        self.p = np.zeros((3, 3))
        self.link: str | None = None
        self.fused = 0  # frames in the current track
        self.rejected = 0  # estimates left out since the track began (another link or outside the gate)
        self.restarts = 0
        self._misses = 0
        self._t_ns = 0
        self._pose = np.zeros((3, 4))  # base_T_link (rotation, translation) at the newest frame
        self._body = 0
        self._c = np.zeros((4, 3))  # the last fused frame's covariance (link frame) and gain
        self._c_work = np.zeros((4, 3))
        self._bias_rms = 0.0

    def set_bias(self, var_ratio: float, t_ns: int | None = None) -> None:
        """How well the compensation's bias is known: its covariance is at most ``var_ratio`` times
        the sensor noise's (a tare over n samples: 1/n), as of host time ``t_ns``; from then on the
        scene's drift adds to it. A bias error is the same in every frame, so fusing frames does not
        shrink its share of the point's error: it is carried apart (see ``point_std``)."""
        if not var_ratio >= 0:
            raise ValueError(f"var_ratio: must be >= 0, got {var_ratio!r}")
        self.bias_ratio = float(var_ratio)
        self._bias_t_ns = t_ns

    def reset(self) -> None:
        self.link = None
        self.fused = self.rejected = self.restarts = self._misses = 0

    @property
    def active(self) -> bool:
        return self.link is not None

    def _bias_var_ratio(self, t_ns: int) -> float:
        if self._bias_t_ns is None:
            return self.bias_ratio + self.chain_ratio
        dt = max(t_ns - self._bias_t_ns, 0) * 1e-9
        return self.bias_ratio + self.chain_ratio + self._drift_ratio * dt * dt

    def update(self, t_ns: int, estimate: ContactEstimate, q,
               poses: tuple[np.ndarray, np.ndarray] | None = None) -> bool:
        """One frame's estimate (at joint angles q, rad); True when it went into the track. ``poses``:
        the bodies' (xpos, xquat) at q when the caller has them (else ``body_poses(q)``).

        An estimate with other flags than ``FUSED_FLAGS`` is not fused but still judged: one that
        disagrees with the track counts as a miss like any other. A track starts (and restarts) only
        from an estimate without a flag; after ``restart_after`` misses in a row with none to restart
        from, it ends (``active`` False) and the events carry each frame's own estimate again."""
        e = estimate
        if not (e.contact and e.link):
            return False
        if self.link is None:
            return self._start(t_ns, e, q) if not e.flags else False
        fusable = FUSED_FLAGS.issuperset(e.flags)
        xpos, xquat = poses if poses is not None else self.body_poses(q)
        q_add = self.slide_var_per_s * max(t_ns - self._t_ns, 0) * 1e-9
        self._t_ns = t_ns
        if e.link == self.link:
            # not fusable: judged only (a gate below every distance leaves the state as it is); a
            # non-finite estimate gives an infinite distance and is left out
            c = self._c_work
            # (the point is reported where its link is now: the kernel writes the link's pose)
            d2 = fuse_point(self.x, self.p, e.point, e.cov, xpos, xquat, self._body, q_add, self.floor_var,
                            self.gate if fusable else -1.0, c, self._pose)
        else:
            # another link's estimate: a miss; time still passed, and the link moved
            self.p[np.diag_indices(3)] += q_add
            link_pose(xpos, xquat, self._body, self._pose)
            d2 = math.inf
        if d2 <= self.gate:
            if not fusable:
                return False  # agrees, but is not a measurement to fuse
            self.fused += 1
            self._misses = 0
            tr = c[0, 0] + c[1, 1] + c[2, 2]
            if tr > 0:
                # the bias's share of this frame's error, fully correlated from frame to frame: it
                # enters the fused point with the frame's weight and is never averaged down
                g = c[3, 0]
                self._bias_rms = (1.0 - g) * self._bias_rms + g * math.sqrt(self._bias_var_ratio(t_ns) * tr)
                self._c, self._c_work = c, self._c
            return True
        self.rejected += 1
        self._misses += 1
        if self._misses >= self.restart_after:
            self.restarts += 1
            if not e.flags:
                return self._start(t_ns, e, q)
            self.link = None
        return False

    def _start(self, t_ns: int, e: ContactEstimate, q) -> bool:
        cov = e.cov[:3, :3]
        if not math.isfinite(float(e.point.sum() + cov.sum())):
            return False
        body = self.model.model.body(e.link).id
        link_pose(*self.body_poses(q), body, self._pose)
        r, t = self._pose[:, :3], self._pose[:, 3]
        c = r.T @ cov @ r
        self.x = r.T @ (e.point - t)
        self.p = c + self.floor_var * np.eye(3)
        self._c[:3] = c
        self._bias_rms = math.sqrt(self._bias_var_ratio(t_ns) * float(np.trace(c)))
        self.link = e.link
        self._body = body
        self._t_ns = t_ns
        self.fused = 1
        self._misses = 0
        return True

    def _report(self) -> tuple[np.ndarray, np.ndarray]:
        point, cov = np.empty(3), np.empty((3, 3))
        report(self.x, self.p, self._c, self._bias_rms, self._pose, point, cov)
        return point, cov

    @property
    def point(self) -> np.ndarray:
        """The fused point (m, base frame, where its link is in the newest frame)."""
        return self._report()[0]

    @property
    def cov(self) -> np.ndarray:
        """The fused point's covariance (m^2, base frame): the filter's, which shrinks as frames come
        in, plus the bias's share, which does not (shaped as the newest fused frame's covariance)."""
        return self._report()[1]

    @property
    def point_std(self) -> np.ndarray:
        return self.point_and_std()[1]

    def point_and_std(self) -> tuple[np.ndarray, np.ndarray]:
        """``point`` and ``point_std`` in one pass (the events' path)."""
        point, cov = self._report()
        return point, np.sqrt(np.maximum(np.diag(cov), 0.0))
