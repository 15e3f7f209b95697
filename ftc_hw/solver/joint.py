"""Contact localization from the external joint torques (and a flange sensor's wrench where present).

A contact particle filter's measurement step over a fixed set of particles (Manuelli & Tedrake, "Localizing
external contact using proprioceptive sensors: the contact particle filter", IROS 2016): candidate points
sampled by area on every touchable link's surface (a coarse set, ``spacing`` apart, and a fine one,
``fine_spacing`` apart, each fine point filed under its nearest coarse one), each with its 3 x n contact
Jacobian; the force that best explains the residual r under its covariance (weighted least squares, a
weak Gaussian prior on the force, pushing into the surface within the friction cone: ``joint_kernels``);
the likelihood ``exp(-chi2 / 2)`` of each, uniform prior by area, the posterior over the coarse points and
so over links; then the fine points of the best coarse cells, the answer the best of those.

Where r cannot tell (Pang, Umenberger & Tedrake, "Identifying external contacts from joint torque
measurements on serial robotic arms and its limitations", ICRA 2021: one external torque vector, several
contact points), the answer is flagged ``ambiguous`` and its candidates kept: when more than
``ambiguity_mass`` of the posterior lies farther than ``ambiguity_radius`` from the answer or on other
links, or when fewer joints move the chosen link than a point force has unknowns (3).

With a flange F/T sensor's compensated wrench w (sensor frame) the likelihood gains ``w``'s term: a
candidate beyond the sensor's site predicts ``(f, (p - s) x f)`` there, any other predicts nothing (the
flange sensor carries only the bodies beyond it), so both signals weigh every candidate in one fit.
"""
from __future__ import annotations

import math

import mujoco
import numpy as np

from ..geometry import inside
from ..model import ArmModel, descends
from ..model.sampling import _area, sample_local
from .joint_kernels import cone_edges, fit_candidates, link_jacobians, posterior, spread
from .solver import ContactEstimate

FORCE_PRIOR_N = 300.0
UNKNOWNS = 3  # a point force's components: fewer joints moving a link cannot fix them


class JointCandidates:
    """Points (link frame) and outward normals sampled by area on the touchable links' surfaces, about
    ``spacing`` apart, visible (not inside another primitive of the same link). ``link_of`` indexes ``links``."""

    def __init__(self, model: ArmModel, spacing: float, seed: int) -> None:
        rng = np.random.default_rng(seed)
        self.links = tuple(dict.fromkeys(s.link for s in model.surfaces))
        loc, nrm, link_of = [], [], []
        for li, link in enumerate(self.links):
            prims = [s for s in model.surfaces if s.link == link and s.kind != "plane"]
            for s in prims:
                count = max(2, int(math.ceil(_area(s.kind, s.size) / spacing**2)))
                p, n = sample_primitive(s.kind, np.asarray(s.size, dtype=float), count, rng)
                r, t = s.link_T_geom[:3, :3], s.link_T_geom[:3, 3]
                p_link, n_link = p @ r.T + t, n @ r.T
                keep = np.ones(count, dtype=bool)
                for o in prims:
                    if o is not s:
                        local = (p_link + 1e-6 * n_link - o.link_T_geom[:3, 3]) @ o.link_T_geom[:3, :3]
                        keep &= ~inside(o.kind, o.size, local)
                loc.append(p_link[keep])
                nrm.append(n_link[keep])
                link_of.append(np.full(int(keep.sum()), li, dtype=np.int64))
        self.loc = np.ascontiguousarray(np.concatenate(loc), dtype=float)
        self.nrm = np.ascontiguousarray(np.concatenate(nrm), dtype=float)
        self.link_of = np.concatenate(link_of)


def _units(rng: np.random.Generator, k: int) -> np.ndarray:
    v = rng.normal(size=(k, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def sample_primitive(kind: str, size: np.ndarray, k: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """k points uniform by area on a primitive (local frame) and their outward normals, (k, 3) each:
    :func:`ftc_hw.model.sampling.sample_local`'s law, drawn at once."""
    r, h = size[0], size[1]
    if kind == "sphere":
        n = _units(rng, k)
        return r * n, n
    if kind in ("capsule", "cylinder"):
        side = 2 * np.pi * r * 2 * h
        ends = 4 * np.pi * r * r if kind == "capsule" else 2 * np.pi * r * r
        on_side = rng.uniform(size=k) * (side + ends) < side
        phi = rng.uniform(0, 2 * np.pi, k)
        n = np.stack([np.cos(phi), np.sin(phi), np.zeros(k)], axis=1)
        p = np.stack([r * n[:, 0], r * n[:, 1], rng.uniform(-h, h, k)], axis=1)
        sign = np.where(rng.uniform(size=k) < 0.5, 1.0, -1.0)
        if kind == "capsule":
            cap = _units(rng, k)
            cap[:, 2] = sign * np.abs(cap[:, 2])
            cap_p = cap * r + np.outer(sign * h, [0.0, 0.0, 1.0])
        else:
            rho = r * np.sqrt(rng.uniform(size=k))
            cap_p = np.stack([rho * np.cos(phi), rho * np.sin(phi), sign * h], axis=1)
            cap = np.outer(sign, [0.0, 0.0, 1.0])
        return np.where(on_side[:, None], p, cap_p), np.where(on_side[:, None], n, cap)
    if kind == "box":
        areas = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]])
        axis = rng.choice(3, size=k, p=areas / areas.sum())
        p = rng.uniform(-1, 1, (k, 3)) * size[:3]
        sign = np.where(rng.uniform(size=k) < 0.5, 1.0, -1.0)
        p[np.arange(k), axis] = sign * size[axis]
        n = np.zeros((k, 3))
        n[np.arange(k), axis] = sign
        return p, n
    if kind == "ellipsoid":
        pts, nrm = [], []
        while sum(len(x) for x in pts) < k:
            p, n = zip(*(sample_local(kind, size, rng) for _ in range(k)), strict=True)
            pts.append(np.array(p))
            nrm.append(np.array(n))
        return np.concatenate(pts)[:k], np.concatenate(nrm)[:k]
    raise ValueError(f"cannot sample a {kind} surface")


class JointContactSolver:
    """Localization from r (n,) and its covariance (n, n); see the module's notes. Not thread-safe."""

    def __init__(self, model: ArmModel, *, spacing: float = 0.02, fine_spacing: float = 0.005,
                 friction_mu: float = 1.0, force_prior: float = FORCE_PRIOR_N, ambiguity_radius: float = 0.03,
                 ambiguity_mass: float = 0.1, refine_cells: int = 6, significant_sigma: float = 3.0,
                 seed: int = 0) -> None:
        self.model = model
        self.scene = model.scene
        m = model.model
        self.coarse = JointCandidates(model, spacing, seed)
        self.fine = JointCandidates(model, fine_spacing, seed + 1)
        self.touch = self.coarse.links
        self.links = tuple(m.body(b).name for b in range(m.nbody))
        self.body_ids = np.array([m.body(link).id for link in self.touch], dtype=np.int64)
        self.moves = np.array([model.moving_joints(link) for link in self.touch])  # (links, n): joint j moves link
        self.n_moving = self.moves.sum(axis=1)
        link_idx = [np.flatnonzero(self.coarse.link_of == li) for li in range(len(self.touch))]
        # per last significant joint j (index j + 1; 0: none), the coarse candidates on the links j moves
        self._admissible_by_joint = [np.concatenate(link_idx)] + [
            np.concatenate([link_idx[li] for li in np.flatnonzero(self.moves[:, j])] + [np.zeros(0, dtype=np.int64)])
            for j in range(model.n_joints)]
        self._cells = self._file_fine(spacing)
        self.spacing, self.fine_spacing = spacing, fine_spacing
        self.mu, self.ridge = float(friction_mu), 1.0 / force_prior**2
        self._edges = cone_edges()
        self.ambiguity_radius, self.ambiguity_mass = ambiguity_radius, ambiguity_mass
        self.refine_cells = refine_cells
        self.significant_sigma = significant_sigma
        self._data = mujoco.MjData(m)
        n_links = len(self.touch)
        self._poses = np.zeros((n_links, 3, 4))
        self._jv = np.zeros((n_links, 3, model.n_joints))
        self._jw = np.zeros((n_links, 3, model.n_joints))
        self._joint_tables()
        self._blocks = np.zeros((n_links, 3, 3, 3))
        self._bvec = np.zeros((n_links, 2, 3))
        self._fblocks, self._fb = np.zeros((3, 3, 3)), np.zeros((2, 3))
        sensor = self.scene.sensor
        self.flange_site = (m.site(sensor.site).id if sensor is not None and sensor.mount == "flange" else -1)
        site_body = int(m.site_bodyid[self.flange_site]) if self.flange_site >= 0 else -1
        self.flange_on = np.array([site_body >= 0 and descends(m, int(b), site_body) for b in self.body_ids])
        self._buf = {k: _buffers(len(t.link_of)) for k, t in (("coarse", self.coarse), ("fine", self.fine))}
        self._solved_q: np.ndarray | None = None

    def _file_fine(self, spacing: float) -> list[np.ndarray]:
        """Each coarse point's fine points: those nearer to it than to any other coarse point of the link."""
        c, f = self.coarse, self.fine
        owner = np.empty(len(f.link_of), dtype=np.int64)
        for li in range(len(self.touch)):
            ci, fi = np.flatnonzero(c.link_of == li), np.flatnonzero(f.link_of == li)
            d2 = ((f.loc[fi, None, :] - c.loc[None, ci, :]) ** 2).sum(-1)
            owner[fi] = ci[np.argmin(d2, axis=1)]
        order = np.argsort(owner, kind="stable")
        bounds = np.searchsorted(owner[order], np.arange(len(c.link_of) + 1))
        return [order[bounds[k]:bounds[k + 1]] for k in range(len(c.link_of))]

    # -- kinematics ---------------------------------------------------------------------------------------
    def _joint_tables(self) -> None:
        """What the links' Jacobians are made of: each model joint of the scene (its MuJoCo id, hinge or
        slide), which touchable link it moves, and its column of C (scene joint, ratio)."""
        m, jm = self.model.model, self.model.joints
        self._jids = np.ascontiguousarray(jm.jnt_ids, dtype=np.int64)
        self._hinge = np.ascontiguousarray(m.jnt_type[self._jids] == mujoco.mjtJoint.mjJNT_HINGE)
        self._moved = np.array([[descends(m, int(b), int(m.jnt_bodyid[j])) for j in self._jids]
                                for b in self.body_ids], dtype=np.bool_)  # (L, J)
        self._scene_joint = np.ascontiguousarray(jm.joint, dtype=np.int64)  # each model joint's scene joint
        self._ratio = np.ascontiguousarray(jm.ratio, dtype=float)

    def _pose(self, q: np.ndarray) -> None:
        """The links' poses and origin Jacobians at q: a hinge's column is ``axis`` (angular) and
        ``axis x (x - anchor)`` (linear), a slide's ``axis`` (linear), through the couplings' C."""
        model, m, d = self.model, self.model.model, self._data
        model.joints.set_qpos(q, d.qpos)
        mujoco.mj_kinematics(m, d)
        link_jacobians(d.xpos, d.xmat, self.body_ids, d.xaxis, d.xanchor, self._jids, self._hinge, self._moved,
                       self._scene_joint, self._ratio, self._poses, self._jv, self._jw)
        self._solved_q = q.copy()

    def body_poses(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Every body's position (nbody, 3) and quaternion (nbody, 4) at q (MuJoCo's arrays)."""
        q = np.asarray(q, dtype=float)
        if self._solved_q is None or not np.array_equal(q, self._solved_q):
            self._pose(q)
        return self._data.xpos, self._data.xquat

    def solved_body_poses(self) -> tuple[np.ndarray, np.ndarray] | None:
        return None if self._solved_q is None else (self._data.xpos, self._data.xquat)

    # -- the fit --------------------------------------------------------------------------------------------
    def _joint_blocks(self, r: np.ndarray, info: np.ndarray) -> float:
        """Every link's blocks at once: Jv W Jv^T, Jv W Jw^T, Jw W Jw^T and Jv W r, Jw W r."""
        vw, ww = self._jv @ info, self._jw @ info  # (L, 3, n); W is symmetric
        jv_t, jw_t = self._jv.transpose(0, 2, 1), self._jw.transpose(0, 2, 1)
        np.matmul(vw, jv_t, out=self._blocks[:, 0])
        np.matmul(vw, jw_t, out=self._blocks[:, 1])
        np.matmul(ww, jw_t, out=self._blocks[:, 2])
        np.matmul(vw, r, out=self._bvec[:, 0])
        np.matmul(ww, r, out=self._bvec[:, 1])
        return float(r @ info @ r)

    def _flange_blocks(self, wrench: np.ndarray, wrench_cov: np.ndarray) -> tuple[float, np.ndarray]:
        """The flange wrench's blocks in the base frame about the sensor origin; (w^T W w, origin)."""
        d = self._data
        rot = d.site_xmat[self.flange_site].reshape(3, 3)
        big = np.zeros((6, 6))
        big[:3, :3] = big[3:, 3:] = rot
        w_base = big @ wrench  # the contact's wrench on the arm, base axes, about the sensor origin
        info = big @ np.linalg.inv(wrench_cov) @ big.T
        u = info @ w_base
        self._fblocks[0], self._fblocks[1], self._fblocks[2] = info[:3, :3], info[:3, 3:], info[3:, 3:]
        self._fb[0], self._fb[1] = u[:3], u[3:]
        return float(w_base @ u), d.site_xpos[self.flange_site].copy()

    def _fit(self, which: str, idx: np.ndarray, const: float, origin: np.ndarray, use_flange: bool):
        table = self.coarse if which == "coarse" else self.fine
        buf = self._buf[which]
        k = len(idx)
        out = {name: arr[:k] for name, arr in buf.items()}
        fit_candidates(table.loc, table.nrm, table.link_of, self._poses, self._blocks, self._bvec, self._fblocks,
                       self._fb, self.flange_on & use_flange, origin, const, self.ridge, self.mu, self._edges, idx,
                       out["chi2"], out["force"], out["point"], out["normal"], out["info"])
        return out

    def solve(self, r, cov, q, *, wrench=None, wrench_cov=None) -> ContactEstimate:
        """The contact from the residual r (n,) N m, its covariance (n, n) and q (n,) rad; ``wrench`` (6,):
        a flange sensor's compensated contact wrench on the arm (sensor frame, about its origin), with
        ``wrench_cov`` (6, 6)."""
        r, q = np.asarray(r, dtype=float), np.asarray(q, dtype=float)
        cov = np.asarray(cov, dtype=float)
        if not (np.isfinite(r).all() and np.isfinite(q).all() and np.isfinite(cov).all()):
            return invalid_estimate()
        self._pose(q)
        try:
            info = np.linalg.inv(cov)
        except np.linalg.LinAlgError:
            return invalid_estimate()
        const = self._joint_blocks(r, info)
        origin = np.zeros(3)
        use_flange = wrench is not None and self.flange_site >= 0
        if use_flange:
            c2, origin = self._flange_blocks(np.asarray(wrench, dtype=float), np.asarray(wrench_cov, dtype=float))
            const += c2
        idx = self._admissible(r, cov, use_flange)
        coarse = self._fit("coarse", idx, const, origin, use_flange)
        post = np.empty(coarse["chi2"].size)
        posterior(coarse["chi2"], post)
        cells = idx[np.argsort(-post)[:self.refine_cells]]
        fine_idx = np.concatenate([self._cells[c] for c in cells] + [np.zeros(0, dtype=np.int64)])
        fine = self._fit("fine", fine_idx, const, origin, use_flange) if fine_idx.size else None
        return self._estimate(idx, coarse, post, fine, fine_idx)

    def last_significant(self, r: np.ndarray, cov: np.ndarray) -> int:
        """The most distal joint whose residual exceeds ``significant_sigma`` standard deviations, or -1:
        the contact is on a link that joint moves (a joint beyond it would feel it too)."""
        big = np.flatnonzero(np.abs(r) > self.significant_sigma * np.sqrt(np.maximum(np.diag(cov), 0.0)))
        return int(big[-1]) if big.size else -1

    def _admissible(self, r: np.ndarray, cov: np.ndarray, use_flange: bool) -> np.ndarray:
        """The coarse candidates on the links the last significant joint moves (every link when none is,
        or when a flange wrench speaks too): the isolation bound of Haddadin et al. (2017) sec. V."""
        idx = self._admissible_by_joint[0 if use_flange else self.last_significant(r, cov) + 1]
        return idx if idx.size else self._admissible_by_joint[0]  # a joint that moves no touchable link

    def _estimate(self, idx, coarse, post, fine, fine_idx) -> ContactEstimate:
        """The answer (the best fine point, else coarse), its covariance, flags and candidates."""
        if fine is not None and fine["chi2"].size:
            best = int(np.argmin(fine["chi2"]))
            src, li = fine, int(self.fine.link_of[fine_idx[best]])
        else:
            best = int(np.argmax(post))
            src, li = coarse, int(self.coarse.link_of[idx[best]])
        point, force, normal = src["point"][best].copy(), src["force"][best].copy(), src["normal"][best].copy()
        chi2 = float(src["chi2"][best])
        out_cov = np.zeros((6, 6))
        point_cov = np.zeros((3, 3))  # the posterior's spread about the answer: coarse (global), fine (local)
        link_p, best_k = np.zeros(len(self.touch)), np.zeros(len(self.touch), dtype=np.int64)
        r2 = self.ambiguity_radius**2
        far = spread(post, coarse["point"], point, r2, self.coarse.link_of[idx], li, point_cov, link_p, best_k)
        if src is fine:
            fpost = np.empty(fine["chi2"].size)
            posterior(fine["chi2"], fpost)
            spread(fpost, fine["point"], point, r2, self.fine.link_of[fine_idx], li, point_cov, np.zeros_like(link_p),
                   np.zeros_like(best_k))
        point_cov[np.diag_indices(3)] += self.fine_spacing**2 / 12.0
        out_cov[:3, :3] = point_cov
        info = src["info"][best]
        ev = np.linalg.eigvalsh(info)
        out_cov[3:, 3:] = np.linalg.inv(info) if ev[0] > 0 else np.inf
        ambiguous = (far > self.ambiguity_mass or link_p[li] < 1.0 - self.ambiguity_mass
                     or self.n_moving[li] < UNKNOWNS)
        flags = ("ambiguous",) if ambiguous else ()
        names, rows = self._candidates(coarse, post, link_p, best_k, li, point, force, chi2)
        return ContactEstimate(
            contact=True, link=self.touch[li], point=point, force=force, normal=normal,
            residual=math.sqrt(max(chi2, 0.0)), chi2=chi2, cov=out_cov,
            conditioning=float(ev[-1] / ev[0]) if ev[0] > 0 else math.inf, flags=flags,
            candidate_links=names, candidate_data=rows)

    def _candidates(self, coarse, post, link_p, best_k, li, point, force, chi2):
        """The answer, then each other link's best coarse point, and on the answer's own link its best point
        farther than the ambiguity radius, by posterior: rows point, force, log posterior, chi2."""
        order = [lj for lj in np.argsort(-link_p) if best_k[lj] >= 0 and link_p[lj] > 1e-12]
        rows = np.empty((1 + len(order), 8))
        rows[0, :3], rows[0, 3:6], rows[0, 6], rows[0, 7] = point, force, math.log(max(link_p[li], 1e-300)), chi2
        for i, lj in enumerate(order, start=1):
            k = best_k[lj]
            share = post[k] if lj == li else link_p[lj]
            rows[i, :3], rows[i, 3:6] = coarse["point"][k], coarse["force"][k]
            rows[i, 6], rows[i, 7] = math.log(max(share, 1e-300)), coarse["chi2"][k]
        return (self.touch[li], *(self.touch[lj] for lj in order)), rows

    def link_probabilities(self, estimate: ContactEstimate) -> dict[str, float]:
        """Per candidate link, its posterior probability (from ``estimate.candidate_data``)."""
        out: dict[str, float] = {}
        for name, row in zip(estimate.candidate_links, estimate.candidate_data, strict=True):
            out.setdefault(name, math.exp(row[6]))
        return out


def _buffers(n: int) -> dict[str, np.ndarray]:
    return {"chi2": np.empty(n), "force": np.empty((n, 3)), "point": np.empty((n, 3)), "normal": np.empty((n, 3)),
            "info": np.empty((n, 3, 3))}


def invalid_estimate() -> ContactEstimate:
    nan3 = np.full(3, np.nan)
    return ContactEstimate(contact=False, link=None, point=nan3, force=nan3.copy(), normal=nan3.copy(),
                           residual=math.nan, chi2=math.nan, cov=np.full((6, 6), np.nan), conditioning=math.inf,
                           flags=("invalid_input",), candidate_links=(), candidate_data=np.zeros((0, 8)))
