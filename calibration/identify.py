"""Identification from static poses: weighted, Huber-robust least squares with standard errors,
identifiability and a verdict (``good``, ``poorly_excited``, ``inconsistent``) with reasons.

Parameters: the 10 core ones of :mod:`ftc_hw.calibration.regressor`, optionally the sensor's mount rotation
about its z axis (``mount_yaw``), a gravity tilt (``gravity_tilt_x``/``_y``) and the arm's gravity base
parameters (:mod:`ftc_hw.calibration.arm_gravity`). Each pose's mean reading is weighted by the scene's sensor
noise covariance over the samples averaged, plus the joint encoders' resolution carried through the
model (a tick of a DYNAMIXEL moves a base-mounted sensor's torque by more than a second of averaging).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .arm_gravity import ArmGravityBasis
from .regressor import N_CORE, PARAMS, GeometryModel, PoseGeometry, arm_param_rows, core_rows, predict
from .samples import PoseSample

HUBER_K = 1.345
STILL_QD = 0.03  # rad/s: faster than this while sampling is motion (DYNAMIXEL velocity LSB 0.024 rad/s)
VARIANCE_RATIO = 2.0  # F/T sample std beyond this times the expected noise: motion or contact
OUTLIER_SIGMA = 5.0
NULL_TOL = 1e-7  # relative singular value below which a direction is not identified at all


@dataclass(frozen=True)
class FitOptions:
    yaw: bool = False
    tilt: bool = False
    arm_gravity: bool = False
    q_std: np.ndarray | float | None = None  # rad, per joint: encoder resolution / sqrt(12)
    limits: dict[str, float] | None = None  # 1-sigma limits per reported quantity (see default_limits)


@dataclass
class Fit:
    names: list[str]
    estimate: np.ndarray
    cov: np.ndarray
    std: np.ndarray
    verdict: str
    reasons: list[str]
    poorly_excited: list[str]
    residual_rms: np.ndarray  # per axis, of the pose means (N, N m)
    residuals: np.ndarray  # (poses, 6): each pose's mean reading minus the fitted model (N, N m)
    residual_std: np.ndarray  # (poses, 6): the expected std of those (the sensor noise, the encoders)
    condition_number: float
    chi2: float
    dof: int
    weights: np.ndarray  # Huber weight per pose and axis
    derived: dict[str, float | list[float] | None] = field(default_factory=dict)
    derived_std: dict[str, float | list[float] | None] = field(default_factory=dict)
    arm_basis: ArmGravityBasis | None = None

    def value(self, name: str) -> float:
        return float(self.estimate[self.names.index(name)])

    @property
    def force_bias(self) -> np.ndarray:
        return self.estimate[:3].copy()

    @property
    def torque_bias(self) -> np.ndarray:
        return self.estimate[3:6].copy()

    @property
    def bias(self) -> np.ndarray:
        return self.estimate[:6].copy()

    @property
    def mass(self) -> float:
        return float(self.estimate[6])

    @property
    def com(self) -> np.ndarray | None:
        m = self.mass
        return None if m <= 0 else self.estimate[7:10] / m


def default_limits(mass: float) -> dict[str, float]:
    """1-sigma limits that make the acceptance tolerances hold at 3 sigma."""
    return {"mass": (0.005 * abs(mass) + 0.002) / 3, "com": 0.001 / 3, "force_bias": 0.03 / 3,
            "torque_bias": 0.002 / 3, "mount_yaw": 1e-3, "gravity_tilt": 1e-3}


def param_names(opts: FitOptions, basis: ArmGravityBasis | None) -> list[str]:
    names = list(PARAMS)
    if opts.yaw:
        names.append("mount_yaw")
    if opts.tilt:
        names += ["gravity_tilt_x", "gravity_tilt_y"]
    if basis is not None:
        names += basis.names
    return names


class Identifier:
    """Fits a scene's calibration from pose samples. ``geometry``: the scene's :class:`GeometryModel`."""

    def __init__(self, geometry: GeometryModel, options: FitOptions | None = None) -> None:
        self.gm = geometry
        self.opts = options or FitOptions()
        self.scene = geometry.scene
        self.basis = ArmGravityBasis(geometry) if self.opts.arm_gravity else None
        self.names = param_names(self.opts, self.basis)
        n = self.scene.n_joints
        q_std = self.opts.q_std
        self.q_var = np.zeros(n) if q_std is None else np.broadcast_to(np.asarray(q_std, float) ** 2, (n,)).copy()
        self.noise_cov = self.scene.sensor.noise_cov

    # -- model ---------------------------------------------------------------------------------------
    def _split(self, p: np.ndarray):
        i = 10
        yaw = 0.0
        tilt = (0.0, 0.0)
        if self.opts.yaw:
            yaw = float(p[i])
            i += 1
        if self.opts.tilt:
            tilt = (float(p[i]), float(p[i + 1]))
            i += 2
        delta = self.basis.delta(p[i:]) if self.basis is not None else None
        return p[:10], yaw, tilt, delta

    def model(self, g: PoseGeometry, p: np.ndarray) -> np.ndarray:
        theta, yaw, tilt, delta = self._split(p)
        return predict(g, theta, self.gm.gravity, self.gm.sign, yaw, tilt, delta)

    def jacobian(self, g: PoseGeometry, p: np.ndarray) -> np.ndarray:
        """Exact in the 10 core parameters and the arm-gravity terms (the reading is linear in them);
        central differences in the mount yaw and the gravity tilt."""
        _, yaw, tilt, _ = self._split(p)
        out = np.empty((6, len(p)))
        out[:, :N_CORE] = core_rows(g, self.gm.gravity, self.gm.sign, yaw, tilt)
        n_arm = self.basis.v.shape[1] if self.basis is not None else 0
        if n_arm:  # linear in the link corrections too, through the basis
            out[:, len(p) - n_arm:] = arm_param_rows(g, self.gm.gravity, self.gm.sign, yaw, tilt) @ self.basis.v
        for j in range(N_CORE, len(p) - n_arm):
            dp = np.zeros(len(p))
            dp[j] = 1e-6
            out[:, j] = (self.model(g, p + dp) - self.model(g, p - dp)) / 2e-6
        return out

    def pose_cov(self, g: PoseGeometry, p: np.ndarray, n: int) -> np.ndarray:
        """Covariance of one pose's mean reading: sensor noise over n samples plus the joint resolution."""
        cov = self.noise_cov / max(n, 1)
        if np.any(self.q_var > 0):
            jq = np.empty((6, len(g.q)))
            for j in range(len(g.q)):
                dq = np.zeros(len(g.q))
                dq[j] = 1e-5
                jq[:, j] = (self.model(self.gm.at(g.q + dq), p) - self.model(self.gm.at(g.q - dq), p)) / 2e-5
            cov = cov + jq @ np.diag(self.q_var) @ jq.T
        return cov

    # -- fit -----------------------------------------------------------------------------------------
    def fit(self, samples: Sequence[PoseSample], limits: dict[str, float] | None = None) -> Fit:
        if len(samples) < 1:
            raise ValueError("no pose samples")
        for k, s in enumerate(samples, 1):
            if not (np.all(np.isfinite(s.q)) and np.all(np.isfinite(s.wrench)) and s.n >= 1):
                raise ValueError(f"pose {k}: non-finite joint angles or wrench, or no samples")
        geoms = [self.gm.at(s.q) for s in samples]
        y = np.array([s.wrench for s in samples])
        p = np.zeros(len(self.names))
        p = self._irls(geoms, y, samples, p, robust=False)
        p = self._irls(geoms, y, samples, p, robust=True)
        return self._result(geoms, y, samples, p, limits)

    def _pose_covs(self, geoms, samples, p) -> list[np.ndarray]:
        return [self.pose_cov(g, p, s.n) for g, s in zip(geoms, samples, strict=True)]

    def _whiteners(self, covs: list[np.ndarray]) -> list[np.ndarray]:
        return [np.linalg.inv(np.linalg.cholesky(c)) for c in covs]

    def _irls(self, geoms, y, samples, p, robust: bool, iters: int = 30) -> np.ndarray:
        lw = self._whiteners(self._pose_covs(geoms, samples, p))

        def residuals(p: np.ndarray) -> np.ndarray:
            return np.concatenate([li @ (yi - self.model(g, p)) for li, yi, g in zip(lw, y, geoms, strict=True)])

        r = residuals(p)
        for _ in range(iters):
            j = np.vstack([li @ self.jacobian(g, p) for li, g in zip(lw, geoms, strict=True)])
            w = huber_weights(r, robust_scale(r, len(p))) if robust else np.ones_like(r)
            sw = np.sqrt(w)
            step = np.linalg.lstsq(j * sw[:, None], r * sw, rcond=1e-12)[0]
            # The model is nonlinear in yaw, tilt and the arm-gravity terms: a full step along a
            # direction the poses barely excite can overshoot far. Halve it until the weighted
            # residual does not grow (the weights are fixed within the iteration).
            cost = float(w @ r**2)
            for _halving in range(30):
                r_new = residuals(p + step)
                if float(w @ r_new**2) <= cost * (1 + 1e-12):
                    break
                step = 0.5 * step
            else:
                break  # no descent left at rounding level
            p, r = p + step, r_new
            if np.all(np.abs(step) < 1e-12 + 1e-9 * np.abs(p)):
                break
        return p

    def _result(self, geoms, y, samples, p, limits) -> Fit:
        covs = self._pose_covs(geoms, samples, p)
        lw = self._whiteners(covs)
        raw = np.array([yi - self.model(g, p) for yi, g in zip(y, geoms, strict=True)])
        r = np.concatenate([li @ ri for li, ri in zip(lw, raw, strict=True)])
        jw = np.vstack([li @ self.jacobian(g, p) for li, g in zip(lw, geoms, strict=True)])
        n_obs, n_par = jw.shape
        scale = robust_scale(r, n_par)
        w = huber_weights(r, scale)
        dof = max(n_obs - n_par, 1)
        chi2 = float(r @ r)
        # conditioning and null space of the noise-weighted, column-scaled regressor
        norms = np.linalg.norm(jw, axis=0)
        norms[norms == 0] = 1.0
        _, sv, vt = np.linalg.svd(jw / norms, full_matrices=True)
        sv_full = np.zeros(n_par)
        sv_full[:len(sv)] = sv
        cond = float(sv_full[0] / sv_full[-1]) if sv_full[-1] > 0 else float("inf")
        null = vt[sv_full < NULL_TOL * sv_full[0]]
        unidentified = np.linalg.norm(null, axis=0) > 1e-3 if len(null) else np.zeros(n_par, bool)
        info = (jw * w[:, None]).T @ jw
        cov = np.linalg.pinv(info, rcond=1e-12, hermitian=True) * max(1.0, float((w * r * r).sum()) / dof)
        std = np.sqrt(np.clip(np.diag(cov), 0, None))
        std[unidentified] = np.inf
        fit = Fit(names=list(self.names), estimate=p, cov=cov, std=std, verdict="good", reasons=[],
                  poorly_excited=[], residual_rms=np.sqrt(np.mean(raw**2, axis=0)), residuals=raw,
                  residual_std=np.sqrt(np.array([np.diag(c) for c in covs])), condition_number=cond,
                  chi2=chi2, dof=dof, weights=w.reshape(len(samples), 6), arm_basis=self.basis)
        _derive(fit, unidentified)
        _judge(fit, samples, r.reshape(len(samples), 6), scale, unidentified, limits, self.scene, raw)
        return fit


def robust_scale(r: np.ndarray, n_par: int) -> float:
    """Residual scale in units of the expected noise: 1 when the noise model holds, more when not (MAD)."""
    if len(r) <= n_par:
        return 1.0
    return max(1.0, 1.4826 * float(np.median(np.abs(r))) * np.sqrt(len(r) / (len(r) - n_par)))


def huber_weights(r: np.ndarray, scale: float, k: float = HUBER_K) -> np.ndarray:
    a = np.abs(r) / scale
    return np.where(a <= k, 1.0, k / np.maximum(a, 1e-300))


def chi2_quantile(dof: int, z: float = 3.09) -> float:
    """Upper chi-square quantile (Wilson-Hilferty), z = 3.09: p = 0.001."""
    c = 2.0 / (9.0 * dof)
    return dof * (1 - c + z * np.sqrt(c)) ** 3


def _derive(fit: Fit, unidentified: np.ndarray) -> None:
    """Mass, centre of mass (flange frame) and biases with their standard errors (delta method)."""
    e, c = fit.estimate, fit.cov
    m = float(e[6])
    d, s = fit.derived, fit.derived_std
    d["force_bias"] = e[:3].tolist()
    d["torque_bias"] = e[3:6].tolist()
    s["force_bias"] = fit.std[:3].tolist()
    s["torque_bias"] = fit.std[3:6].tolist()
    d["mass"] = m
    s["mass"] = float(fit.std[6])
    if m > 0:
        h = e[7:10]
        jac = np.zeros((3, 4))
        jac[:, 0] = -h / m**2
        jac[:, 1:] = np.eye(3) / m
        com_cov = jac @ c[6:10, 6:10] @ jac.T
        com_std = np.sqrt(np.clip(np.diag(com_cov), 0, None))
        com_std[unidentified[7:10] | unidentified[6]] = np.inf
        d["com"] = (h / m).tolist()
        s["com"] = com_std.tolist()
    else:
        d["com"] = None
        s["com"] = None
    for name in fit.names[10:]:
        i = fit.names.index(name)
        d[name] = float(e[i])
        s[name] = float(fit.std[i])


def _judge(fit: Fit, samples: Sequence[PoseSample], r: np.ndarray, scale: float, unidentified: np.ndarray,
           limits: dict[str, float] | None, scene, raw: np.ndarray) -> None:
    reasons = fit.reasons
    inconsistent = False
    expected = np.sqrt(np.diag(scene.sensor.noise_cov))
    axes = ("fx", "fy", "fz", "tx", "ty", "tz")
    for k, s in enumerate(samples):
        if s.qd_max > STILL_QD:
            inconsistent = True
            reasons.append(f"pose {k + 1}: moved while sampling (joint speed up to {s.qd_max:.3f} rad/s)")
        ratio = np.asarray(s.wrench_std) / expected
        if s.n >= 10 and np.any(ratio > VARIANCE_RATIO):
            a = int(np.argmax(ratio))
            inconsistent = True
            reasons.append(f"pose {k + 1}: F/T variance {ratio[a]:.1f} x the sensor noise on {axes[a]} "
                           "(motion, vibration or a contact while sampling)")
    for k in range(len(samples)):
        a = int(np.argmax(np.abs(r[k])))
        if np.abs(r[k, a]) > OUTLIER_SIGMA * max(scale, 1.0):
            inconsistent = True
            unit = "N" if a < 3 else "N m"
            reasons.append(f"pose {k + 1}: residual {raw[k, a]:+.4f} {unit} on {axes[a]} ({abs(r[k, a]):.1f} sigma): "
                           "a contact or a load that is not the payload")
    if fit.dof > 0 and fit.chi2 > chi2_quantile(fit.dof) and len(samples) * 6 > len(fit.names):
        inconsistent = True
        reasons.append(f"residuals are {np.sqrt(fit.chi2 / fit.dof):.1f} x the expected noise over all poses "
                       "(chi-square test, p < 0.001): the model does not explain the data")
    drift = _drift(samples, raw, fit)
    if drift:
        inconsistent = True
        reasons.append(drift)
    # identifiability
    poorly: list[str] = []
    names = fit.names
    mass = fit.mass
    no_payload = not unidentified[6] and np.isfinite(fit.std[6]) and mass < max(3 * fit.std[6], 1e-3)
    lim = {**default_limits(mass), **(limits or {})}
    for i, name in enumerate(names):
        if name.startswith("mass_com") and no_payload:
            continue
        if unidentified[i]:
            poorly.append(_public(name))
    ds = fit.derived_std
    checks = [("mass", [ds["mass"]], lim["mass"], ["mass"])]
    if not no_payload and ds.get("com") is not None:
        checks.append(("com", ds["com"], lim["com"], ["com_x", "com_y", "com_z"]))
    checks += [("force_bias", ds["force_bias"], lim["force_bias"], ["force_bias_x", "force_bias_y", "force_bias_z"]),
               ("torque_bias", ds["torque_bias"], lim["torque_bias"],
                ["torque_bias_x", "torque_bias_y", "torque_bias_z"])]
    for key in ("mount_yaw", "gravity_tilt_x", "gravity_tilt_y"):
        if key in names:
            checks.append((key, [ds[key]], lim["gravity_tilt" if key.startswith("gravity") else key], [key]))
    for _key, stds, limit, labels in checks:
        for sd, label in zip(stds, labels, strict=True):
            if (not np.isfinite(sd) or sd > limit) and label not in poorly:
                poorly.append(label)
    fit.poorly_excited = sorted(set(poorly), key=poorly.index)
    if fit.poorly_excited:
        reasons.append("the poses cannot identify " + ", ".join(fit.poorly_excited) +
                       _why(fit.poorly_excited, unidentified, names))
    if no_payload:
        fit.derived["com"] = None
        fit.derived_std["com"] = None
        reasons.append(f"no payload: mass {mass * 1e3:.1f} g is within 3 standard errors of zero")
    fit.verdict = "inconsistent" if inconsistent else ("poorly_excited" if fit.poorly_excited else "good")


def _public(name: str) -> str:
    return name.replace("mass_com", "com")


def _why(poorly: list[str], unidentified: np.ndarray, names: list[str]) -> str:
    hard = [_public(n) for n, u in zip(names, unidentified, strict=True) if u]
    if hard:
        return (f" ({', '.join(hard)}: not at all, the data cannot tell them from other parameters; "
                "add poses that tilt the flange in other directions)")
    return " (standard errors above the limits: add poses or sample longer)"


def _drift(samples: Sequence[PoseSample], raw: np.ndarray, fit: Fit) -> str | None:
    """A trend of the residuals over time beyond the noise: the bias drifted while calibrating."""
    t = np.array([s.t for s in samples], dtype=float)
    if len(samples) < 4 or np.ptp(t) <= 0:
        return None
    tc = t - t.mean()
    axes = ("fx", "fy", "fz", "tx", "ty", "tz")
    for a in range(6):
        sig = np.array([np.sqrt(s.wrench_std[a] ** 2 / max(s.n, 1)) for s in samples])
        sig = np.maximum(sig, 1e-12)
        w = 1.0 / sig**2
        slope = float((w * tc * raw[:, a]).sum() / (w * tc * tc).sum())
        slope_std = float(1.0 / np.sqrt((w * tc * tc).sum()))
        change = abs(slope) * float(np.ptp(t))
        if abs(slope) > 6 * slope_std and change > 3 * max(fit.std[a], 1e-12) and change > 3 * float(sig.mean()):
            unit = "N" if a < 3 else "N m"
            return f"drift: {axes[a]} moved by {slope * np.ptp(t):+.4f} {unit} over {np.ptp(t):.0f} s while calibrating"
    return None
