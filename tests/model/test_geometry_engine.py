"""The compiled geometry engine (ftc_hw.geometry) held against the numpy reference (geometry_reference.py)
on random lines and points at the scenes' scales and on the reference's hard cases that lie in the
engine's domain: tangent lines, lines along axes, grazing lines, capsule seams, box edges and faces.

Tolerances (eps the float64 epsilon, scale the primitive's largest size, |o| the line origin's distance):
- crossings: the same hits, and s within 16 eps (scale + |o|) / |cos incidence| of the reference's,
  except where the reference calls the line tangent (hit or miss is then a matter of rounding);
- tangent lines built within 3 sizes of the point: a double root, within the reference's root by
  sqrt(2 rho delta) (rho the largest curvature radius, delta = 64 eps (scale + |s|)). The engine's
  tangency margin is 1e-14 of the size, the reference's the line's rounding, eps (size + |o|): from
  farther away a line tangent within rounding may be a miss for the engine and a touch for the
  reference;
- inside: the same answer except within 1e-12 scale of the boundary; for an ellipsoid with a margin
  the engine's test is algebraic: the reference's answer with margin tol implies the engine's, which
  implies the reference's with margin tol * min/max semi-axis;
- closest points and signed distances: 16 eps scale; normals at surface points: 1e-12.
"""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw import geometry as eng
from ftc_hw.geometry.solid import depth_s
from ftc_hw.model import ArmModel
from ftc_hw.model.arm import GEOM_KINDS, SURFACE_GROUP
from ftc_hw.model.sampling import sample_local
from ftc_hw.scene import builtin_names, load_scene
from tests.model import geometry_reference as ref

EPS = np.finfo(np.float64).eps
KINDS = ("sphere", "capsule", "cylinder", "ellipsoid", "box", "plane")
N_LINES = 3000


def _scene_primitives() -> list[tuple[str, np.ndarray]]:
    out = []
    for name in builtin_names():
        m = ArmModel(load_scene(name)).model
        out += [(GEOM_KINDS[int(m.geom_type[g])], m.geom_size[g].copy()) for g in range(m.ngeom)
                if m.geom_group[g] == SURFACE_GROUP and int(m.geom_type[g]) in GEOM_KINDS]
    return out


SCENE_PRIMS = _scene_primitives()


def _primitives(kind: str, rng: np.random.Generator) -> list[np.ndarray]:
    """The scenes' primitives of this kind and random ones from 5 mm to 0.3 m (aspect up to 10)."""
    sizes = [s for k, s in SCENE_PRIMS if k == kind]
    for _ in range(4):
        base = 10.0 ** rng.uniform(np.log10(0.005), np.log10(0.3))
        sizes.append(base * 10.0 ** rng.uniform(-0.5, 0.5, 3) if kind in ("ellipsoid", "box")
                     else np.array([base, base * 10.0 ** rng.uniform(-1.0, 0.7), 0.0]))
    return sizes


def _scale(kind: str, size: np.ndarray) -> float:
    return 1.0 if kind == "plane" else float(np.max(size[:3]))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _lines(kind: str, size: np.ndarray, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Lines through points within 1.5 scales of the centre, their origins up to 1.5 m away: about
    half of them hit."""
    d = _unit(rng.normal(size=(n, 3)))
    target = rng.uniform(-1.5, 1.5, (n, 3)) * _scale(kind, size)
    return target - rng.uniform(-1.5, 1.5, (n, 1)) * d, d


def _check_crossings(kind: str, size: np.ndarray, o: np.ndarray, d: np.ndarray) -> None:
    count, s = eng.crossings(kind, size, o, d)
    h = ref.intersect(kind, size, o, d)
    sure = ~h.tangent.any(-1)
    np.testing.assert_array_equal((count > 0)[sure], h.hit[sure, 0])
    both = (count > 0) & h.hit[:, 0]
    k = h.s.shape[1]
    cos = np.maximum(np.abs(h.cos_incidence[both]), 1e-300)
    tol = 16 * EPS * (_scale(kind, size) + np.linalg.norm(o[both], axis=-1))[:, None] / cos
    err = np.abs(s[both, :k] - h.s[both])
    assert (err <= tol).all(), f"{kind} {size}: worst s error {(err / tol).max():.3g} x tolerance"


@pytest.mark.parametrize("kind", KINDS)
def test_crossings_of_random_lines(kind: str) -> None:
    rng = np.random.default_rng(KINDS.index(kind))
    for size in _primitives(kind, rng):
        _check_crossings(kind, size, *_lines(kind, size, N_LINES, rng))


def _grazing_lines(kind: str, size: np.ndarray, n: int, rng: np.random.Generator, theta: np.ndarray):
    """Lines through surface points at grazing angle theta (rad), entering, origins up to 1.5 m away."""
    pn = [sample_local(kind, size, rng) for _ in range(n)]
    p, nrm = np.array([a for a, _ in pn]), np.array([b for _, b in pn])
    t = _unit(np.cross(nrm, rng.normal(size=(n, 3))))
    d = -np.sin(theta)[:, None] * nrm + np.cos(theta)[:, None] * t
    s = rng.uniform(-1.5, 1.5, n)
    return p - s[:, None] * d, d, s


@pytest.mark.parametrize("kind", ["sphere", "capsule", "cylinder", "ellipsoid", "box"])
def test_crossings_of_grazing_lines(kind: str) -> None:
    rng = np.random.default_rng(10 + KINDS.index(kind))
    for size in _primitives(kind, rng):
        theta = np.radians(10.0 ** rng.uniform(-3, 0, 500))
        o, d, _ = _grazing_lines(kind, size, 500, rng, theta)
        _check_crossings(kind, size, o, d)


@pytest.mark.parametrize("kind", ["sphere", "capsule", "cylinder", "ellipsoid"])
def test_tangent_lines_are_double_roots(kind: str) -> None:
    rng = np.random.default_rng(20 + KINDS.index(kind))
    for size in _primitives(kind, rng):
        sc = _scale(kind, size)
        pn = [sample_local(kind, size, rng) for _ in range(400)]
        p, nrm = np.array([a for a, _ in pn]), np.array([b for _, b in pn])
        if kind in ("capsule", "cylinder"):  # tangent lines exist on the curved side only, off the rims
            keep = (np.abs(nrm[:, 2]) < 1e-9) & (np.abs(p[:, 2]) < 0.95 * size[1])
            p, nrm = p[keep], nrm[keep]
        d = _unit(np.cross(nrm, rng.normal(size=nrm.shape)))
        if kind in ("capsule", "cylinder"):  # a line along a ruling lies in the side (test_lines_along_axes)
            p, d = p[np.abs(d[:, 2]) < 0.99], d[np.abs(d[:, 2]) < 0.99]
        s_true = rng.uniform(-3, 3, len(p)) * sc
        o = p - s_true[:, None] * d
        count, s = eng.crossings(kind, size, o, d)
        h = ref.intersect(kind, size, o, d)
        assert (count == 2).all() and h.hit.all()
        radii = size[:3] if kind == "ellipsoid" else size[:1]
        rho_max = radii.max() ** 2 / radii.min()
        bound = np.sqrt(2 * rho_max * 64 * EPS * (sc + np.abs(s_true)))[:, None]
        assert (np.abs(s - h.s) <= bound).all() and (np.abs(s - s_true[:, None]) <= bound).all()


@pytest.mark.parametrize("kind", ["capsule", "cylinder"])
def test_lines_along_axes(kind: str) -> None:
    r, h = 0.04, 0.15
    rho = np.array([0.0, 0.1, 0.97, 1.0, 1.03, 2.0]) * r
    for dz in (-1.0, 1.0):
        o = np.stack([rho, 0 * rho, np.full_like(rho, -1.0 * dz)], -1)
        d = np.array([0.0, 0.0, dz])
        count, s = eng.crossings(kind, [r, h], o, d)
        hits = ref.intersect(kind, [r, h], o, d)
        np.testing.assert_array_equal(count > 0, hits.hit[:, 0])
        np.testing.assert_allclose(s[count > 0], hits.s[hits.hit[:, 0]], rtol=0, atol=16 * EPS)
    # along the axes of a box and an ellipsoid, through the centre and off it
    for kind2, size in (("box", [0.03, 0.02, 0.05]), ("ellipsoid", [0.03, 0.02, 0.05])):
        for axis in range(3):
            d = np.eye(3)[axis]
            o = np.array([[0.0, 0.0, 0.0], [0.01, 0.01, 0.01], [0.1, 0.1, 0.1]]) - 2.0 * d
            _check_crossings(kind2, np.array(size), o, np.broadcast_to(d, o.shape))


def test_capsule_seams_and_cylinder_rims() -> None:
    r, h = 0.2, 0.5
    seam = np.array([[-3.0, 0.0, h], [-3.0, 0.0, -h], [0.0, -3.0, h]])  # horizontal, at the seams' height
    d = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    _check_crossings("capsule", np.array([r, h, 0.0]), seam, d)
    d_obl = _unit(np.array([0.1, 0.0, 1.0]))  # entering through the side, leaving through the top ball
    _check_crossings("capsule", np.array([r, h, 0.0]), (np.array([-r, 0.0, 0.0]) - 2 * d_obl)[None], d_obl[None])
    rim = np.array([r, 0.0, h])
    for dd in (_unit(np.array([-1.0, 0.0, -0.3])), _unit(np.array([-0.3, 0.0, -1.0]))):
        _check_crossings("cylinder", np.array([r, h, 0.0]), (rim - 5 * dd)[None], dd[None])


def test_box_edges_corners_and_faces() -> None:
    hs = np.array([1.0, 2.0, 3.0])
    d = np.array([1.0, 0.0, 0.0])
    # through the box; lying in the face y = +2; just outside it; along an edge
    o = np.array([[-5.0, 0.5, -1.0], [-5.0, 2.0, 0.0], [-5.0, 2.0 + 1e-9, 0.0], [-5.0, 2.0, 3.0]])
    count, s = eng.crossings("box", hs, o, np.broadcast_to(d, o.shape))
    np.testing.assert_array_equal(count, [2, 2, 0, 2])
    np.testing.assert_array_equal(s[[0, 1, 3]], [[4.0, 6.0]] * 3)
    edge, corner = np.array([1.0, 2.0, 0.0]), hs
    for point, dd in ((edge, _unit(np.array([-1.0, -0.5, 0.1]))), (edge, _unit(np.array([-0.5, -1.0, 0.1]))),
                      (corner, _unit(-np.array([1.0, 1.1, 1.2])))):
        _check_crossings("box", hs, (point - 3 * dd)[None], dd[None])


def test_quadric_crossings() -> None:
    rng = np.random.default_rng(30)
    r, t = 0.04, 0.03
    for k in ([1 / r, 1 / r, 0.0], [0.0, 0.0, 1 / t], [1 / r] * 3, [1 / 0.048, 1 / 0.058, 1 / 0.05]):
        k = np.array(k)
        o, d = _lines("ellipsoid", np.full(3, 0.1), N_LINES, rng)
        count, s = eng.quadric_crossings(k, o, d)
        h = ref.intersect_quadric(o, d, k)
        sure = ~h.tangent.any(-1)
        np.testing.assert_array_equal((count == 2)[sure], h.hit[sure, 0])
        both = (count == 2) & h.hit[:, 0]
        cos = np.maximum(np.abs(h.cos_incidence[both]), 1e-300)
        tol = 16 * EPS * (0.1 + np.linalg.norm(o[both], axis=-1))[:, None] / cos
        assert (np.abs(s[both] - h.s[both]) <= tol).all()
    # parallel to the infinite axis: no crossing
    count, _ = eng.quadric_crossings([1 / r, 1 / r, 0.0], [[0.0, 0.0, 1.0]], [[0.0, 0.0, 1.0]])
    assert count[0] == 0


def _points(kind: str, size: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    return rng.uniform(-1.5, 1.5, (n, 3)) * _scale(kind, size)


@pytest.mark.parametrize("kind", KINDS)
def test_inside(kind: str) -> None:
    rng = np.random.default_rng(40 + KINDS.index(kind))
    for size in _primitives(kind, rng):
        sc = _scale(kind, size)
        x = _points(kind, size, N_LINES, rng)
        sd = ref.signed_distance(kind, size, x).distance
        for tol in (0.0, 0.1 * sc):
            mine = eng.inside(kind, size, x, tol)
            if kind == "ellipsoid" and tol > 0:
                assert (mine[ref.inside(kind, size, x, tol)]).all()
                assert ref.inside(kind, size, x, tol * size.min() / size.max())[mine].all()
                continue
            clear = np.abs(sd + tol) > 1e-12 * sc
            np.testing.assert_array_equal(mine[clear], ref.inside(kind, size, x, tol)[clear])


@pytest.mark.parametrize("kind", ["sphere", "capsule", "cylinder", "box", "ellipsoid"])
def test_depth_inside(kind: str) -> None:
    """The engine's depth is the distance to the surface inside (a lower bound for an ellipsoid)."""
    rng = np.random.default_rng(50 + KINDS.index(kind))
    size = _primitives(kind, rng)[-1]
    x = _points(kind, size, 500, rng)
    sd = ref.signed_distance(kind, size, x).distance
    depth = np.array([depth_s(eng.kind_code(kind), size, *p) for p in x])
    assert (np.sign(depth[np.abs(sd) > 1e-12]) == -np.sign(sd[np.abs(sd) > 1e-12])).all()
    inner = sd < 0
    if kind == "ellipsoid":
        assert (depth[inner] <= -sd[inner] + 16 * EPS * size.max()).all()
    else:
        np.testing.assert_allclose(depth[inner], -sd[inner], rtol=0, atol=16 * EPS * size.max())


@pytest.mark.parametrize("kind", ["sphere", "capsule", "cylinder", "box", "plane"])
def test_closest_point_of_the_closed_forms(kind: str) -> None:
    rng = np.random.default_rng(60 + KINDS.index(kind))
    for size in _primitives(kind, rng):
        x = _points(kind, size, N_LINES, rng)
        np.testing.assert_allclose(eng.project(kind, size, x), ref.signed_distance(kind, size, x).closest,
                                   rtol=0, atol=16 * EPS * _scale(kind, size))


def test_closest_point_of_ellipsoids_and_infinite_quadrics() -> None:
    rng = np.random.default_rng(70)
    semis = _primitives("ellipsoid", rng) + [np.array([0.3, 0.02, 0.02]), np.array([0.04, 0.04, 0.04]),
                                             np.array([0.04, 0.04, np.inf])]
    for semi in semis:
        k = np.where(np.isinf(semi), 0.0, 1.0 / semi)
        scale = np.max(semi[np.isfinite(semi)])
        x = _points("ellipsoid", np.full(3, scale), N_LINES, rng)
        x[:10, np.argmax(k)] = 0.0  # inside on the mid-plane of the smallest semi-axis: off-axis nearest points
        closest, dist = eng.quadric_closest(k, x)
        sd = ref.signed_distance("ellipsoid", semi, x)
        np.testing.assert_allclose(closest, sd.closest, rtol=0, atol=16 * EPS * scale)
        np.testing.assert_allclose(dist, sd.distance, rtol=0, atol=16 * EPS * scale)


@pytest.mark.parametrize("kind", KINDS)
def test_normals_at_surface_points(kind: str) -> None:
    rng = np.random.default_rng(80 + KINDS.index(kind))
    for size in _primitives(kind, rng):
        if kind == "plane":
            pts = np.column_stack([rng.uniform(-1, 1, (200, 2)), np.zeros(200)])
        else:
            pts = np.array([sample_local(kind, size, rng)[0] for _ in range(500)])
        np.testing.assert_allclose(eng.normals(kind, size, pts), ref.surface_normal(kind, size, pts), rtol=0,
                                   atol=1e-12)
        # and at the reference's crossings of random lines, off edges and rims
        o, d = _lines(kind, size, 500, rng)
        h = ref.intersect(kind, size, o, d)
        ok = h.hit & ~h.edge
        np.testing.assert_allclose(eng.normals(kind, size, h.points[ok]), h.normals[ok], rtol=0, atol=1e-9)


def test_ray_distance_is_the_first_crossing_ahead() -> None:
    """The world's ray entry: from outside, the entry; from inside, the exit; behind, none."""
    pos, mat = np.array([0.1, 0.2, 0.3]), np.eye(3).ravel()
    u = np.array([0.0, 0.0, 1.0])
    assert eng.ray_distance("sphere", [0.05], pos, mat, pos - 0.1 * u, u) == pytest.approx(0.05, abs=1e-15)
    assert eng.ray_distance("sphere", [0.05], pos, mat, pos, u) == pytest.approx(0.05, abs=1e-15)
    assert eng.ray_distance("sphere", [0.05], pos, mat, pos + 0.1 * u, u) == -1.0
