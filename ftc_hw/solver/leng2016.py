"""The reference paper's method as a baseline ("leng2016").

Leng, Chen, He, Zhang, Zhang, "Collision Sensing Using Force/Torque Sensor", Journal of Sensors 2016
(shared/reference/collision-sensing-paper.txt), section 5, on our scene model:

* Surfaces (section 2.2, eqs. 9-11): every touchable primitive is a union of bounded patches of the
  unified quadric ``|A (x - x0)|^2 = 1`` (eq. 9, A = diag of inverse semi-axes, 0 for an infinite
  axis, eq. 10) or of its degenerate case, the plane. A cylinder is its side (``k = (1/r, 1/r, 0)``,
  bounded to ``|z| <= h`` as eqs. 29-31 bound the link rods) and, optionally, its flat caps (bounded
  planes); a capsule is its side and two bounded hemispheres (the paper's "top of link 3", eq. 32);
  a sphere or ellipsoid is one quadric; a box is six bounded planes; a plane is a plane. Normals are
  the gradient of the patch (eq. 11). A point inside another primitive is not on the arm's outline
  (the geometric constraint, eq. 27, is on the whole outline, which is what the paper's bounds encode).
* Force constraint (5.1, eqs. 25-26): ``f = p`` and ``tau = c x p`` with (f, tau) the external
  contact wrench in the base frame about the base origin. Noise-free (``rank(M) = 5``: the moment
  is perpendicular to the force within rounding) the contact lies on the force line; the exact
  solutions are the line's crossings with the patches (eq. 27), ``p = f``.
* Normal-vector constraint (5.3, eq. 28): ``p . n < 0`` (push only; the paper has no pulls, so the
  scene's ``pulls`` setting is ignored).
* Current-mutation constraint (5.4): with per-joint external torques, the touched link is the one
  whose most distal joint is the most distal joint with a torque above its threshold; candidates on
  any other link are rejected. Without any torque above threshold the constraint says nothing.
* Compatibility solution (5.5), when noise makes the moment not perpendicular to the force: for each
  primitive near the force line, each of the 6 subsystems "5 of the 6 wrench equations + the surface
  equation" (6 equations, 6 unknowns c, p) is solved by Newton's method on each patch; converged
  solutions inside the patch bounds, on the outline and obeying eq. 28 are kept; outliers
  ("singular solutions") are removed by the deviation of their positions and normals; the rest are
  averaged, the average is projected on the primitive's outline (closest point), and the force is
  taken from eq. 25 (``p = f``). Candidates from all primitives are then ranked by their wrench
  residual (the moment mismatch ``c x f - tau``, normalised by the sensor noise).

The paper gives no uncertainty: ``cov`` is all zeros and ``conditioning`` is ``inf``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..geometry import inside, quadric_closest, quadric_crossings
from ..model import ArmModel
from ..model.arm import GEOM_KINDS, SURFACE_GROUP
from ..scene import Scene
from .protocol import BodyPoses
from .solver import FLAG_NAMES, BatchEstimate, ContactEstimate, ContactSolver, flag_names

FLAG_BITS = {name: bit for bit, name in FLAG_NAMES.items()}
CHI2_3DOF_999 = 16.266236196238129  # chi-square quantile, 3 degrees of freedom, p = 0.999
MAD_TO_SIGMA = 1.482602218505602  # 1 / Phi^-1(3/4)
_ROWS = np.array([[i for i in range(6) if i != k] + [6] for k in range(6)])  # subsystem k drops row k


# -- patches: the unified quadric (eq. 9) and its plane limit, with the paper's bounds ------------------
@dataclass(frozen=True)
class _Quadric:
    """``S(x) = |k * (x - centre)|^2 - 1 = 0`` (eq. 9 with A = diag(k), eq. 10) in the geom frame,
    bounded to ``zlo <= x_z <= zhi`` (eqs. 29-32)."""

    k: np.ndarray  # inverse semi-axes, 0 = infinite axis
    centre: np.ndarray
    zlo: float
    zhi: float
    scale: float  # m, the largest finite semi-axis

    def g(self, x: np.ndarray) -> np.ndarray:
        y = self.k * (x - self.centre)
        return (y * y).sum(-1) - 1.0

    def grad(self, x: np.ndarray) -> np.ndarray:
        """``grad S = 2 A^2 (x - centre)`` (eq. 11 before normalisation)."""
        return 2.0 * self.k * self.k * (x - self.centre)

    def normal(self, x: np.ndarray) -> np.ndarray:
        return _unit(self.grad(x))

    def in_bounds(self, x: np.ndarray, tol: float) -> bool:
        return self.zlo - tol <= x[2] <= self.zhi + tol

    def crossings(self, o: np.ndarray, d: np.ndarray, tol: float) -> list[np.ndarray]:
        """Crossings of the line ``o + s d`` (unit d) with the bounded patch."""
        v = o - self.centre
        count, s = quadric_crossings(self.k, v, d)
        points = [v + s[0, j] * d + self.centre for j in range(count[0])]
        return [x for x in points if self.in_bounds(x, tol)]

    def project(self, x: np.ndarray) -> np.ndarray:
        """The patch point nearest to ``x`` (bounds included)."""
        v = x - self.centre
        if self.k[2] == 0.0:  # side of a cylinder or capsule: k = (1/r, 1/r, 0)
            r = 1.0 / self.k[0]
            out = self.centre + r * _radial(v)
            out[2] = min(max(x[2], self.zlo), self.zhi)
            return out
        if self.k[0] == self.k[1] == self.k[2]:  # sphere or hemisphere
            r = 1.0 / self.k[0]
            nv = np.linalg.norm(v)
            out = self.centre + r * (v / nv if nv > 0 else np.array([0.0, 0.0, 1.0]))
            if self.zlo <= out[2] <= self.zhi:
                return out
            zb = min(max(out[2], self.zlo), self.zhi)  # nearest point on the bounding rim
            rho = math.sqrt(max(r * r - (zb - self.centre[2]) ** 2, 0.0))
            out = self.centre + rho * _radial(v)
            out[2] = zb
            return out
        return quadric_closest(self.k, v)[0][0] + self.centre  # an ellipsoid: unbounded


@dataclass(frozen=True)
class _Plane:
    """The plane limit of eq. 9 (section 2.2): ``n . x = h`` in the geom frame (n = +-e_axis),
    bounded to a disk of radius ``disk`` (cylinder caps) or to ``|x_j| <= half_j`` (box faces)."""

    n: np.ndarray
    h: float
    axis: int
    disk: float  # 0: no disk bound
    half: np.ndarray  # inf: unbounded along that axis
    scale: float

    def g(self, x: np.ndarray) -> np.ndarray:
        return ((x * self.n).sum(-1) - self.h) / self.scale

    def grad(self, x: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.n / self.scale, np.shape(x)).copy()

    def normal(self, x: np.ndarray) -> np.ndarray:
        return self.n.copy()

    def in_bounds(self, x: np.ndarray, tol: float) -> bool:
        if self.disk > 0 and math.hypot(x[0], x[1]) > self.disk + tol:
            return False
        return bool(np.all(np.abs(x) <= self.half + tol))

    def crossings(self, o: np.ndarray, d: np.ndarray, tol: float) -> list[np.ndarray]:
        dn = float(d @ self.n)
        if abs(dn) < 1e-15:
            return []
        x = o + ((self.h - float(o @ self.n)) / dn) * d
        x[self.axis] = self.n[self.axis] * self.h
        return [x] if np.all(np.isfinite(x)) and self.in_bounds(x, tol) else []

    def project(self, x: np.ndarray) -> np.ndarray:
        out = np.array(x, dtype=float)
        out[self.axis] = self.n[self.axis] * self.h
        if self.disk > 0:
            rho = math.hypot(out[0], out[1])
            if rho > self.disk:
                out[:2] *= self.disk / rho
        return np.clip(out, -self.half, self.half)


_Patch = _Quadric | _Plane


def _patches(kind: str, size: np.ndarray, flat_caps: bool) -> tuple[_Patch, ...]:
    """A primitive (MuJoCo size conventions) as the paper's bounded surfaces."""
    inf = math.inf
    if kind == "sphere":
        r = float(size[0])
        return (_Quadric(np.full(3, 1.0 / r), np.zeros(3), -inf, inf, r),)
    if kind in ("capsule", "cylinder"):
        r, h = float(size[0]), float(size[1])
        out: list[_Patch] = [_Quadric(np.array([1.0 / r, 1.0 / r, 0.0]), np.zeros(3), -h, h, r)]
        if kind == "capsule":  # hemispheres, bounded like eq. 32
            out += [_Quadric(np.full(3, 1.0 / r), np.array([0.0, 0.0, h]), h, inf, r),
                    _Quadric(np.full(3, 1.0 / r), np.array([0.0, 0.0, -h]), -inf, -h, r)]
        elif flat_caps:
            out += [_Plane(np.array([0.0, 0.0, s]), h, 2, r, np.full(3, inf), max(r, h)) for s in (1.0, -1.0)]
        return tuple(out)
    if kind == "ellipsoid":
        semi = np.asarray(size[:3], dtype=float)
        return (_Quadric(1.0 / semi, np.zeros(3), -inf, inf, float(semi.max())),)
    if kind == "box":
        hs = np.asarray(size[:3], dtype=float)
        out = []
        for a in range(3):
            half = hs.copy()
            half[a] = inf
            for s in (1.0, -1.0):
                n = np.zeros(3)
                n[a] = s
                out.append(_Plane(n, float(hs[a]), a, 0.0, half, float(hs.max())))
        return tuple(out)
    return (_Plane(np.array([0.0, 0.0, 1.0]), 0.0, 2, 0.0, np.full(3, inf), 1.0),)  # plane


def _bound(kind: str, size: np.ndarray) -> float:
    if kind == "sphere":
        return float(size[0])
    if kind == "capsule":
        return float(size[0] + size[1])
    if kind == "cylinder":
        return float(math.hypot(size[0], size[1]))
    if kind == "ellipsoid":
        return float(np.max(size[:3]))
    if kind == "box":
        return float(np.linalg.norm(size[:3]))
    return math.inf


@dataclass(frozen=True)
class _Prim:
    geom: int
    body: int
    link: str
    kind: str
    size: np.ndarray
    touch: bool
    patches: tuple[_Patch, ...]
    scale: float
    bound: float  # m, radius of a sphere about the geom origin that holds the primitive (inf: plane)


class _Frame(NamedTuple):
    """One frame's data for the candidate searches (base frame)."""

    f: np.ndarray  # the force (eq. 25: p = f)
    tau: np.ndarray  # the moment about the base origin
    u: np.ndarray  # the force's direction
    r0: np.ndarray  # the force line's point nearest the origin
    poses: dict[int, tuple[np.ndarray, np.ndarray]]  # geom -> (rotation, centre)
    sigma: np.ndarray  # covariance of (f, tau)


@dataclass
class _Cand:
    prim: _Prim
    point: np.ndarray
    force: np.ndarray
    normal: np.ndarray
    chi2: float
    s: float  # position along the force line (m)


class Leng2016Solver:
    """The paper's section-5 method on a scene; ``solve``/``solve_batch`` like :class:`ContactSolver`.

    Not thread-safe (it owns the model's MjData): one per thread.

    ``flat_caps``: model cylinder caps as bounded planes (the paper's unified model has planes; its
    own arm has contacts on the rods only, eqs. 29-32). ``rank_tol``: relative size of the moment
    along the force line below which the wrench counts as consistent (rank(M) = 5, section 5.1).
    ``mutation_sigma``, ``mutation_floor``: a joint's current "mutates" (5.4) when its external
    torque exceeds ``max(mutation_sigma * torque_constant * current_noise_std, mutation_floor)`` N m.
    ``ambiguity_dchi2``: candidates whose residual chi-square is within this of the best one are
    not told apart by the data (``ambiguous``).
    """

    def __init__(self, scene: Scene | ArmModel, *, flat_caps: bool = True, rank_tol: float = 1e-9,
                 low_force_sigma: float = 5.0, mutation_sigma: float = 3.0, mutation_floor: float = 0.05,
                 ambiguity_dchi2: float = CHI2_3DOF_999, outlier_k: float = 3.0, max_iter: int = 30,
                 max_halvings: int = 8, newton_tol: float = 1e-12, bound_tol: float = 1e-9,
                 hide_tol: float = 1e-8) -> None:
        self._ours = ContactSolver(scene, low_force_sigma=low_force_sigma)  # frames, links, noise floor
        self.model = self._ours.model
        self.scene = self.model.scene
        self.links = self._ours.links
        self.low_force = self._ours.low_force
        self.rank_tol = float(rank_tol)
        self.ambiguity_dchi2 = float(ambiguity_dchi2)
        self.outlier_k = float(outlier_k)
        self.max_iter = int(max_iter)
        self.max_halvings = int(max_halvings)
        self.newton_tol = float(newton_tol)
        self.bound_tol = float(bound_tol)
        self.hide_tol = float(hide_tol)
        m = self.model.model
        touch = {t.link for t in self.scene.touchable}
        prims = []
        for g in range(m.ngeom):
            kind = GEOM_KINDS.get(int(m.geom_type[g]))
            if m.geom_group[g] != SURFACE_GROUP or kind is None:
                continue
            body = int(m.geom_bodyid[g])
            size = m.geom_size[g].copy()
            patches = _patches(kind, size, flat_caps)
            prims.append(_Prim(g, body, m.body(body).name, kind, size, m.body(body).name in touch, patches,
                               max(p.scale for p in patches), _bound(kind, size)))
        self._prims = tuple(prims)
        self.extent = max(float(m.stat.extent), 0.1)
        # 5.4: the most distal (scene) joint moving each body (depth = number of joints moving its body)
        jm = self.model.joints
        moves = np.array([self.model.moving_joints(b) for b in range(m.nbody)])
        depth = np.array([moves[m.jnt_bodyid[j]].sum() for j in jm.jnt_ids[jm.lead]])
        self._deepest = np.array([int(np.argmax(np.where(moves[b], depth, -1))) if moves[b].any() else -1
                                  for b in range(m.nbody)])
        self._joint_depth = depth
        robot = self.scene.robot
        self.mutation_threshold = np.maximum(mutation_sigma * np.abs(robot.torque_constant)
                                             * robot.current_noise_std, mutation_floor)
        self._sigma0 = self._sigma(np.array(self.scene.robot.home))

    # -- noise --------------------------------------------------------------------------------------------
    def _sigma(self, q: np.ndarray, extra: np.ndarray | None = None) -> np.ndarray:
        """Covariance of the external wrench (base frame, about the base origin) from the sensor noise
        (plus ``extra``, sensor frame)."""
        a = np.column_stack([self._ours.external_wrench_base(e, q) for e in np.eye(6)])
        cov = self.scene.sensor.noise_cov if extra is None else self.scene.sensor.noise_cov + extra
        return a @ cov @ a.T

    def _chi2(self, c: np.ndarray, f: np.ndarray, tau: np.ndarray, sigma: np.ndarray) -> float:
        """Moment mismatch ``c x f - tau`` (eq. 25 with p = f) normalised by its noise covariance."""
        r = np.cross(c, f) - tau
        j = np.hstack([_skew(c), -np.eye(3)])
        cov = j @ sigma @ j.T
        cov += (1e-12 * np.trace(cov) + 1e-300) * np.eye(3)
        return float(r @ np.linalg.solve(cov, r))

    # -- single frame -------------------------------------------------------------------------------------
    def solve(self, wrench_sensor, q, tau_ext=None, saturated: bool = False, tau_std=None,
              extra_cov=None) -> ContactEstimate:
        """Estimate the contact from the compensated wrench (sensor frame, the scene's sign convention:
        the external contact wrench only) at joint angles q (rad), by the paper's section 5.

        ``tau_ext``: optional per-joint external torques (N m, the scene's joint order); they drive the
        current-mutation constraint (5.4), whose thresholds are fixed (``tau_std`` is not used).
        ``extra_cov``: the compensation's own uncertainty (6x6, sensor frame), added to the sensor
        noise that normalises the ranking residual.
        """
        bits = FLAG_BITS["saturated"] if saturated else 0
        w = np.asarray(wrench_sensor, dtype=np.float64).reshape(6)
        q = np.asarray(q, dtype=np.float64).reshape(self.model.n_joints)
        tau_arr = None if tau_ext is None else np.asarray(tau_ext, dtype=float).reshape(self.model.n_joints)
        extra = None if extra_cov is None else np.asarray(extra_cov, dtype=np.float64).reshape(6, 6)
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(q)) and (tau_arr is None or np.all(np.isfinite(tau_arr)))
                and (extra is None or np.all(np.isfinite(extra)))):
            return _empty(bits | FLAG_BITS["invalid_input"], 0.0)
        ext = self._ours.external_wrench_base(w, q)  # (f, tau) = (p, c x p), eq. 25
        sigma = self._sigma(q, extra) if (self._ours.sensor_moves or extra is not None) else self._sigma0
        if not np.all(np.isfinite(ext)):
            return _empty(bits | FLAG_BITS["invalid_input"], 0.0)
        poses = self._poses(q)
        f, tau = ext[:3], ext[3:]
        fn = float(np.linalg.norm(f))
        if fn == 0.0:
            return _empty(bits | FLAG_BITS["low_force"] | FLAG_BITS["no_candidate"], 0.0)
        if fn < self.low_force:
            bits |= FLAG_BITS["low_force"]
        cands, m_par = self._search(_Frame(f, tau, f / fn, np.cross(f, tau) / (fn * fn), poses, sigma))
        if tau_arr is not None:
            allowed = self._mutation_links(tau_arr)
            if allowed is not None:
                cands = [c for c in cands if c.prim.body in allowed]
        if not cands:
            return _empty(bits | FLAG_BITS["no_candidate"], m_par)
        return self._estimate(cands, bits, m_par)

    def _poses(self, q: np.ndarray) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """Every primitive's (rotation, centre) at q."""
        self.model.kinematics(q)
        d = self.model.data
        return {p.geom: (d.geom_xmat[p.geom].reshape(3, 3).copy(), d.geom_xpos[p.geom].copy()) for p in self._prims}

    def _search(self, fr: _Frame) -> tuple[list[_Cand], float]:
        """The candidates, one per contact, and the moment along the force line (N m)."""
        fn = float(np.linalg.norm(fr.f))
        m_par = float(fr.tau @ fr.u)  # moment along the force line: 0 for a consistent wrench
        if abs(m_par) <= self.rank_tol * (float(np.linalg.norm(fr.tau)) + fn * self.extent):
            # rank(M) = 5: exact crossings
            return _dedup(self._exact(fr), 1e-9 * (1.0 + float(np.linalg.norm(fr.r0)))), m_par
        # rank(M) = 6: compatibility solution (5.5)
        sig_line = self._line_sigma(fn, fr.r0, fr.sigma)
        return _dedup(self._compatible(fr, 0.005 + 5.0 * sig_line), max(1e-6, 10.0 * sig_line)), m_par

    def _estimate(self, cands: list[_Cand], bits: int, m_par: float) -> ContactEstimate:
        """Candidates ranked by their residual (the first along the force line on a tie), the best
        reported."""
        cands.sort(key=lambda c: (c.chi2 + 1e-12 * c.s))
        if len(cands) > 1 and cands[1].chi2 - cands[0].chi2 < self.ambiguity_dchi2:
            bits |= FLAG_BITS["ambiguous"]
        best = cands[0]
        data = np.array([[*c.point, *c.force, -0.5 * c.chi2, c.chi2] for c in cands])
        return ContactEstimate(not bits & FLAG_BITS["low_force"], best.prim.link, best.point.copy(),
                               best.force.copy(), best.normal.copy(), m_par, best.chi2, np.zeros((6, 6)), math.inf,
                               flag_names(bits), tuple(c.prim.link for c in cands), data)

    # -- 5.1-5.3 noise-free: the force line crossed with the outline --------------------------------------
    def _exact(self, fr: _Frame) -> list[_Cand]:
        out = []
        for prim, o_loc, d_loc in self._touchable(fr):
            for patch in prim.patches:
                for x_loc in patch.crossings(o_loc, d_loc, self.bound_tol):
                    cand = self._candidate(prim, patch, x_loc, fr)
                    if cand is not None:
                        out.append(cand)
        return out

    def _touchable(self, fr: _Frame):
        """Every touchable primitive with the force line in its frame (o_loc, d_loc)."""
        for prim in self._prims:
            if prim.touch:
                rot, org = fr.poses[prim.geom]
                yield prim, rot.T @ (fr.r0 - org), rot.T @ fr.u

    def _candidate(self, prim: _Prim, patch: _Patch, x_loc: np.ndarray, fr: _Frame) -> _Cand | None:
        """The contact at a patch point (geom frame) with p = f (eq. 25), if it pushes (eq. 28) and lies
        on the outline (eq. 27)."""
        rot, org = fr.poses[prim.geom]
        n = rot @ patch.normal(x_loc)
        if not float(fr.f @ n) < 0.0:
            return None
        x = rot @ x_loc + org
        if self._hidden(x[None], n[None], prim, fr.poses)[0]:
            return None
        return _Cand(prim, x, fr.f.copy(), n, self._chi2(x, fr.f, fr.tau, fr.sigma), float((x - fr.r0) @ fr.u))

    # -- 5.5 compatibility solution -----------------------------------------------------------------------
    def _line_sigma(self, fn: float, r0: np.ndarray, sigma: np.ndarray) -> float:
        """Rough standard deviation (m) of the force line's position from the sensor noise."""
        sf = math.sqrt(max(np.linalg.eigvalsh(sigma[:3, :3]).max(), 0.0))
        st = math.sqrt(max(np.linalg.eigvalsh(sigma[3:, 3:]).max(), 0.0))
        return (st + 2.0 * sf * (float(np.linalg.norm(r0)) + self.extent)) / fn

    def _compatible(self, fr: _Frame, margin: float) -> list[_Cand]:
        out = []
        for prim, o_loc, d_loc in self._touchable(fr):
            if float(np.linalg.norm(o_loc - (o_loc @ d_loc) * d_loc)) > prim.bound + margin:
                continue  # the line passes far from this primitive
            pts, nrms = self._solutions(prim, o_loc, d_loc, fr, margin)
            if not pts:
                continue
            pts_a, nrm_a = np.array(pts), np.array(nrms)
            keep = ~self._hidden(pts_a, nrm_a, prim, fr.poses)  # eq. 27: on the outline
            pts_a, nrm_a = pts_a[keep], nrm_a[keep]
            if len(pts_a) == 0:
                continue
            keep = _inliers(pts_a, nrm_a, self.outlier_k)  # "remove singular solutions"
            # the closest point of the outline (this primitive's patches) to the average
            rot, org = fr.poses[prim.geom]
            m_loc = rot.T @ (pts_a[keep].mean(axis=0) - org)
            best, best_d = None, math.inf
            for patch in prim.patches:
                x_loc = patch.project(m_loc)
                dist = float(np.linalg.norm(x_loc - m_loc))
                if dist < best_d:
                    best, best_d = (patch, x_loc), dist
            cand = self._candidate(prim, *best, fr)
            if cand is not None:
                out.append(cand)
        return out

    def _solutions(self, prim: _Prim, o_loc: np.ndarray, d_loc: np.ndarray, fr: _Frame,
                   margin: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """The converged subsystem solutions (points, normals; base frame) on each patch of ``prim``
        within the patch's bounds (eqs. 29-32) that push (eq. 28)."""
        rot, org = fr.poses[prim.geom]
        pts, nrms = [], []
        for patch in prim.patches:
            # start: the patch's push crossing of the least-squares line, else its point nearest the line
            start = None
            for x_loc in patch.crossings(o_loc, d_loc, self.bound_tol):
                if float(d_loc @ patch.normal(x_loc)) < 0.0:
                    start = x_loc
                    break
            if start is None:
                start, dist = _nearest_to_line(patch, o_loc, d_loc)
                if dist > margin:
                    continue
            cs, ps, ok = self._newton(patch, rot, org, fr.f, fr.tau, rot @ start + org)
            for k in np.flatnonzero(ok):
                x_loc = rot.T @ (cs[k] - org)
                if not patch.in_bounds(x_loc, self.bound_tol):
                    continue
                n = rot @ patch.normal(x_loc)
                if not float(ps[k] @ n) < 0.0:
                    continue
                pts.append(cs[k])
                nrms.append(n)
        return pts, nrms

    def _newton(self, patch: _Patch, rot: np.ndarray, org: np.ndarray, f: np.ndarray, tau: np.ndarray,
                c0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The 6 subsystems of 5.5 at once: subsystem k keeps the wrench equations of eq. 25 except row k,
        plus the surface equation (eq. 9) of ``patch``; unknowns (c, p). Newton's method with the
        analytic Jacobian and a backtracking line search, from (c0, f). A subsystem stops (not
        converged) when its Jacobian is singular or no step of at least 2^-max_halvings of Newton's
        decreases its residual (typically: its solution line misses the patch, no root exists).

        Returns c (6, 3), p (6, 3) and which subsystems converged to an isolated root.
        """
        fn = float(np.linalg.norm(f))
        lever = float(np.linalg.norm(c0)) + patch.scale
        row_scale = np.concatenate([np.full(3, 1.0 / fn), np.full(3, 1.0 / (fn * lever)), [1.0]])
        col_scale = np.concatenate([np.full(3, lever), np.full(3, fn)])
        idx = np.arange(6)[:, None]

        def residual(x: np.ndarray) -> np.ndarray:
            c, p = x[:, :3], x[:, 3:]
            e = np.empty((x.shape[0], 7))
            e[:, :3] = p - f
            e[:, 3:6] = _cross(c, p) - tau
            e[:, 6] = patch.g((c - org) @ rot)
            return e * row_scale

        x = np.tile(np.concatenate([c0, f]), (6, 1))
        e = residual(x)[idx, _ROWS]
        norm = np.abs(e).max(axis=1)
        active = np.ones(6, dtype=bool)
        conv = norm <= self.newton_tol
        active &= ~conv
        for _ in range(self.max_iter):
            if not active.any():
                break
            a = np.flatnonzero(active)
            c, p = x[a, :3], x[a, 3:]
            jac = np.zeros((len(a), 7, 6))
            jac[:, 0:3, 3:6] = np.eye(3)
            jac[:, 3:6, 0:3] = -_skew_many(p)  # d(c x p)/dc
            jac[:, 3:6, 3:6] = _skew_many(c)  # d(c x p)/dp
            jac[:, 6, 0:3] = patch.grad((c - org) @ rot) @ rot.T
            jac = jac * row_scale[:, None] * col_scale
            js = jac[np.arange(len(a))[:, None], _ROWS[a]]
            uu, sv, vt = np.linalg.svd(js)
            singular = ~(sv[:, -1] > 1e-12 * sv[:, 0])
            y = np.einsum("nji,nj->ni", uu, e[a]) / np.where(singular[:, None], 1.0, sv)
            step = -np.einsum("nji,nj->ni", vt, y)  # -(J^-1 e) in scaled variables
            step *= col_scale
            dc = np.linalg.norm(step[:, :3], axis=1)
            cap = np.minimum(1.0, lever / np.maximum(dc, 1e-300))
            step *= cap[:, None]
            alpha = np.ones(len(a))
            new_x, new_e, new_n = x[a].copy(), e[a].copy(), norm[a].copy()
            pending = ~singular
            for _ls in range(self.max_halvings + 1):
                if not pending.any():
                    break
                pi = np.flatnonzero(pending)
                trial = x[a[pi]] + alpha[pi, None] * step[pi]
                te = residual(trial)[np.arange(len(pi))[:, None], _ROWS[a[pi]]]
                tn = np.abs(te).max(axis=1)
                good = tn < norm[a[pi]] * (1.0 - 1e-4 * alpha[pi]) + 1e-300
                gi = pi[good]
                new_x[gi], new_e[gi], new_n[gi] = trial[good], te[good], tn[good]
                pending[gi] = False
                alpha[pi[~good]] *= 0.5
            stalled = singular | pending
            x[a], e[a], norm[a] = new_x, new_e, new_n
            conv[a] = new_n <= self.newton_tol
            active[a[stalled]] = False
            active &= ~conv
        ok = conv & np.all(np.isfinite(x), axis=1)
        return x[:, :3], x[:, 3:], ok

    # -- kinematics (the Solver protocol) -------------------------------------------------------------------
    def body_poses(self, q) -> BodyPoses:
        """Every body's position and quaternion at q: the model's own kinematics."""
        return self.model.body_poses(q)

    def solved_body_poses(self) -> None:
        """None: a solve leaves no body poses of its own to reuse."""
        return None

    # -- constraints --------------------------------------------------------------------------------------
    def _hidden(self, points: np.ndarray, normals: np.ndarray, prim: _Prim, poses) -> np.ndarray:
        """Not on the arm's outline: the point just outside (along the outward normal) lies inside
        another primitive (touchable or not)."""
        y = points + self.hide_tol * normals
        hid = np.zeros(len(points), dtype=bool)
        for other in self._prims:
            if other.geom == prim.geom:
                continue
            rot, org = poses[other.geom]
            hid |= inside(other.kind, other.size, (y - org) @ rot)
        return hid

    def _mutation_links(self, tau_ext: np.ndarray) -> set[int] | None:
        """5.4: bodies compatible with the joint torques; None when no joint's torque is above threshold."""
        over = np.abs(tau_ext) > self.mutation_threshold
        if not over.any():
            return None
        joints = np.flatnonzero(over)
        j = int(joints[np.argmax(self._joint_depth[joints])])  # the most distal mutated joint
        return {b for b in range(len(self._deepest)) if self._deepest[b] == j}

    # -- batch --------------------------------------------------------------------------------------------
    def solve_batch(self, wrenches_sensor, qs, tau_ext=None, saturated=None) -> BatchEstimate:
        """``solve`` over N frames (a loop): wrenches (N, 6), qs (N, n)."""
        w = np.asarray(wrenches_sensor, dtype=np.float64).reshape(-1, 6)
        n = w.shape[0]
        qs = np.asarray(qs, dtype=np.float64).reshape(n, self.model.n_joints)
        taus = None if tau_ext is None else np.asarray(tau_ext, dtype=float).reshape(n, self.model.n_joints)
        sat = np.zeros(n, dtype=bool) if saturated is None else np.asarray(saturated, dtype=bool).reshape(n)
        est = [self.solve(w[i], qs[i], None if taus is None else taus[i], bool(sat[i])) for i in range(n)]
        return BatchEstimate.from_estimates(est, self.links)


# -- helpers -------------------------------------------------------------------------------------------
def _empty(bits: int, residual: float) -> ContactEstimate:
    z = np.zeros(3)
    return ContactEstimate(False, None, z, z.copy(), z.copy(), residual, 0.0, np.zeros((6, 6)), math.inf,
                           flag_names(bits), (), np.zeros((0, 8)))


def _dedup(cands: list[_Cand], tol: float) -> list[_Cand]:
    """One candidate per contact: a seam point reported by two primitives of one link is kept once
    (the smaller residual)."""
    out: list[_Cand] = []
    for c in sorted(cands, key=lambda c: c.chi2):
        if not any(o.prim.body == c.prim.body and np.linalg.norm(o.point - c.point) <= tol for o in out):
            out.append(c)
    return out


def _inliers(points: np.ndarray, normals: np.ndarray, k: float) -> np.ndarray:
    """5.5's removal of singular solutions: drop those whose position, then whose normal, deviates
    from the median by more than ``k`` robust standard deviations (1.4826 MAD)."""
    keep = np.ones(len(points), dtype=bool)
    if len(points) <= 2:
        return keep
    dist = np.linalg.norm(points - np.median(points, axis=0), axis=1)
    keep &= dist <= k * MAD_TO_SIGMA * np.median(dist) + 1e-9
    nm = _unit(np.median(normals[keep], axis=0))
    ang = np.arccos(np.clip(normals @ nm, -1.0, 1.0))
    keep &= ang <= k * MAD_TO_SIGMA * np.median(ang[keep]) + 1e-9
    return keep


def _nearest_to_line(patch: _Patch, o: np.ndarray, d: np.ndarray, iters: int = 30) -> tuple[np.ndarray, float]:
    """The patch point nearest the line ``o + s d`` (unit d) by alternating projections (line, patch),
    from the line point nearest the patch's centre, and its distance to the line."""
    centre = patch.centre if isinstance(patch, _Quadric) else patch.n * patch.h
    y = o + float((centre - o) @ d) * d
    x = patch.project(y)
    for _ in range(iters):
        y = o + float((x - o) @ d) * d
        x_new = patch.project(y)
        if np.linalg.norm(x_new - x) <= 1e-12 * (1.0 + patch.scale):
            x = x_new
            break
        x = x_new
    off = x - o
    return x, float(np.linalg.norm(off - (off @ d) * d))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (n, 3) arrays (np.cross is slow on small arrays)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 0 else v


def _radial(v: np.ndarray) -> np.ndarray:
    """Unit xy direction of v (+x on the axis)."""
    rho = math.hypot(v[0], v[1])
    return np.array([v[0] / rho, v[1] / rho, 0.0]) if rho > 0 else np.array([1.0, 0.0, 0.0])


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _skew_many(v: np.ndarray) -> np.ndarray:
    out = np.zeros((len(v), 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -v[:, 2], v[:, 1]
    out[:, 1, 0], out[:, 1, 2] = v[:, 2], -v[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -v[:, 1], v[:, 0]
    return out


__all__ = ["Leng2016Solver"]
