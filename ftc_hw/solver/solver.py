"""Contact localization: from the external contact wrench and q, where the arm was touched, how hard,
and how sure we are.

Method ("ours"): the wrench's line of action crossed with every touchable primitive (analytic,
stable roots), hidden and inadmissible crossings dropped (inside another primitive; pulls where
the scene forbids them); every link the line misses by less than 3 of its own local standard
deviations is a candidate too (noise moves the line off a touched link, or behind a seam). Then for
each candidate the weighted least-squares fit on its surface: minimise the Mahalanobis distance of
the 6-D wrench over the contact point (on the surface) and the force; the force is solved in closed
form at each point and Gauss-Newton moves the point (variable projection). Covariances come from
the Jacobian at the solution; candidates are ranked by log-likelihood, including the per-joint
external torques when given (link isolation), and the answer is ``ambiguous`` when a runner-up
comes within a factor 100 in likelihood.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from ..geometry import kinds as GK
from ..model import ArmModel
from ..model.arm import GEOM_KINDS, SURFACE_GROUP
from ..scene import Scene
from . import kernels as K

FLAG_NAMES = {
    K.F_INVALID: "invalid_input",
    K.F_LOW_FORCE: "low_force",
    K.F_NO_CANDIDATE: "no_candidate",
    K.F_AMBIGUOUS: "ambiguous",
    K.F_GRAZING: "grazing",
    K.F_OFF_SURFACE: "off_surface",
    K.F_SATURATED: "saturated",
    K.F_PULL: "pull",
    K.F_OFF_LINE: "off_line",
    K.F_NOT_CONVERGED: "not_converged",
}
CHI2_1DOF_999 = 10.827566170662733  # chi-square quantile, 1 degree of freedom, p = 0.999
# ambiguous: a runner-up whose likelihood is within a factor 100 of the best (posterior >= ~1 %)
AMBIGUITY_DLOGL = math.log(100.0)
BATCH_CANDIDATES = 4  # candidates kept per frame by solve_batch (the best first)


_FLAG_CACHE: dict[int, tuple[str, ...]] = {}


def flag_names(bits: int) -> tuple[str, ...]:
    names = _FLAG_CACHE.get(bits)
    if names is None:
        names = _FLAG_CACHE[bits] = tuple(name for bit, name in FLAG_NAMES.items() if bits & bit)
    return names


@dataclass(frozen=True, slots=True)
class Candidate:
    link: str
    point: np.ndarray  # m, base frame
    force: np.ndarray  # N applied to the arm, base frame
    score: float  # log-likelihood (higher is better)
    chi2: float


@dataclass(frozen=True, slots=True)
class ContactEstimate:
    """The solver's answer for one frame (SI, base frame).

    ``contact`` is False when no admissible point exists (``no_candidate``, ``invalid_input``) or the
    force is below the noise floor (``low_force``; the best fit is still filled in).
    ``residual`` is the moment about the force line (N m): zero for a perfect point contact.
    ``cov`` is the 6x6 covariance of (point, force); the point block has rank 2 (on the surface).
    ``conditioning`` is the condition number of the fit's information matrix.
    """

    contact: bool
    link: str | None
    point: np.ndarray
    force: np.ndarray
    normal: np.ndarray
    residual: float
    chi2: float
    cov: np.ndarray
    conditioning: float
    flags: tuple[str, ...]
    candidate_links: tuple[str, ...]  # best first
    candidate_data: np.ndarray  # (n, 8): point (3), force (3), score, chi2

    @property
    def candidates(self) -> tuple[Candidate, ...]:
        """Every admissible candidate, best first (built on demand: the live path rarely needs it)."""
        d = self.candidate_data
        return tuple(Candidate(link, d[k, 0:3], d[k, 3:6], float(d[k, 6]), float(d[k, 7]))
                     for k, link in enumerate(self.candidate_links))

    @property
    def point_std(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.cov)[:3], 0.0))

    @property
    def force_std(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.cov)[3:], 0.0))


@dataclass(frozen=True)
class BatchEstimate:
    """Arrays over N frames; ``flags`` are bit masks (see ``flag_names``); ``link`` indexes ``links``."""

    contact: np.ndarray  # (N,) bool
    link: np.ndarray  # (N,) int, -1 when none
    point: np.ndarray  # (N, 3)
    force: np.ndarray  # (N, 3)
    normal: np.ndarray  # (N, 3)
    residual: np.ndarray
    chi2: np.ndarray
    cov: np.ndarray  # (N, 6, 6)
    conditioning: np.ndarray
    flags: np.ndarray  # (N,) int
    n_candidates: np.ndarray  # (N,) admissible candidates found
    candidate_link: np.ndarray  # (N, BATCH_CANDIDATES) link index, best first, -1 past n_candidates
    candidate_data: np.ndarray  # (N, BATCH_CANDIDATES, 8): point (3), force (3), score, chi2
    links: tuple[str, ...]

    @classmethod
    def from_estimates(cls, estimates: list[ContactEstimate], links: tuple[str, ...]) -> BatchEstimate:
        """Pack single-frame estimates (a method without a batch kernel) into the batch arrays."""
        n = len(estimates)
        index = {name: i for i, name in enumerate(links)}
        bits = {name: bit for bit, name in FLAG_NAMES.items()}
        cand_link = np.full((n, BATCH_CANDIDATES), -1, dtype=np.int64)
        cand_data = np.zeros((n, BATCH_CANDIDATES, K.C_SIZE))
        for i, e in enumerate(estimates):
            for j, c in enumerate(e.candidates[:BATCH_CANDIDATES]):
                cand_link[i, j] = index[c.link]
                cand_data[i, j] = np.concatenate([c.point, c.force, [c.score, c.chi2]])
        return cls(
            contact=np.array([e.contact for e in estimates], dtype=bool),
            link=np.array([index[e.link] if e.link else -1 for e in estimates], dtype=np.int64),
            point=np.array([e.point for e in estimates]).reshape(n, 3),
            force=np.array([e.force for e in estimates]).reshape(n, 3),
            normal=np.array([e.normal for e in estimates]).reshape(n, 3),
            residual=np.array([e.residual for e in estimates], dtype=float),
            chi2=np.array([e.chi2 for e in estimates], dtype=float),
            cov=np.array([e.cov for e in estimates]).reshape(n, 6, 6),
            conditioning=np.array([e.conditioning for e in estimates], dtype=float),
            flags=np.array([sum(bits[f] for f in e.flags) for e in estimates], dtype=np.int64),
            n_candidates=np.array([len(e.candidate_links) for e in estimates], dtype=np.int64),
            candidate_link=cand_link, candidate_data=cand_data, links=links)


class ContactSolver:
    """Solver for one scene. Not thread-safe (it owns the model's MjData): one per thread."""

    def __init__(self, scene: Scene | ArmModel, *, low_force_sigma: float = 5.0, grazing_deg: float = 5.0,
                 ambiguity_dlogl: float = AMBIGUITY_DLOGL, hide_tol: float = 1e-8, max_iter: int = 20,
                 tau_std: np.ndarray | None = None, miss_sigma: float = 3.0) -> None:
        self.model = scene if isinstance(scene, ArmModel) else ArmModel(scene)
        self.scene = self.model.scene
        m = self.model.model
        touch = {t.link: t for t in self.scene.touchable}
        geoms = [g for g in range(m.ngeom)
                 if m.geom_group[g] == SURFACE_GROUP and int(m.geom_type[g]) in GEOM_KINDS]
        self._geom_ids = np.array(geoms, dtype=np.int64)
        self.kinds = np.array([GK.KINDS[GEOM_KINDS[int(m.geom_type[g])]] for g in geoms], dtype=np.int64)
        # MuJoCo's size triple and a bounding radius about the geom centre
        self.sizes = np.array([np.append(m.geom_size[g], _bounding_radius(self.kinds[i], m.geom_size[g]))
                               for i, g in enumerate(geoms)], dtype=float).reshape(len(geoms), 4)
        self.prim_link = np.array([m.geom_bodyid[g] for g in geoms], dtype=np.int64)
        self.prim_touch = np.array([m.body(int(m.geom_bodyid[g])).name in touch for g in geoms])
        self.prim_pulls = np.array([bool(touch.get(m.body(int(m.geom_bodyid[g])).name) and
                                         touch[m.body(int(m.geom_bodyid[g])).name].pulls) for g in geoms])
        self.links = tuple(m.body(b).name for b in range(m.nbody))
        self._prim_names = tuple(self.links[b] for b in self.prim_link.tolist())  # each primitive's link
        self._kin_q: np.ndarray | None = None  # the q of the scratch's body poses (last solve)
        # joint j moves body b when j's body is b or an ancestor of b
        self.link_joint = np.zeros((m.nbody, m.njnt), dtype=np.bool_)
        for b in range(m.nbody):
            a = b
            while a > 0:
                for j in range(m.body_jntadr[a], m.body_jntadr[a] + m.body_jntnum[a]):
                    self.link_joint[b, j] = True
                a = int(m.body_parentid[a])
        jm = self.model.joints
        # model joint -> (scene joint or -1, MuJoCo joint type), and its ratio
        self.jnt_i = np.stack([np.full(m.njnt, -1, dtype=np.int64), m.jnt_type.astype(np.int64)], axis=1)
        self.jnt_i[jm.jnt_ids, 0] = jm.joint
        self.jnt_ratio = np.zeros(m.njnt)
        self.jnt_ratio[jm.jnt_ids] = jm.ratio
        self._a_pose: np.ndarray | None = None  # the sensor pose of _a, the last _sensor_to_base
        self._a = np.eye(6)
        sensor_body = self.model.sensor_body
        self.sensor_moves = bool(self.link_joint[sensor_body].any())
        self.sigma_sensor = self.scene.sensor.noise_cov
        self.ext_sign = -self.scene.sensor.reading_sign  # reading -> the contact wrench on the arm
        q0 = np.array(self.scene.robot.home)
        self._A0, self._WS0 = self._frame_transform(q0)
        self._W0 = self._WS0[:6]
        force_var = np.trace(self._WS0[6:9, :3]) / 3.0  # the covariance sits under W
        self.low_force = float(low_force_sigma * np.sqrt(force_var))
        self.grazing_cos = float(np.sin(np.radians(grazing_deg)))
        self.off_chi2 = CHI2_1DOF_999
        self.ambiguity_dlogl = float(ambiguity_dlogl)
        self.hide_tol = float(hide_tol)
        self.max_iter = int(max_iter)
        if tau_std is None:
            tau_std = np.maximum(self.scene.robot.torque_constant * self.scene.robot.current_noise_std, 0.05)
        self.tau_var = np.asarray(tau_std, dtype=float).reshape(self.model.n_joints) ** 2
        self.tau_var[self.tau_var == 0] = 1.0
        self.prim_i = np.ascontiguousarray(np.stack([self.kinds, self.prim_link, self.prim_touch.astype(np.int64),
                                                     self.prim_pulls.astype(np.int64)], axis=1))
        self.cfg = np.zeros(K.CFG_SIZE)
        self.cfg[:6] = (self.low_force, self.grazing_cos, self.off_chi2, self.ambiguity_dlogl, self.hide_tol,
                        self.max_iter)
        # the line's position uncertainty: moment noise over force, and force noise times the arm's
        # reach; near misses within miss_sigma of it stay candidates
        kin = self.model.kinematics(q0)
        reach = max(float(np.linalg.norm((kin[self.links[self.prim_link[i]]] @ np.append(
            m.geom_pos[g], 1.0))[:3])) + self.sizes[i, 3] for i, g in enumerate(geoms) if self.kinds[i] != GK.PLANE)
        sig = np.sqrt(np.diag(self._WS0[6:]))
        self.cfg[K.CFG_MISS_TOL] = miss_sigma * float(np.linalg.norm(sig[3:]) + np.linalg.norm(sig[:3]) * reach)
        self.cfg[K.CFG_MISS_T] = miss_sigma * float(np.linalg.norm(sig[3:]))
        self.cfg[K.CFG_MISS_F] = miss_sigma * float(np.linalg.norm(sig[:3]))
        self.cfg[K.CFG_MISS_SIGMA] = miss_sigma
        self._tree = _TreeArrays(m, self._geom_ids)
        self.max_candidates = 2 * len(geoms)
        self._out = np.zeros(K.O_SIZE)
        self._ws_extra = np.zeros((12, 6))
        self._cand_prim = np.zeros(self.max_candidates, dtype=np.int64)
        self._cand_f = np.zeros((self.max_candidates, K.C_SIZE))
        self._tau = np.zeros(self.model.n_joints)
        self._tau_var_frame = self.tau_var.copy()
        self._no_extra = np.zeros((6, 6))  # frame_inputs' extra covariance when there is none
        self._sigma = np.array(self.sigma_sensor, dtype=np.float64)  # its own: C-ordered, writable
        self._ws = np.zeros(K.workspace_size(self.max_candidates))
        self._raw_prim = np.zeros(self.max_candidates, dtype=np.int64)
        self._qfull = np.zeros(m.nq)
        self._scratch = (np.zeros((m.nbody, 3)), np.zeros((m.nbody, 4)), np.zeros((len(geoms), 3)),
                         np.zeros((len(geoms), 9)), np.zeros((m.njnt, 3)), np.zeros((m.njnt, 3)))

    # -- frames ---------------------------------------------------------------------------------------
    def _sensor_to_base(self, q) -> np.ndarray:
        """A: maps a sensor-frame wrench about the sensor origin to the base frame about the base
        origin, at joint angles q."""
        b_T_s = self.model.base_T_sensor(q)  # the same array while q is (the model keeps the last)
        if b_T_s is self._a_pose:
            return self._a
        r, t = b_T_s[:3, :3], b_T_s[:3, 3]
        a = np.zeros((6, 6))
        a[:3, :3] = r
        a[3:, 3:] = r
        a[3:, :3] = _skew(t) @ r
        self._a, self._a_pose = a, b_T_s  # (the callers only read it)
        return a

    def _frame_transform(self, q) -> tuple[np.ndarray, np.ndarray]:
        """A (``_sensor_to_base``) and, stacked over each other (12 x 6: the kernels take both at
        once), W, the inverse covariance of the external wrench in the base frame, and that covariance."""
        a = self._sensor_to_base(q)
        ws = np.empty((12, 6))
        if not K.weight_stack(a, self.sigma_sensor, ws):
            raise ValueError("the wrench covariance is not positive definite")
        return a, ws

    def external_wrench_base(self, wrench_sensor, q=None) -> np.ndarray:
        """(p, c x p) in the base frame about the base origin from a compensated sensor reading."""
        a = self._sensor_to_base(q) if (self.sensor_moves and q is not None) else self._A0
        return self.ext_sign * (a @ np.asarray(wrench_sensor, dtype=float))

    # -- single frame ---------------------------------------------------------------------------------
    def solve(self, wrench_sensor, q, tau_ext=None, saturated: bool = False, tau_std=None,
              extra_cov=None) -> ContactEstimate:
        """Estimate the contact from the compensated wrench (sensor frame, the scene's sign
        convention: the external contact wrench only) at joint angles q (rad).

        ``tau_ext``: optional per-joint external torques (N m, the scene's joint order) from the
        joint currents; they score each candidate by J_c^T p and isolate the link. ``tau_std``: their
        standard deviations for this frame (default: the solver's, from the current noise).
        ``extra_cov``: the compensation's own uncertainty for this frame (6x6, sensor frame), added
        to the sensor noise: it weights the fit and enters the reported covariance.
        """
        self._kin_q = None  # the scratch's body poses are stale until the kernel has run
        n_j = self.model.n_joints
        # copies, C-ordered and writable: frame_inputs is compiled (and warmed) for those (a read-only
        # frame's array would be another signature, compiled at the first contact)
        w = np.array(wrench_sensor, dtype=np.float64).reshape(6)
        q = np.array(q, dtype=np.float64).reshape(n_j)
        if self.sensor_moves and not (math.isfinite(np.add.reduce(w)) and math.isfinite(np.add.reduce(q))):
            return self._invalid(saturated)  # NaN or Inf anywhere (checked first: the pose needs a finite q)
        use_extra, use_tau = extra_cov is not None, tau_ext is not None
        use_std = use_tau and tau_std is not None
        if use_extra:
            a, wmat = (self._sensor_to_base(q) if self.sensor_moves else self._A0), self._ws_extra
        elif self.sensor_moves:
            a, wmat = self._frame_transform(q)
        else:
            a, wmat = self._A0, self._WS0
        tau_var = self._tau_var_frame if use_std else self.tau_var
        # the checks, the weight with the extra covariance and the joint torques' layout: one kernel
        if not K.frame_inputs(w, q, a, self._sigma,
                              np.array(extra_cov, dtype=np.float64).reshape(6, 6) if use_extra else self._no_extra,
                              use_extra, np.array(tau_ext, dtype=np.float64).reshape(n_j) if use_tau else self._tau,
                              use_tau, _per_joint(tau_std, n_j) if use_std else self._tau, use_std, wmat, self._tau,
                              tau_var):
            return self._invalid(saturated)
        self.model.joints.set_qpos(q, self._qfull)
        ext = self.ext_sign * (a @ w)
        tr, sc = self._tree, self._scratch
        n = K.solve_frame_q(ext, self._qfull, wmat, self.prim_i, self.sizes, self.link_joint, self.jnt_i,
                            self.jnt_ratio, self._tau, tau_var, use_tau, self.cfg, tr.tree_i, tr.tree_f, tr.geom_i,
                            tr.geom_f, self._out, self._cand_prim, self._cand_f, self._ws, self._raw_prim, *sc)
        self._kin_q = q  # the solver's own copy
        return self._estimate(n, saturated)

    def solved_body_poses(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``body_poses`` at the last ``solve``'s q without checking q (None when that solve ran no
        kinematics): for a caller that has just solved at the q it needs."""
        return None if self._kin_q is None else (self._scratch[0], self._scratch[1])

    def body_poses(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Every body's position (nbody, 3) and quaternion (nbody, 4) in the base frame at joint
        angles q, in MuJoCo's layout: the last ``solve``'s own kinematics when it was at this q (no
        second pass), else computed now. Valid until the next call or solve."""
        q = np.asarray(q, dtype=np.float64)
        sc = self._scratch
        if self._kin_q is None or not np.array_equal(q, self._kin_q):
            self.model.joints.set_qpos(q, self._qfull)
            tr = self._tree
            K.tree_kinematics(self._qfull, tr.tree_i, tr.tree_f, tr.geom_i, tr.geom_f, *sc)
            self._kin_q = q.copy()
        return sc[0], sc[1]

    def _invalid(self, saturated: bool) -> ContactEstimate:
        z = np.zeros(3)
        bits = K.F_INVALID | (K.F_SATURATED if saturated else 0)
        return ContactEstimate(False, None, z, z, z, 0.0, 0.0, np.zeros((6, 6)), math.inf, flag_names(bits), (),
                               np.zeros((0, K.C_SIZE)))

    def _estimate(self, n: int, saturated: bool) -> ContactEstimate:
        out = self._out
        sc = out[K.O_SCALARS:K.O_SCALARS + 8].tolist()
        bits = int(sc[K.S_FLAGS]) | (K.F_SATURATED if saturated else 0)
        if n == 0:
            z = np.zeros(3)
            return ContactEstimate(False, None, z, z, z, sc[K.S_RESIDUAL], 0.0, np.zeros((6, 6)), math.inf,
                                   flag_names(bits), (), np.zeros((0, K.C_SIZE)))
        names = self._prim_names
        cand_links = tuple([names[g] for g in self._cand_prim[:n].tolist()])
        out = out.copy()
        cov = out[K.O_COV:K.O_COV + 36].reshape(6, 6)
        if not math.isfinite(np.add.reduce(out[K.O_COV:K.O_COV + 36])):
            cov = _unbounded(cov)
        # below the noise floor the fit is reported but not called a contact
        return ContactEstimate(not bits & K.F_LOW_FORCE, cand_links[0], out[0:3], out[3:6], out[6:9],
                               sc[K.S_RESIDUAL], sc[K.S_CHI2], cov, sc[K.S_COND],
                               flag_names(bits), cand_links, self._cand_f[:n].copy())

    # -- batch ----------------------------------------------------------------------------------------
    def solve_batch(self, wrenches_sensor, qs, tau_ext=None, saturated=None) -> BatchEstimate:
        """``solve`` over N frames at once: wrenches (N, 6), qs (N, n); the same answers."""
        w = np.ascontiguousarray(wrenches_sensor, dtype=np.float64).reshape(-1, 6)
        n = w.shape[0]
        qs = np.ascontiguousarray(qs, dtype=np.float64).reshape(n, self.model.n_joints)
        m = self.model.model
        qfull = np.zeros((n, m.nq))
        jm = self.model.joints
        qfull[:, jm.qadr] = jm.ratio * qs[:, jm.joint]
        if self.sensor_moves:
            pairs = [self._frame_transform(q) for q in qs]
            ext = np.einsum("nij,nj->ni", np.array([p[0] for p in pairs]), w) * self.ext_sign
            ws = np.array([p[1] for p in pairs])
        else:
            # not w @ A.T: that wakes BLAS's thread pool, whose spinning threads then take the cores
            # from the kernel's own threads (a 20 000-frame batch ran 1.6x slower)
            ext = np.einsum("ij,nj->ni", self._A0, w) * self.ext_sign
            ws = self._WS0[None]
        ext = np.ascontiguousarray(ext)
        use_tau = np.zeros(n, dtype=np.bool_)
        tau = np.zeros((n, self.model.n_joints))
        if tau_ext is not None:
            t = np.asarray(tau_ext, dtype=float).reshape(n, self.model.n_joints)
            tau[:] = t
            use_tau[:] = np.all(np.isfinite(t), axis=1)
            tau[~use_tau] = 0.0
        bad = ~(np.all(np.isfinite(ext), axis=1) & np.all(np.isfinite(qfull), axis=1))
        qfull[bad] = 0.0
        out = np.zeros((n, K.O_SIZE))
        cand_f = np.zeros((n, BATCH_CANDIDATES, K.C_SIZE))
        cand_prim = np.zeros((n, BATCH_CANDIDATES), dtype=np.int64)
        n_cand = np.zeros(n, dtype=np.int64)
        tr = self._tree
        K.solve_batch(ext, qfull, ws, self.prim_i, self.sizes, self.link_joint, self.jnt_i, self.jnt_ratio, tau,
                      self.tau_var, use_tau, self.cfg,
                      tr.tree_i, tr.tree_f, tr.geom_i, tr.geom_f, self.max_candidates, out, cand_prim, cand_f, n_cand)
        sc = out[:, K.O_SCALARS:K.O_SCALARS + 8]
        flags = sc[:, K.S_FLAGS].astype(np.int64)
        flags[bad] = K.F_INVALID
        if saturated is not None:
            flags[np.asarray(saturated, dtype=bool)] |= K.F_SATURATED
        contact = (n_cand > 0) & ~bad & ((flags & K.F_LOW_FORCE) == 0)
        link = np.where(contact, self.prim_link[cand_prim[:, 0]], -1)
        cand_link = np.where(np.arange(BATCH_CANDIDATES)[None] < n_cand[:, None], self.prim_link[cand_prim], -1)
        return BatchEstimate(contact=contact, link=link, point=out[:, 0:3], force=out[:, 3:6], normal=out[:, 6:9],
                             residual=sc[:, K.S_RESIDUAL], chi2=sc[:, K.S_CHI2],
                             cov=_unbounded_where_broken(out[:, K.O_COV:K.O_COV + 36].reshape(n, 6, 6)),
                             conditioning=sc[:, K.S_COND],
                             flags=flags, n_candidates=n_cand, candidate_link=cand_link, candidate_data=cand_f,
                             links=self.links)


class _TreeArrays:
    """The compiled model's tree in the packed arrays the batch kinematics kernel reads."""

    def __init__(self, m: mujoco.MjModel, geom_ids: np.ndarray) -> None:
        hinge, slide = int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)
        self.tree_i = np.zeros((m.nbody, 4), dtype=np.int64)
        self.tree_f = np.zeros((m.nbody, 13))
        for b in range(m.nbody):
            if m.body_jntnum[b] > 1:
                raise ValueError(f"body {m.body(b).name!r} has {m.body_jntnum[b]} joints; the batch solver "
                                 "supports one hinge or slide joint per body")
            j = int(m.body_jntadr[b]) if m.body_jntnum[b] == 1 else -1
            self.tree_i[b, 0] = m.body_parentid[b]
            self.tree_i[b, 1] = j
            self.tree_f[b, 0:3] = m.body_pos[b]
            self.tree_f[b, 3:7] = m.body_quat[b]
            if j >= 0:
                if int(m.jnt_type[j]) not in (hinge, slide):
                    raise ValueError(f"joint {m.joint(j).name!r} is not a hinge or slide joint")
                self.tree_i[b, 2] = m.jnt_type[j]
                self.tree_i[b, 3] = m.jnt_qposadr[j]
                self.tree_f[b, 7:10] = m.jnt_axis[j]
                self.tree_f[b, 10:13] = m.jnt_pos[j]
        self.geom_i = m.geom_bodyid[geom_ids].astype(np.int64).reshape(-1, 1)
        self.geom_f = np.ascontiguousarray(np.concatenate([m.geom_pos[geom_ids], m.geom_quat[geom_ids]], axis=1))


def _bounding_radius(kind: int, size: np.ndarray) -> float:
    r, h = float(size[0]), float(size[1])
    if kind == GK.SPHERE:
        return r
    if kind == GK.CAPSULE:
        return r + h
    if kind == GK.CYLINDER:
        return float(np.hypot(r, h))
    if kind == GK.ELLIPSOID:
        return float(np.max(size[:3]))
    if kind == GK.BOX:
        return float(np.linalg.norm(size[:3]))
    return math.inf  # plane


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])



def _per_joint(x, n: int) -> np.ndarray:
    """``x`` (one value or one per joint) as n contiguous floats."""
    a = np.array(x, dtype=np.float64)  # a copy: C-ordered, writable (see solve)
    return a if a.shape == (n,) else np.full(n, a)


def _unbounded(cov: np.ndarray) -> np.ndarray:
    """A covariance the fit could not give in full (a singular information matrix: a fit that did
    not converge, a force below the noise floor): the broken rows get an infinite variance and no
    correlations, instead of NaN."""
    ok = np.isfinite(cov).all(axis=1)
    out = np.where(np.outer(ok, ok), cov, 0.0)
    bad = np.flatnonzero(~ok)
    out[bad, bad] = np.inf
    return out


def _unbounded_where_broken(covs: np.ndarray) -> np.ndarray:
    broken = ~np.isfinite(covs).all(axis=(1, 2))
    for i in np.flatnonzero(broken):
        covs[i] = _unbounded(covs[i])
    return covs
