"""Identification from the joints' own signals (motor currents, joint torque sensors): the links'
inertial parameters, the torque constants, the joints' friction and the torque sensors' offsets, from
contact-free motion, in one Bayesian linear fit.

    currents:       kt0 (1 + s) i = tau(q, qd, qdd) + Y(q, qd, qdd) dpi + (b0 + db) qd + (fc0 + dfc) tanh(qd / v)
                                    + I_r qdd
    joint torques:  tau_J         = tau(q, qd, qdd) + Y(q, qd, qdd) dpi + offset

``tau`` is the model's inverse dynamics, ``Y`` the joint-torque regressor (:func:`ftc_hw.model.
inertials.joint_regressor`), ``dpi`` the bodies' parameter corrections, ``I_r`` the motor's rotor inertia
beyond the model's armature (a real motor's, reflected through its gear; in the simulated world MuJoCo's
Euler integrator takes joint damping implicitly, which looks like ``h b`` of it); a torque sensor sits
on the link side of the gear, so it reads neither the joint's friction nor its rotor.

The currents alone cannot tell a common scale of every torque constant, inertial parameter and friction
term (``kt i`` is all they see of the torques). Its residual in amperes stays the same along that
scale, and the fit is moved along it to where the vendor's data put it: the gravity torques of the
vendor's masses (``Priors.mass_rel``) and the torque constants the data told, with their priors
(``JointPriors.torque_constant_rel``). Left to all the parameters' priors (wide ones, and ones leaning
on the model's smallest terms) it moved by 3 % on ur5e in a typical world. The fit reports the scale's
std. With joint torque sensors the scale is theirs.

Each parameter has a prior about the model's value (``JointPriors``): what the motion cannot tell
stays there, named in the verdict; parameters no motion can tell from joint torques (the base links'
unseen moments, the regressor's structural null space) are named apart and do not spoil it. Current
rows near standstill (``|qd| < MIN_SPEED``) are left out: there Coulomb friction holds anything within
+-fc (and the world's Stribeck excess has faded to exp(-(MIN_SPEED / 0.02)^2) = 0.2 % above it, so no
Stribeck term is fitted). Signals are prepared by :mod:`.joint_motion`.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np

from ..model import ArmModel
from ..model.build import moves
from ..model.inertials import N_PARAMS, PARAM_LABELS, body_params, joint_regressor
from .free_motion import (
    HUBER_K,
    MIN_SAMPLES,
    SMOOTH_S,
    TOLD,
    IdentificationError,
    Priors,
    bayes,
    block_diagonal,
    body_prior,
)
from .joint_motion import JointMotionData, noise_std, prepare_joint_motion

MIN_SPEED = 0.05  # rad/s: current rows of a slower joint are left out (Coulomb friction is set-valued there)
KINDS = ("currents", "joint_torques")
GENERIC_STATES = 60  # random states that tell which parameters joint torques can tell at all
GRAVITY_POSES = 50  # poses of the motion at which the gravity torques pin the currents' common scale
# a joint whose links' torque is less than this share of its motor's (the rest its own friction) tells
# its torque constant only through that share, where the low pass's small errors weigh most: measured on
# ur5e's wrist 3 (a share of 0.001), its torque constant came out 2-5 % off while the fit claimed 0.3 %
MIN_RIGID_SHARE = 0.05


@dataclass(frozen=True)
class JointPriors:
    """Prior standard deviations of what the joints' signals add to :class:`Priors`."""

    inertial: Priors = Priors()
    # ESTIMATE: vendors publish no per-arm torque constants (UR none at all); a motor constant within
    # +-10 % of its nominal value over production spread and temperature
    torque_constant_rel: float = 0.10
    # ESTIMATE: joint friction is rarely published and changes with temperature and load: the scene's
    # value within +-100 %, at least these absolute amounts
    friction_rel: float = 1.0
    viscous_floor: float = 0.1  # N m s / rad
    coulomb_floor: float = 0.2  # N m
    # ESTIMATE: torque sensors' offsets after a power cycle (Franka asks users to re-zero them above
    # ~1 N m); unknown to within a few N m
    offset_nm: float = 5.0
    # ESTIMATE: a motor's rotor inertia reflected through a ~100:1 gear is of the order of the link
    # inertia the joint moves; prior std this fraction of the joint's diagonal mass-matrix term at home
    rotor_rel: float = 1.0


@dataclass
class JointIdentFit:
    kinds: tuple[str, ...]  # the signals fitted, of KINDS
    bodies: list[str]
    delta_pi: np.ndarray  # (len(bodies), 10)
    torque_constant: np.ndarray  # (n,) N m / A (the scene's where currents were not fitted)
    friction_viscous: np.ndarray  # (n,) N m s / rad
    friction_coulomb: np.ndarray  # (n,) N m
    offset: np.ndarray  # (n,) N m, the torque sensors' offsets (zeros without them)
    rotor_inertia: np.ndarray  # (n,) kg m^2 beyond the model's armature (zeros without currents)
    cov: np.ndarray  # posterior covariance of the parameters, in the order of ``labels``
    labels: list[str]
    prior_std: np.ndarray
    residual_std: dict[str, np.ndarray]  # kind -> (n,) N m: after the fit, of the thinned samples
    residual_std_before: dict[str, np.ndarray]  # kind -> (n,) N m: the scene's model
    noise_std: dict[str, np.ndarray]  # kind -> (n,) N m: the signal's noise at the recorded rate
    samples: int
    dropped_rows: int  # recorded rows left out: not finite, or not after the one before
    scale_std: float | None  # relative std of the common scale the currents cannot tell (None: not fitted)
    untold: list[str] = field(default_factory=list)  # parameters this motion did not tell
    unidentifiable: list[str] = field(default_factory=list)  # parameters no motion tells from these signals
    verdict: str = "good"
    reasons: list[str] = field(default_factory=list)

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))

    def joint_std(self) -> np.ndarray:
        """(n, 3): the posterior std of the torque constant (N m / A), viscous and Coulomb friction."""
        n = len(self.torque_constant)
        out = np.zeros((n, 3))
        s = dict(zip(self.labels, self.std, strict=True))
        for j in range(n):
            out[j] = [s.get(f"kt_scale[{j}]", 0.0) * self.torque_constant[j], s.get(f"viscous[{j}]", 0.0),
                      s.get(f"coulomb[{j}]", 0.0)]
        return out


class JointIdentifier:
    """``kinds``: the signals to fit, of :data:`KINDS` (default: what the scene's sensing uses)."""

    def __init__(self, arm: ArmModel, kinds: Sequence[str] | None = None, priors: JointPriors | None = None) -> None:
        self.arm = arm
        scene = arm.scene
        sensing = scene.sensing
        self.kinds = tuple(k for k in KINDS if k in (kinds if kinds is not None else sensing.kinds))
        if not self.kinds:
            raise IdentificationError(f"scene {scene.name!r} uses no joint signal ({sensing.label()}): "
                                      "identify it from its F/T sensor")
        self.priors = priors or JointPriors()
        m = arm.model
        # the moving bodies with inertia to identify (a flange sensor's tool-side body is massless)
        self.body_ids = [b for b in range(1, m.nbody) if moves(m, b) and m.body_mass[b] > 0]
        self.bodies = [m.body(b).name for b in self.body_ids]
        self.pi0 = np.concatenate([body_params(m, b) for b in self.body_ids])
        self.n = scene.n_joints
        r = scene.robot
        self.kt0 = np.asarray(r.torque_constant, dtype=float)
        self.b0 = np.asarray(r.friction_viscous, dtype=float)
        self.fc0 = np.asarray(r.friction_coulomb, dtype=float)
        self._data = mujoco.MjData(m)
        self._ct = arm.joints.matrix.T  # model dofs -> scene joints
        self._armature = arm.joints.matrix.T @ np.diag(m.dof_armature) @ arm.joints.matrix
        self.labels = [f"{b}.{p}" for b in self.bodies for p in PARAM_LABELS]
        if "currents" in self.kinds:
            self.labels += [f"{k}[{j}]" for k in ("kt_scale", "viscous", "coulomb", "rotor") for j in range(self.n)]
        if "joint_torques" in self.kinds:
            self.labels += [f"offset[{j}]" for j in range(self.n)]
        self.prior_sqrt = self._prior()
        self.prior_std = np.sqrt(np.sum(self.prior_sqrt**2, axis=1))

    def _prior(self) -> np.ndarray:
        p = self.priors
        blocks = [body_prior(self.pi0[k * N_PARAMS:(k + 1) * N_PARAMS], p.inertial) for k in range(len(self.bodies))]
        if "currents" in self.kinds:
            blocks.append(np.eye(self.n) * p.torque_constant_rel)
            blocks.append(np.diag(p.friction_rel * np.maximum(self.b0, p.viscous_floor)))
            blocks.append(np.diag(p.friction_rel * np.maximum(self.fc0, p.coulomb_floor)))
            blocks.append(np.diag(p.rotor_rel * np.maximum(self._inertia_at_home(), 1e-6)))
        if "joint_torques" in self.kinds:
            blocks.append(np.eye(self.n) * p.offset_nm)
        return block_diagonal(blocks)

    def _inertia_at_home(self) -> np.ndarray:
        """(n,) kg m^2: each scene joint's diagonal mass-matrix term at home."""
        m, d = self.arm.model, self._data
        self.arm.joints.set_qpos(np.asarray(self.arm.scene.robot.home, dtype=float), d.qpos)
        mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        return np.diag(self._ct @ full @ self._ct.T).copy()

    def rows(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Y, tau): the joint-torque regressor of the bodies' parameters (n x 10 len(bodies)) and the
        model's joint torques (N m, rigid body: no friction) at one state."""
        m, d, jm = self.arm.model, self._data, self.arm.joints
        jm.set_qpos(q, d.qpos)
        jm.set_dofs(qd, d.qvel)
        jm.set_dofs(qdd, d.qacc)
        for stage in (mujoco.mj_kinematics, mujoco.mj_comPos, mujoco.mj_comVel, mujoco.mj_rnePostConstraint):
            stage(m, d)
        y = self._ct @ joint_regressor(m, d, self.body_ids)
        return y, y @ self.pi0 + self._armature @ qdd

    def fit(self, segments: JointMotionData | Sequence[JointMotionData]) -> JointIdentFit:
        """Fit one stretch of free motion or several (each low-passed on its own, never across a gap)."""
        segments = [segments] if not isinstance(segments, Sequence) else list(segments)
        samples, dropped = [], 0
        for seg in segments:
            runs, bad = prepare_joint_motion(seg, self.kinds)
            samples += runs
            dropped += bad
        if not samples:
            raise IdentificationError(f"no usable stretch of motion ({dropped} rows not finite or out of order)")
        q, qd, qdd, sgn = (np.concatenate([getattr(s, k) for s in samples]) for k in ("q", "qd", "qdd", "sgn"))
        signal = {k: np.concatenate([s.signal[k] for s in samples]) for k in self.kinds}
        usable = len(q) if "joint_torques" in self.kinds else int(np.sum(np.any(np.abs(qd) > MIN_SPEED, axis=1)))
        if usable < MIN_SAMPLES:
            raise IdentificationError(f"{usable} usable samples of motion (at least {MIN_SAMPLES} needed: "
                                      f"{MIN_SAMPLES * SMOOTH_S:g} s with a joint faster than {MIN_SPEED} rad/s)")
        ys, taus = zip(*(self.rows(q[k], qd[k], qdd[k]) for k in range(len(q))), strict=True)
        ys, taus = np.array(ys), np.array(taus)
        state = (ys, taus, qd, sgn, qdd)
        before = {k: self._linear(k, np.zeros(len(self.labels)), state, signal[k])[1] for k in self.kinds}
        x, cov, e, use = self._solve(state, signal)
        scale_std = None
        friction_bound = np.zeros(self.n, dtype=bool)
        if self.kinds == ("currents",):
            friction_bound = self._rigid_share(x, state, use) < MIN_RIGID_SHARE
            x = self._prior_scale(x, friction_bound)
            x, scale_std = self._pin_scale(x, cov, q, ~friction_bound)
            e = {"currents": self._linear("currents", x, state, signal["currents"])[1]}
        fit = self._result(x, cov, e, before, use, len(q), dropped, noise_std(segments, self.kinds, self.kt0),
                           scale_std)
        self._verdict(fit, friction_bound)
        return fit

    def _rigid_share(self, x: np.ndarray, state: tuple[np.ndarray, ...], use: dict[str, np.ndarray]) -> np.ndarray:
        """(n,): each joint's links' torque RMS over its motor's, on the current rows fitted."""
        ys, taus, qd, sgn, qdd = state
        p_in, n = ys.shape[2], self.n
        rigid = taus + ys @ x[:p_in]
        motor = (rigid + (self.b0 + x[p_in + n:p_in + 2 * n]) * qd + (self.fc0 + x[p_in + 2 * n:p_in + 3 * n]) * sgn
                 + x[p_in + 3 * n:p_in + 4 * n] * qdd)
        m = use["currents"]
        return np.array([np.sqrt(np.mean(rigid[m[:, j], j] ** 2) / max(np.mean(motor[m[:, j], j] ** 2), 1e-30))
                         if m[:, j].any() else 0.0 for j in range(n)])

    def _prior_scale(self, x: np.ndarray, joints: np.ndarray) -> np.ndarray:
        """``x`` with the torque constant of ``joints`` at the scene's value, their friction and rotor
        scaled with it (each joint's current is then what it was, but for its links' small share)."""
        x = x.copy()
        p_in, n = N_PARAMS * len(self.bodies), self.n
        for j in np.flatnonzero(joints):
            f = 1.0 / (1.0 + x[p_in + j])
            x[p_in + j] = 0.0
            x[p_in + n + j] = f * (self.b0[j] + x[p_in + n + j]) - self.b0[j]
            x[p_in + 2 * n + j] = f * (self.fc0[j] + x[p_in + 2 * n + j]) - self.fc0[j]
            x[p_in + 3 * n + j] *= f
        return x

    def _pin_scale(self, x: np.ndarray, cov: np.ndarray, q: np.ndarray,
                   candidates: np.ndarray) -> tuple[np.ndarray, float]:
        """``x`` moved along the common scale the currents cannot tell (every parameter times ``c``: the
        residuals in amperes stay as they are) to where the vendor's data put it, and the scale's relative
        std. Two kinds of evidence, each with its prior: the gravity torques at the motion's poses (the
        identified ones against the model's, known to ``mass_rel`` per body, averaged over the bodies) and
        each torque constant the data told (``torque_constant_rel``). A torque constant the data did not
        tell, a mass the motion cannot tell apart, would only say their prior again."""
        n, p_in = self.n, N_PARAMS * len(self.bodies)
        theta0 = np.concatenate([self.pi0, np.ones(n), self.b0, self.fc0, np.diag(self._armature)])
        theta = theta0 + x
        poses = q[np.linspace(0, len(q) - 1, min(len(q), GRAVITY_POSES)).astype(int)]
        z = np.zeros(n)
        g = np.concatenate([self.rows(pose, z, z)[0] for pose in poses])  # the gravity torques' regressor
        nominal, fitted = g @ self.pi0, g @ theta[:p_in]
        ratios = [float(fitted @ nominal / (nominal @ nominal))]
        stds = [self.priors.inertial.mass_rel / np.sqrt(len(self.bodies))]
        told = candidates & (np.sqrt(np.diag(cov))[p_in:p_in + n] < TOLD * self.priors.torque_constant_rel)
        ratios += list(theta[p_in:p_in + n][told])
        stds += [self.priors.torque_constant_rel] * int(told.sum())
        a, b = np.array(ratios) / np.array(stds), 1.0 / np.array(stds)
        c = float(a @ b / (a @ a))
        return c * theta - theta0, float(1.0 / np.sqrt(a @ a))

    def _solve(self, state: tuple[np.ndarray, ...], signal: dict[str, np.ndarray]):
        """Gauss-Newton on the readings' own units (a current's residual ``i - tau / kt`` does not shrink
        with a common scale of the torque constants and the torques, which a torque-side residual would
        pull toward zero), each signal's joint weighed by its robust residual scale, each row by Huber's
        weight. Returns the estimate, its covariance, the residuals (kind -> (M, n), the reading's
        units) and the rows fitted (kind -> (M, n) bool)."""
        qd = state[2]
        use = {k: (np.abs(qd) > MIN_SPEED if k == "currents" else np.ones(qd.shape, dtype=bool)) for k in self.kinds}
        scale = {k: np.ones(self.n) for k in self.kinds}
        huber = {k: np.ones(qd.shape) for k in self.kinds}
        x = np.zeros(len(self.labels))
        cov = e = None
        for _ in range(8):
            a, y, w = [], [], []
            for kind in self.kinds:
                jac, err = self._linear(kind, x, state, signal[kind])
                jac = jac.reshape(-1, len(self.labels))
                a.append(jac)
                y.append(jac @ x - err.reshape(-1))
                w.append(np.where(use[kind], np.sqrt(huber[kind]) / scale[kind], 0.0).reshape(-1))
            a, y, w = np.vstack(a), np.concatenate(y), np.concatenate(w)
            if not (np.all(np.isfinite(a)) and np.all(np.isfinite(y))):
                raise IdentificationError("the motion data hold NaN or Inf after preparation")
            x, cov = _bayes_normal(a * w[:, None], y * w, self.prior_sqrt)
            e = {kind: self._linear(kind, x, state, signal[kind])[1] for kind in self.kinds}
            for kind in self.kinds:
                for j in range(self.n):
                    r = e[kind][use[kind][:, j], j]
                    if len(r):
                        scale[kind][j] = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 1e-9)
                u = np.abs(e[kind]) / scale[kind]
                huber[kind] = np.where(u <= HUBER_K, 1.0, HUBER_K / np.maximum(u, 1e-12))
        return x, cov, e, use

    def _linear(self, kind: str, x: np.ndarray, state: tuple[np.ndarray, ...],
                reading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(J, e) at ``x``: the residual ``reading - model`` (M, n) and its derivative with respect to
        the parameters (M, n, P). ``state``: the regressor, the model's torques, qd, the Coulomb column."""
        ys, taus, qd, sgn, qdd = state
        m_s, n, p_in = len(qd), self.n, ys.shape[2]
        torque = taus + ys @ x[:p_in]  # the links' joint torques at x
        jac = np.zeros((m_s, n, len(self.labels)))
        eye = np.eye(n)
        if kind == "joint_torques":
            col = len(self.labels) - n
            jac[:, :, :p_in] = -ys
            jac[:, :, col:] = -eye
            return jac, reading - torque - x[col:]
        col = p_in
        kt = self.kt0 * (1.0 + x[col:col + n])
        motor = (torque + (self.b0 + x[col + n:col + 2 * n]) * qd + (self.fc0 + x[col + 2 * n:col + 3 * n]) * sgn
                 + x[col + 3 * n:col + 4 * n] * qdd)
        jac[:, :, :p_in] = -ys / kt[:, None]
        jac[:, :, col:col + n] = (motor / kt * (self.kt0 / kt))[:, :, None] * eye
        jac[:, :, col + n:col + 2 * n] = -(qd / kt)[:, :, None] * eye
        jac[:, :, col + 2 * n:col + 3 * n] = -(sgn / kt)[:, :, None] * eye
        jac[:, :, col + 3 * n:col + 4 * n] = -(qdd / kt)[:, :, None] * eye
        return jac, reading - motor / kt

    def _result(self, x, cov, e, before_e, use, samples, dropped, noise, scale_std) -> JointIdentFit:
        n, nb = self.n, len(self.bodies)
        dpi = x[:N_PARAMS * nb].reshape(nb, N_PARAMS)
        col = N_PARAMS * nb
        kt, b, fc, off, rotor = self.kt0.copy(), self.b0.copy(), self.fc0.copy(), np.zeros(n), np.zeros(n)
        if "currents" in self.kinds:
            kt = self.kt0 * (1.0 + x[col:col + n])
            b, fc = self.b0 + x[col + n:col + 2 * n], self.fc0 + x[col + 2 * n:col + 3 * n]
            rotor = x[col + 3 * n:col + 4 * n].copy()
            col += 4 * n
        if "joint_torques" in self.kinds:
            off = x[col:col + n].copy()
        after, before = {}, {}
        for kind in self.kinds:
            after[kind] = _masked_std(e[kind] * (kt if kind == "currents" else 1.0), use[kind])  # N m
            before[kind] = _masked_std(before_e[kind] * (self.kt0 if kind == "currents" else 1.0), use[kind],
                                       centred=kind == "joint_torques")
        fit = JointIdentFit(self.kinds, self.bodies, dpi, kt, b, fc, off, rotor, cov, list(self.labels), self.prior_std,
                            after, before, noise, samples, dropped, scale_std)
        return fit

    def _verdict(self, fit: JointIdentFit, friction_bound: np.ndarray) -> None:
        ratio = fit.std / self.prior_std
        never = self.unidentifiable()
        fit.unidentifiable = [lab for lab in self.labels if lab in never]
        fit.untold = [lab for lab, v in zip(self.labels, ratio, strict=True) if v > TOLD and lab not in never]
        if fit.untold:
            fit.verdict = "poorly_excited"
            fit.reasons.append(f"{len(fit.untold)} of {len(self.labels) - len(never)} parameters that joint signals "
                               f"can tell were not told apart by this motion (posterior std above {TOLD:g} x "
                               "prior): they stay at the model's values")
        bound = [self.arm.scene.robot.joints[j] for j in np.flatnonzero(friction_bound)]
        if bound:
            labels = [f"kt_scale[{j}]" for j in np.flatnonzero(friction_bound)]
            fit.untold += [lab for lab in labels if lab not in fit.untold]
            fit.verdict = "poorly_excited"
            fit.reasons.append(f"{', '.join(bound)}: the links' torque is less than {MIN_RIGID_SHARE:g} of the motor's "
                               "(the rest is the joint's own friction), which cannot tell the torque constant: the "
                               "scene's value kept, the friction fitted at its scale")
        if fit.unidentifiable:
            fit.reasons.append(f"{len(fit.unidentifiable)} inertial parameters no motion tells from joint signals "
                               "(the base links' unseen moments): the model's values kept")
        if fit.scale_std is not None:
            fit.reasons.append(f"the currents cannot tell a common scale of every torque constant, inertial "
                               f"parameter and friction term: the gravity torques of the vendor's masses and the "
                               f"torque constants' priors pin it to {100 * fit.scale_std:.1f} % (1 sigma)")
        low = [j for j in range(self.n) if np.any(fit.torque_constant[j] <= 0)]
        if low:
            fit.verdict = "bad"
            fit.reasons.append(f"joints {low}: a torque constant <= 0 (the currents do not follow the torques)")

    def unidentifiable(self) -> set[str]:
        """The inertial labels no motion can tell from joint torques: their prior-scaled posterior stays
        above TOLD x prior under abundant data at random states (the regressor's structural null space)."""
        if getattr(self, "_never", None) is None:
            rng = np.random.default_rng(0)
            home = np.asarray(self.arm.scene.robot.home, dtype=float)
            rows = [self.rows(home + rng.uniform(-1.5, 1.5, self.n), rng.normal(size=self.n),
                              rng.normal(size=self.n) * 3)[0] for _ in range(GENERIC_STATES)]
            p_in = N_PARAMS * len(self.bodies)
            prior = self.prior_sqrt[:p_in, :p_in]
            _, cov = bayes(np.vstack(rows) * 1e4, np.zeros(GENERIC_STATES * self.n), prior)
            ratio = np.sqrt(np.maximum(np.diag(cov), 0.0)) / self.prior_std[:p_in]
            self._never = {lab for lab, v in zip(self.labels[:p_in], ratio, strict=True) if v > TOLD}
        return self._never


def _bayes_normal(a: np.ndarray, y: np.ndarray, prior_sqrt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~.free_motion.bayes` through its normal equations (``B^T B + 1`` is never singular): a
    tall stack of joint rows costs its SVD seconds, this milliseconds."""
    b = a @ prior_sqrt
    lam, vec = np.linalg.eigh(b.T @ b)  # its rounding (eps x the largest) is far below the prior's 1
    h_inv = (vec / (np.maximum(lam, 0.0) + 1.0)) @ vec.T
    z = h_inv @ (b.T @ y)
    return prior_sqrt @ z, prior_sqrt @ h_inv @ prior_sqrt.T


def _masked_std(r: np.ndarray, mask: np.ndarray, centred: bool = False) -> np.ndarray:
    out = np.zeros(r.shape[1])
    for j in range(r.shape[1]):
        v = r[mask[:, j], j]
        if len(v):
            out[j] = float(np.std(v)) if centred else float(np.sqrt(np.mean(v * v)))
    return out
