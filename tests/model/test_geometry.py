"""Tests of the numpy geometry reference (geometry_reference.py): line/primitive crossings, closest points,
signed distances."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from tests.model import geometry_reference as geo

EPS = np.finfo(np.float64).eps
# Any numpy RuntimeWarning (overflow, invalid, divide) in the module under test fails the test.
pytestmark = pytest.mark.filterwarnings("error")
HYP = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
KINDS = geo.KINDS
# Error budget: C_ERR * eps * (problem scale) / sin(grazing angle); measured worst case ~1.4 (point),
# ~2.9 (s).  Surface-equation residuals: RES_ULPS ulps (measured <= 4).
C_ERR = 8.0
RES_ULPS = 16.0


# ----------------------------------------------------------------------------- generators


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _sphere_dir(u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    z = 2.0 * u1 - 1.0
    phi = 2.0 * np.pi * u2
    rr = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([rr * np.cos(phi), rr * np.sin(phi), z], -1)


def make_size(kind: str, base: np.ndarray, e: np.ndarray) -> np.ndarray:
    """MuJoCo-style size (..., 3): base scale (m) and log10 aspect exponents e (..., 3)."""
    s = base[..., None] * 10.0 ** e
    if kind in ("sphere", "plane"):
        return np.stack([base, 0 * base, 0 * base], -1)
    if kind in ("capsule", "cylinder"):
        return np.stack([s[..., 0], s[..., 1], 0 * base], -1)
    return s


def surface_sample(kind: str, size: np.ndarray, u: np.ndarray, margin: float = 1e-3
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Surface points and outward normals from uniforms u (..., 4); flat faces keep `margin` off edges."""
    u1, u2, u3, u4 = (u[..., i] for i in range(4))
    m = 1.0 - margin
    if kind == "sphere":
        n = _sphere_dir(u1, u2)
        return size[..., :1] * n, n
    if kind == "ellipsoid":
        w = _sphere_dir(u1, u2)
        return size * w, _unit(w / size)
    if kind == "plane":
        p = np.stack([20 * u1 - 10, 20 * u2 - 10, 0 * u1], -1)
        return p, np.broadcast_to([0.0, 0.0, 1.0], p.shape).copy()
    if kind == "capsule":
        r, h = size[..., 0], size[..., 1]
        phi = 2 * np.pi * u2
        radial = np.stack([np.cos(phi), np.sin(phi), 0 * phi], -1)
        side = u3 < 0.5
        p_side = r[..., None] * radial + np.stack([0 * r, 0 * r, (2 * u1 - 1) * h], -1)
        w = _sphere_dir(u1, u2)
        w[..., 2] = np.abs(w[..., 2]) * np.where(u4 < 0.5, 1.0, -1.0)
        p_cap = r[..., None] * w + np.stack([0 * r, 0 * r, np.sign(w[..., 2]) * h], -1)
        return np.where(side[..., None], p_side, p_cap), np.where(side[..., None], radial, w)
    if kind == "cylinder":
        r, h = size[..., 0], size[..., 1]
        phi = 2 * np.pi * u2
        radial = np.stack([np.cos(phi), np.sin(phi), 0 * phi], -1)
        side = u3 < 0.5
        p_side = r[..., None] * radial + np.stack([0 * r, 0 * r, m * (2 * u1 - 1) * h], -1)
        sz = np.where(u4 < 0.5, 1.0, -1.0)
        p_cap = (m * np.sqrt(u1) * r)[..., None] * radial + np.stack([0 * r, 0 * r, sz * h], -1)
        n_cap = np.stack([0 * r, 0 * r, sz], -1)
        return np.where(side[..., None], p_side, p_cap), np.where(side[..., None], radial, n_cap)
    # box
    face = np.minimum((u3 * 3).astype(int), 2)
    sgn = np.where(u4 < 0.5, 1.0, -1.0)
    coords = m * (2 * np.stack([u1, u2, u1 * u2], -1) - 1) * size
    sel = np.arange(3) == face[..., None]
    p = np.where(sel, sgn[..., None] * size, coords)
    return p, np.where(sel, sgn[..., None], 0.0)


def entering_dir(n: np.ndarray, theta: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """Unit direction making grazing angle theta (rad) with the surface, entering (d.n = -sin theta)."""
    a = np.where(np.abs(n[..., :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = _unit(np.cross(n, a))
    t2 = np.cross(n, t1)
    tang = np.cos(psi)[..., None] * t1 + np.sin(psi)[..., None] * t2
    return -np.sin(theta)[..., None] * n + np.cos(theta)[..., None] * tang


def scale_of(kind: str, size: np.ndarray) -> np.ndarray:
    if kind == "plane":
        return np.full(size.shape[:-1], 10.0)
    if kind == "sphere":
        return size[..., 0]
    if kind in ("capsule", "cylinder"):
        return size[..., 0] + size[..., 1]
    return size.max(-1)


def implicit_residual(kind: str, size: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Relative residual of the surface equation at x (scale-free); exact distance where closed form."""
    if kind == "ellipsoid":
        return np.abs(((x / size) ** 2).sum(-1) - 1.0)
    sd = geo.signed_distance(kind, size, x).distance
    return np.abs(sd) / scale_of(kind, size)


def random_batch(kind: str, n: int, seed: int, *, far: float = 1e3, theta_min_deg: float = 0.1,
                 theta_deg: float | None = None, aspect: float = 1.5) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    base = 10.0 ** rng.uniform(-2.0, 0.0, n)
    size = make_size(kind, base, rng.uniform(-aspect, aspect, (n, 3)) if kind == "ellipsoid"
                     else rng.uniform(-1.0, 1.0, (n, 3)))
    p, nrm = surface_sample(kind, size, rng.uniform(0, 1, (n, 4)))
    theta = np.deg2rad(rng.uniform(theta_min_deg, 90.0 - theta_min_deg, n) if theta_deg is None
                       else np.full(n, theta_deg))
    d = entering_dir(nrm, theta, rng.uniform(0, 2 * np.pi, n))
    s_true = rng.uniform(-far, far, n)
    o = p - s_true[:, None] * d
    return dict(size=size, p=p, n=nrm, theta=theta, d=d, s_true=s_true, o=o)


def check_entry(kind: str, b: dict[str, np.ndarray], C: float = C_ERR) -> dict[str, float]:
    """Assert the entry crossing recovers the constructed point/normal; return worst error ratios."""
    hits = geo.intersect(kind, b["size"], b["o"], b["d"])
    assert hits.hit[:, 0].all()
    scale = scale_of(kind, b["size"]) + np.abs(b["s_true"]) + np.linalg.norm(b["p"], axis=-1)
    bound = EPS * scale / np.sin(b["theta"])
    err = np.linalg.norm(hits.points[:, 0] - b["p"], axis=-1)
    s_err = np.abs(hits.s[:, 0] - b["s_true"])
    n_err = np.linalg.norm(hits.normals[:, 0] - b["n"], axis=-1)
    ratio = err / bound
    assert (ratio <= C).all(), f"worst point error {err[np.argmax(ratio)]:.3g} m = {ratio.max():.3g} x bound"
    assert (s_err / bound <= C).all()
    # normal error: rounding of the point over the curvature radius (>= smallest size)
    sz = b["size"]
    if kind in ("sphere", "capsule", "cylinder"):
        curv_radius = sz[:, 0]
    elif kind == "ellipsoid":
        curv_radius = sz.min(-1) ** 2 / sz.max(-1)
    else:
        curv_radius = np.full(len(sz), np.inf)
    n_bound = C * bound / curv_radius
    assert (n_err <= np.maximum(n_bound, C * EPS)).all(), n_err.max()
    assert (np.abs(hits.cos_incidence[:, 0] + np.sin(b["theta"])) <= np.maximum(n_bound, C * EPS)).all()
    assert not hits.tangent[:, 0].any() or kind in ("box", "cylinder")  # faces: a grazed edge is fine
    both = hits.hit
    res = implicit_residual(kind, b["size"][:, None, :], hits.points)[both]
    assert (res <= RES_ULPS * EPS).all(), res.max()
    return dict(point=float(ratio.max()), s=float((s_err / bound).max()),
                normal=float((n_err / np.maximum(n_bound / C, EPS)).max()),
                residual_ulps=float(res.max() / EPS))


# ----------------------------------------------------------------------------- surface point recovery


@pytest.mark.parametrize("kind", KINDS)
def test_entry_recovers_surface_point_batch(kind: str) -> None:
    b = random_batch(kind, 20_000, seed=1)
    check_entry(kind, b)


@pytest.mark.parametrize("kind", KINDS)
@HYP
@given(u=st.lists(st.floats(0, 1), min_size=4, max_size=4),
       base_exp=st.floats(-2.0, 0.5), aspect=st.lists(st.floats(-1.5, 1.5), min_size=3, max_size=3),
       theta_deg=st.floats(0.1, 89.9), psi=st.floats(0, 2 * np.pi), s_true=st.floats(-1e3, 1e3))
def test_entry_recovers_surface_point_hypothesis(kind, u, base_exp, aspect, theta_deg, psi, s_true) -> None:
    base = np.array([10.0**base_exp])
    e = np.array([aspect]) if kind == "ellipsoid" else np.array([aspect]) / 1.5
    size = make_size(kind, base, e)
    p, n = surface_sample(kind, size, np.array([u]))
    theta = np.deg2rad(np.array([theta_deg]))
    d = entering_dir(n, theta, np.array([psi]))
    o = p - s_true * d
    check_entry(kind, dict(size=size, p=p, n=n, theta=theta, d=d, s_true=np.array([s_true]), o=o))


@pytest.mark.parametrize("kind", ["sphere", "ellipsoid", "capsule", "cylinder", "box"])
def test_grazing_error_grows_like_one_over_sin(kind: str) -> None:
    """Sweep 0.1..89.9 deg with |o| up to 1e3 m: error <= C eps scale / sin(theta) at every angle, and
    the error really does grow towards grazing (the bound has the right form, it is not just loose)."""
    worst_abs = {}
    for deg in [0.1, 0.3, 1, 3, 10, 30, 60, 89.9]:
        b = random_batch(kind, 4000, seed=int(deg * 10), theta_deg=deg)
        check_entry(kind, b)
        h = geo.intersect(kind, b["size"], b["o"], b["d"])
        err = np.linalg.norm(h.points[:, 0] - b["p"], axis=-1)
        rel = err / (scale_of(kind, b["size"]) + np.abs(b["s_true"]))
        worst_abs[deg] = rel.max()
    assert worst_abs[0.1] > 30 * worst_abs[89.9]


def test_ellipsoid_extreme_aspect_surface_equation() -> None:
    """Semi-axes 1e-4..1e2 m (axis ratios up to 1e6): every crossing satisfies the quadric to a few
    ulps (measured <= 3) and lies on the input line."""
    rng = np.random.default_rng(3)
    n = 20_000
    a = 10.0 ** rng.uniform(-3, 3, (n, 3)) * 0.1
    o = rng.uniform(-1, 1, (n, 3)) * a * 2
    d = _unit(rng.normal(size=(n, 3)) * a)  # directions scaled like the body, so many lines hit
    h = geo.intersect_ellipsoid(o, d, a)
    assert h.hit.mean() > 0.15
    res = np.abs(((h.points / a[:, None, :]) ** 2).sum(-1) - 1.0)[h.hit]
    assert res.max() <= 8 * EPS, res.max() / EPS
    # points lie on the input line
    on_line = o[:, None, :] + h.s[..., None] * d[:, None, :]
    dev = np.linalg.norm(on_line - h.points, axis=-1)[h.hit]
    assert (dev <= 32 * EPS * (np.linalg.norm(o, axis=-1)[:, None] + np.abs(h.s))[h.hit]).all()


# ----------------------------------------------------------------------------- independent consistency


@pytest.mark.parametrize("kind", KINDS)
def test_crossings_consistent_with_signed_distance(kind: str) -> None:
    """Random lines: crossings lie on the surface with the surface normal, the chord midpoint is inside,
    points just beyond entry/exit are outside; misses never pass inside."""
    rng = np.random.default_rng(11)
    n = 1500 if kind == "ellipsoid" else 5000  # its signed distance is iterative: keep the test quick
    size = make_size(kind, 10.0 ** rng.uniform(-1.5, 0, n), rng.uniform(-1, 1, (n, 3)))
    sc = scale_of(kind, size)
    o = rng.uniform(-1.5, 1.5, (n, 3)) * sc[:, None]
    d = _unit(rng.normal(size=(n, 3)))
    h = geo.intersect(kind, size, o, d)
    K = geo.N_CROSSINGS[kind]
    assert h.s.shape == (n, K) and h.points.shape == (n, K, 3)
    hit = h.hit
    sd = geo.signed_distance(kind, size[:, None, :], h.points)
    assert (np.abs(sd.distance[hit]) <= 64 * EPS * np.broadcast_to(sc[:, None], hit.shape)[hit]).all()
    ok_n = ~h.edge & hit
    assert np.allclose(sd.normal[ok_n], h.normals[ok_n], atol=1e-7)
    assert np.allclose(np.linalg.norm(h.normals[hit], axis=-1), 1.0, atol=4 * EPS)
    if K == 2:
        both = hit.all(-1) & ~h.tangent.any(-1)
        assert (h.s[:, 0] <= h.s[:, 1])[hit[:, 0]].all()
        mid = o + (0.5 * h.s.sum(-1))[:, None] * d
        assert (geo.signed_distance(kind, size, mid).distance[both] < 0).all()
        delta = 1e-6 * sc
        before = o + (h.s[:, 0] - delta)[:, None] * d
        after = o + (h.s[:, 1] + delta)[:, None] * d
        assert (geo.signed_distance(kind, size, before).distance[both] > 0).all()
        assert (geo.signed_distance(kind, size, after).distance[both] > 0).all()
        miss = ~hit[:, 0]
        ts = np.linspace(-4, 4, 401)[None, :] * sc[:, None] - (o * d).sum(-1)[:, None]
        pts = o[:, None, :] + ts[..., None] * d[:, None, :]
        sd_line = geo.signed_distance(kind, size[:, None, :], pts).distance
        assert (sd_line[miss] > -1e-9 * sc[miss, None]).all()
        # ... and hitting lines do pass inside (the grid is fine enough for non-grazing chords)
        long = both & ((h.s[:, 1] - h.s[:, 0]) > 0.05 * sc)
        assert (sd_line[long].min(-1) < 0).all()


# ----------------------------------------------------------------------------- degenerate cases


@pytest.mark.parametrize("kind", ["capsule", "cylinder"])
def test_line_parallel_to_axis(kind: str) -> None:
    r, h = 0.3, 0.7
    rho = np.array([0.0, 0.1, 0.29, 0.31, 2.0])
    o = np.stack([rho, 0 * rho, np.full_like(rho, 50.0)], -1)
    for dz in (-1.0, 1.0):
        d = np.array([0.0, 0.0, dz])
        hits = geo.intersect(kind, [r, h, 0], o * [1, 1, dz * -1], d)
        inside_r = rho < r
        assert (hits.hit[:, 0] == inside_r).all() and (hits.hit[:, 1] == inside_r).all()
        z = hits.points[inside_r][..., 2]
        if kind == "cylinder":
            np.testing.assert_array_equal(z, np.array([[-dz * h, dz * h]] * inside_r.sum()))
            np.testing.assert_array_equal(hits.normals[inside_r][..., 2], [[-dz, dz]] * inside_r.sum())
        else:
            zc = h + np.sqrt(r**2 - rho[inside_r] ** 2)
            np.testing.assert_allclose(z, np.stack([-dz * zc, dz * zc], -1), rtol=0, atol=8 * EPS)
        assert (hits.s == 0)[~inside_r].all() and (hits.points == 0)[~inside_r].all()


def test_line_along_cylinder_and_capsule_side_is_grazing() -> None:
    o = np.array([0.3, 0.0, -10.0])
    d = np.array([0.0, 0.0, 1.0])
    cyl = geo.intersect_cylinder(o, d, 0.3, 0.7)
    assert cyl.hit.all() and cyl.tangent.all() and cyl.edge.all()
    np.testing.assert_allclose(cyl.points, [[0.3, 0, -0.7], [0.3, 0, 0.7]], atol=1e-15)
    cap = geo.intersect_capsule(o, d, 0.3, 0.7)
    assert cap.hit.all() and cap.tangent.all()
    np.testing.assert_allclose(cap.points, [[0.3, 0, -0.7], [0.3, 0, 0.7]], atol=1e-15)
    np.testing.assert_allclose(cap.normals, [[1, 0, 0], [1, 0, 0]], atol=1e-15)


@pytest.mark.parametrize("kind", ["sphere", "ellipsoid", "capsule", "cylinder"])
@HYP
@given(u=st.lists(st.floats(0, 1), min_size=4, max_size=4), psi=st.floats(0, 2 * np.pi),
       s=st.floats(-1e3, 1e3))
def test_tangent_line_is_double_root(kind, u, psi, s) -> None:
    size = make_size(kind, np.array([0.2]), np.array([[0.3, -0.4, 0.5]]))
    if kind == "cylinder":
        u = [u[0], u[1], 0.0, u[3]]  # tangent lines exist on the curved side only
    p, n = surface_sample(kind, size, np.array([u]), margin=0.05)
    d = entering_dir(n, np.zeros(1), np.array([psi]))
    # a line along a vertical ruling of a side lies in the surface (a grazing chord, tested separately)
    assume(kind in ("sphere", "ellipsoid") or abs(d[0, 2]) < 0.99)
    o = p - s * d
    h = geo.intersect(kind, size, o, d)
    assert h.hit.all() and h.tangent.all()
    assert h.s[0, 0] == h.s[0, 1]
    # Along a tangent line the crossing is ill-conditioned: an offset delta ~ eps (size + |s|) across
    # the line moves it by ~sqrt(2 rho delta), rho the curvature radius, and turns the normal by that / rho.
    sz = size[0, :3] if kind == "ellipsoid" else size[0, :1]
    rho_min, rho_max = sz.min() ** 2 / sz.max(), sz.max() ** 2 / sz.min()
    delta = 64 * EPS * (sz.max() + abs(s))
    assert np.abs(h.cos_incidence).max() <= np.sqrt(2 * delta / rho_min)
    assert np.linalg.norm(h.points[0, 0] - p[0]) <= np.sqrt(2 * rho_max * delta)


def test_tangent_sphere_exact_and_slightly_off() -> None:
    r = 0.5
    d = np.array([1.0, 0.0, 0.0])
    # centre, exactly tangent, one ulp inside, one ulp outside (a miss by rounding), clear misses
    off = np.array([0.0, 1.0, 1.0 - EPS / 2, 1.0 + EPS, 1.0 + 1e-12, 1.0 + 1e-6])
    o = np.stack([-3 + 0 * off, r * off, 0 * off], -1)
    h = geo.intersect_sphere(o, d, r)
    assert h.hit[:4].all() and not h.hit[4:].any()
    assert h.tangent[1:4].all() and not h.tangent[0].any()
    np.testing.assert_array_equal(h.s[1:4, 0], h.s[1:4, 1])  # one double root
    np.testing.assert_allclose(h.s[1:4], 3.0, rtol=EPS)
    assert np.abs(h.cos_incidence[1:4]).max() < 1e-15


def test_line_through_sphere_centre() -> None:
    rng = np.random.default_rng(5)
    d = _unit(rng.normal(size=(100, 3)))
    r = 10.0 ** rng.uniform(-3, 1, 100)
    s_c = rng.uniform(-1e3, 1e3, 100)
    o = -s_c[:, None] * d
    h = geo.intersect_sphere(o, d, r)
    assert h.hit.all() and not h.tangent.any()
    np.testing.assert_allclose(h.s, np.stack([s_c - r, s_c + r], -1), rtol=0, atol=8 * EPS * 1e3)
    np.testing.assert_allclose(h.normals[:, 0], -d, atol=8 * EPS * 1e3 / r.min())
    np.testing.assert_allclose(h.cos_incidence, [[-1.0, 1.0]] * 100, atol=1e-12)


def test_far_origin_no_cancellation() -> None:
    """|o| = 1e3 m, r = 1 mm: the crossing error stays ~eps*|o|, not eps*|o|^2/r."""
    r = 1e-3
    p = np.array([0.0, r, 0.0])
    d = _unit(np.array([0.3, -1.0, 0.2]))
    o = p - 1e3 * d
    h = geo.intersect_sphere(o, d, r)
    assert np.linalg.norm(h.points[0] - p) <= 8 * EPS * 1e3
    assert abs(np.linalg.norm(h.points[0]) - r) <= 8 * EPS * r


def test_float32_inputs() -> None:
    b = random_batch("ellipsoid", 2000, seed=4, far=10.0, theta_min_deg=5)
    o32, d32 = b["o"].astype(np.float32), b["d"].astype(np.float32)
    h32 = geo.intersect_ellipsoid(o32, d32, b["size"].astype(np.float32))
    assert h32.s.dtype == np.float64 and h32.points.dtype == np.float64
    # identical to the float64 computation on the rounded inputs ...
    h64 = geo.intersect_ellipsoid(o32.astype(np.float64), d32.astype(np.float64),
                                  b["size"].astype(np.float32))
    np.testing.assert_array_equal(h32.points, h64.points)
    # ... and as accurate as float32 allows
    eps32 = np.finfo(np.float32).eps
    scale = np.abs(b["s_true"]) + b["size"].max(-1)
    err = np.linalg.norm(h32.points[:, 0] - b["p"], axis=-1)
    assert (err <= 8 * eps32 * scale / np.sin(b["theta"])).all()


@pytest.mark.parametrize("kind", KINDS)
def test_nan_inf_inputs_report_miss_without_warnings(kind: str) -> None:
    bad = [np.nan, np.inf, -np.inf]
    o = np.array([[0.0, 0.0, 5.0]] * 8)
    d = np.array([[0.0, 0.0, -1.0]] * 8)
    o[0, 0], o[1, 1], o[2, 2] = bad
    d[3, 0], d[4, 1], d[5, 2] = bad
    d[6] = 0.0
    o[7, 0] = 1e300  # beyond MAX_COORD
    size = [0.3, 0.4, 0.5]
    with warnings.catch_warnings(), np.errstate(all="raise", under="ignore"):
        warnings.simplefilter("error")
        h = geo.intersect(kind, size, o, d)
        c = geo.closest_point_on_surface_to_line(kind, size, o, d)
        sd = geo.signed_distance(kind, size, o)
        ins = geo.inside(kind, size, o)
        nn = geo.surface_normal(kind, size, o)
    assert not h.hit.any() and not c.valid.any() and not c.hit.any() and not ins.any()
    np.testing.assert_array_equal(sd.valid, [False] * 3 + [True] * 4 + [False])
    for arr in (*h, *c):
        assert np.isfinite(np.asarray(arr, dtype=float)).all()
        assert (arr == 0).all()
    for arr in (*sd, nn):
        assert np.isfinite(np.asarray(arr, dtype=float)).all()
        assert (arr[[0, 1, 2, 7]] == 0).all()
    # valid line in the same batch still works
    o[:] = [0.0, 0.0, 5.0]
    d[:] = [0.0, 0.0, -1.0]
    assert geo.intersect(kind, size, o, d).hit[:, 0].all()


@pytest.mark.parametrize("kind", ["sphere", "capsule", "cylinder", "ellipsoid", "box"])
@pytest.mark.parametrize("bad", [-1.0, 0.0, np.nan, np.inf, 1e13])
def test_invalid_size_raises(kind: str, bad: float) -> None:
    size = np.array([0.3, 0.4, 0.5])
    size[0] = bad
    if kind == "ellipsoid" and bad == np.inf:
        geo.intersect(kind, size, [0, 0, 5], [0, 0, -1])  # an infinite semi-axis is legal
        return
    if kind == "capsule" and bad == 0.0:
        size[1] = bad  # capsule radius 0 is invalid, half-length 0 is a sphere
        assert geo.intersect(kind, [0.3, 0.0], [0, 0, 5], [0, 0, -1]).hit.all()
        size[:2] = [0.0, 0.4]
    with pytest.raises(ValueError):
        geo.intersect(kind, size, [0, 0, 5], [0, 0, -1])
    with pytest.raises(ValueError):
        geo.signed_distance(kind, size, [0, 0, 5])


@pytest.mark.parametrize("kind", KINDS)
def test_misses_hold_zero_placeholders(kind: str) -> None:
    o = np.array([[50.0, 50.0, 50.0], [0.0, 0.0, 5.0]])
    d = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    h = geo.intersect(kind, [0.3, 0.4, 0.5], o, d)
    if kind == "plane":
        assert not h.hit.any()  # parallel
    assert not h.hit[0].any()
    for arr in (h.s, h.points, h.normals, h.cos_incidence):
        assert (arr[0] == 0).all()
    assert not h.tangent[0].any() and not h.edge[0].any()


# ----------------------------------------------------------------------------- seams, edges, faces


def test_capsule_seam_and_side_plus_sphere() -> None:
    r, h = 0.2, 0.5
    # horizontal line exactly at the seam height: two crossings, radial normals, no duplicate
    hits = geo.intersect_capsule([-3.0, 0.0, h], [1.0, 0.0, 0.0], r, h)
    assert hits.hit.all() and not hits.tangent.any()
    np.testing.assert_allclose(hits.points, [[-r, 0, h], [r, 0, h]], atol=1e-15)
    np.testing.assert_allclose(hits.normals, [[-1, 0, 0], [1, 0, 0]], atol=1e-15)
    # oblique line entering through the side and leaving through the top hemisphere
    p_in = np.array([-r, 0.0, 0.0])
    d = _unit(np.array([0.1, 0.0, 1.0]))
    hits = geo.intersect_capsule(p_in - 2 * d, d, r, h)
    np.testing.assert_allclose(hits.points[0], p_in, atol=1e-15)
    x_out = hits.points[1]
    assert x_out[2] > h
    np.testing.assert_allclose(np.linalg.norm(x_out - [0, 0, h]), r, rtol=4 * EPS)
    np.testing.assert_allclose(hits.normals[1], (x_out - [0, 0, h]) / r, atol=1e-14)


def test_cylinder_rim_is_flagged_with_consistent_normal() -> None:
    r, h = 0.2, 0.5
    rim = np.array([r, 0.0, h])
    for d, expect in [(_unit(np.array([-1.0, 0.0, -0.3])), [1, 0, 0]),
                      (_unit(np.array([-0.3, 0.0, -1.0])), [0, 0, 1])]:
        hits = geo.intersect_cylinder(rim - 5 * d, d, r, h)
        assert hits.edge[0] and not hits.edge[1]
        np.testing.assert_allclose(hits.points[0], rim, atol=1e-15)
        np.testing.assert_array_equal(hits.normals[0], expect)  # the face met most head-on
    # just off the rim by more than edge_tol: no flag
    d = _unit(np.array([-1.0, 0.0, -0.3]))
    hits = geo.intersect_cylinder(rim - [0, 0, 1e-6] - 5 * d, d, r, h)
    assert not hits.edge[0]


def test_box_parallel_faces_and_edges() -> None:
    hs = np.array([1.0, 2.0, 3.0])
    d = np.array([1.0, 0.0, 0.0])
    o = np.array([[-5.0, 0.5, -1.0], [-5.0, 2.0, 0.0], [-5.0, 2.0 + 1e-9, 0.0], [-5.0, 2.0, 3.0]])
    h = geo.intersect_box(o, d, hs)
    assert h.hit[0].all() and not h.tangent[0].any() and not h.edge[0].any()
    np.testing.assert_array_equal(h.points[0], [[-1, 0.5, -1], [1, 0.5, -1]])
    np.testing.assert_array_equal(h.normals[0], [[-1, 0, 0], [1, 0, 0]])
    np.testing.assert_array_equal(h.s[0], [4.0, 6.0])
    assert h.hit[1].all() and h.tangent[1].all() and h.edge[1].all()  # line lying in the face y = +2
    np.testing.assert_array_equal(h.normals[1], [[-1, 0, 0], [1, 0, 0]])
    assert not h.hit[2].any()
    assert h.hit[3].all() and h.tangent[3].all()  # along an edge
    # through an edge at an angle: flagged, normal of the most head-on face
    e = np.array([1.0, 2.0, 0.0])
    for dd, expect in [(_unit(np.array([-1.0, -0.5, 0.1])), [1, 0, 0]),
                       (_unit(np.array([-0.5, -1.0, 0.1])), [0, 1, 0])]:
        h = geo.intersect_box(e - 3 * dd, dd, hs)
        assert h.edge[0] and h.hit.all()
        np.testing.assert_allclose(h.points[0], e, atol=1e-15)
        np.testing.assert_array_equal(h.normals[0], expect)
    # corner
    c = hs.copy()
    dd = _unit(-np.array([1.0, 1.1, 1.2]))
    h = geo.intersect_box(c - 3 * dd, dd, hs)
    assert h.edge[0]
    np.testing.assert_allclose(h.points[0], c, rtol=0, atol=4 * EPS)
    np.testing.assert_array_equal(h.normals[0], [0, 0, 1])


def test_plane() -> None:
    o = np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 3.0], [1.0, 2.0, -3.0]])
    d = np.array([[0.0, 0.6, -0.8], [1.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
    h = geo.intersect_plane(o, d)
    assert h.s.shape == (3, 1)
    np.testing.assert_array_equal(h.hit[:, 0], [True, False, True])
    np.testing.assert_allclose(h.s[:, 0], [3.75, 0.0, 3.0], rtol=4 * EPS)
    np.testing.assert_allclose(h.points[0, 0], [1.0, 4.25, 0.0], rtol=4 * EPS)
    assert h.points[0, 0, 2] == 0.0
    np.testing.assert_array_equal(h.normals[[0, 2], 0], [[0, 0, 1], [0, 0, 1]])
    np.testing.assert_allclose(h.cos_incidence[:, 0], [-0.8, 0.0, 1.0])


def test_quadric_limits_infinite_cylinder_and_slab() -> None:
    r, t = 0.3, 0.2
    k_cyl = [1 / r, 1 / r, 0.0]
    o = np.array([[-5.0, 0.1, 1e3], [0.1, 0.1, -5.0], [5.0, 5.0, 1.0]])
    d = _unit(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -1.0, 0.3]]))
    h = geo.intersect_quadric(o, d, k_cyl)
    assert h.hit[0].all() and not h.hit[1].any() and h.hit[2].all()
    np.testing.assert_allclose(np.hypot(h.points[..., 0], h.points[..., 1])[h.hit], r, rtol=4 * EPS)
    np.testing.assert_allclose(h.points[0, :, 2], 1e3, rtol=0, atol=0)
    np.testing.assert_allclose(h.normals[0], [[-np.sqrt(1 - (0.1 / r) ** 2), 1 / 3, 0],
                                               [np.sqrt(1 - (0.1 / r) ** 2), 1 / 3, 0]], atol=1e-14)
    # the same through intersect_ellipsoid with an infinite semi-axis
    he = geo.intersect_ellipsoid(o, d, [r, r, np.inf])
    np.testing.assert_array_equal(he.points, h.points)
    slab = geo.intersect_quadric(o, d, [0.0, 0.0, 1 / t])
    assert not slab.hit[0].any() and slab.hit[1].all() and slab.hit[2].all()
    np.testing.assert_allclose(slab.points[1, :, 2], [-t, t], rtol=4 * EPS)
    np.testing.assert_array_equal(slab.normals[1], [[0, 0, -1], [0, 0, 1]])


# ----------------------------------------------------------------------------- broadcasting / dispatcher


def test_broadcasting_frames_and_primitives() -> None:
    rng = np.random.default_rng(2)
    # N lines vs one primitive
    o = rng.normal(size=(7, 5, 3))
    d = rng.normal(size=(7, 5, 3))
    h = geo.intersect("box", [0.5, 0.6, 0.7], o, d)
    assert h.s.shape == (7, 5, 2) and h.points.shape == (7, 5, 2, 3)
    # one line (per local frame) vs P primitives of one type
    sizes = rng.uniform(0.1, 1.0, (4, 3))
    hp = geo.intersect("capsule", sizes, o[0, 0], d[0, 0])
    assert hp.s.shape == (4, 2)
    for i in range(4):
        hi = geo.intersect_capsule(o[0, 0], d[0, 0], sizes[i, 0], sizes[i, 1])
        np.testing.assert_array_equal(hp.points[i], hi.points)
    # per-primitive scalar sizes through the direct functions
    hr = geo.intersect_sphere(np.zeros(3) + [0, 0, 3], [0, 0, -1], np.array([0.1, 0.2, 0.3]))
    np.testing.assert_allclose(hr.s[:, 0], [2.9, 2.8, 2.7])
    hq = geo.intersect_ellipsoid(o[:, :, None], d[:, :, None], sizes[None, None])
    assert hq.s.shape == (7, 5, 4, 2)
    assert geo.intersect(2, 0.5, [0, 0, 3], [0, 0, -1]).hit.all()  # mjGEOM_SPHERE
    # sphere radii for P primitives go as (P, 1) (or MuJoCo rows (P, 3)); (P,) would be one size vector
    hs = geo.intersect("sphere", np.array([[0.1], [0.2], [0.3]]), [0, 0, 3], [0, 0, -1])
    np.testing.assert_allclose(hs.s[:, 0], [2.9, 2.8, 2.7])
    with pytest.raises(ValueError):
        geo.intersect("sphere", np.array([0.1, 0.2, 0.3, 0.4]), [0, 0, 3], [0, 0, -1])
    with pytest.raises(ValueError):
        geo.intersect("torus", 1.0, [0, 0, 3], [0, 0, -1])
    with pytest.raises(ValueError):
        geo.intersect("box", [1.0, 2.0], [0, 0, 3], [0, 0, -1])


def test_direction_need_not_be_unit() -> None:
    h1 = geo.intersect_sphere([0, 0, 3], [0, 0, -1], 1.0)
    h2 = geo.intersect_sphere([0, 0, 3], [0, 0, -1e-300], 1.0)
    h3 = geo.intersect_sphere([0, 0, 3], [0, 0, -1e300], 1.0)
    np.testing.assert_array_equal(h1.s, h2.s)
    np.testing.assert_array_equal(h1.s, h3.s)


# ----------------------------------------------------------------------------- closest points


@pytest.mark.parametrize("kind", KINDS)
@HYP
@given(u=st.lists(st.floats(0, 1), min_size=4, max_size=4), base_exp=st.floats(-2, 0.5),
       aspect=st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3), gap_exp=st.floats(-6, 1),
       psi=st.floats(0, 2 * np.pi), s=st.floats(-100, 100))
def test_closest_point_of_missing_line(kind, u, base_exp, aspect, gap_exp, psi, s) -> None:
    """A line at distance g along the outward normal of p, running tangentially, misses at distance g
    (supporting-plane argument), and for a strictly convex surface its nearest point is p."""
    size = make_size(kind, np.array([10.0**base_exp]), np.array([aspect]))
    p, n = surface_sample(kind, size, np.array([u]), margin=0.01)
    sc = scale_of(kind, size)[0]
    g = 10.0**gap_exp * sc
    d = entering_dir(n, np.zeros(1), np.array([psi]))
    o = p + g * n - s * d
    c = geo.closest_point_on_surface_to_line(kind, size, o, d)
    assert c.valid.all() and not c.hit.any()
    tol = 1e-10 * (sc + abs(s))
    assert abs(c.distance[0] - g) <= tol + 64 * EPS * g
    # the returned point is on the surface, the line point at s is at `distance` from it along the normal
    assert implicit_residual(kind, size, c.point)[0] <= 1e-10
    lp = o + c.s[:, None] * d
    np.testing.assert_allclose(lp - c.point, c.distance[:, None] * c.normal, atol=tol + 1e-7 * g)
    if kind in ("sphere", "ellipsoid") or kind == "capsule" and abs(p[0, 2]) > size[0, 1]:
        assert np.linalg.norm(c.point[0] - p[0]) <= 1e-6 * sc


@pytest.mark.parametrize("kind", ["sphere", "capsule", "cylinder", "ellipsoid", "box"])
def test_closest_point_minimises_brute_force(kind: str) -> None:
    """Returned distance is never above a dense sampling of the line around the returned parameter and
    matches its minimum (the distance along a line is convex, so a local minimum is the global one)."""
    rng = np.random.default_rng(21)
    n = 400
    size = make_size(kind, np.full(n, 0.3), rng.uniform(-1, 1, (n, 3)))
    o = rng.uniform(-2, 2, (n, 3))
    d = _unit(rng.normal(size=(n, 3)))
    c = geo.closest_point_on_surface_to_line(kind, size, o, d)
    ts = c.s[:, None] + np.linspace(-0.5, 0.5, 2001)[None, :]
    pts = o[:, None, :] + ts[..., None] * d[:, None, :]
    sd = geo.signed_distance(kind, size[:, None, :], pts).distance
    brute = np.maximum(sd.min(-1), 0.0)
    assert (c.distance <= brute + 1e-12).all()
    assert np.allclose(c.distance, brute, atol=2e-6)  # grid spacing 5e-4, quadratic minimum
    h = geo.intersect(kind, size, o, d)
    np.testing.assert_array_equal(c.hit, h.hit[:, 0])
    np.testing.assert_array_equal(c.point[c.hit], h.points[c.hit, 0])
    assert (c.distance[c.hit] == 0).all() and (c.distance[~c.hit] > 0).all()


def test_closest_point_quadric_limits() -> None:
    # infinite cylinder: skew line at distance 1 - r from the surface
    r = 0.3
    d = _unit(np.array([0.0, 1.0, 1.0]))
    c = geo.closest_point_on_surface_to_line("ellipsoid", [r, r, np.inf], [1.0, -4.0, 7.0], d)
    np.testing.assert_allclose(c.distance, 1.0 - r, rtol=4 * EPS)
    np.testing.assert_allclose(c.point[:2], [r, 0.0], atol=1e-15)
    np.testing.assert_allclose(c.normal, [1, 0, 0], atol=1e-15)
    # parallel to its axis, outside
    c = geo.closest_point_on_surface_to_line("ellipsoid", [r, 2 * r, np.inf], [0.0, 1.0, 7.0], [0, 0, 1])
    np.testing.assert_allclose(c.distance, 1.0 - 2 * r, rtol=1e-14)
    # slab, parallel line
    c = geo.closest_point_on_surface_to_line("ellipsoid", [np.inf, np.inf, 0.2], [1.0, 2.0, 0.5], [1, 0, 0])
    np.testing.assert_allclose(c.distance, 0.3, rtol=1e-14)
    np.testing.assert_allclose(c.point[2], 0.2, rtol=1e-15)


# ----------------------------------------------------------------------------- signed distance / inside


def test_signed_distance_closed_forms() -> None:
    rng = np.random.default_rng(8)
    x = rng.uniform(-2, 2, (5000, 3))
    sd = geo.signed_distance("sphere", 0.7, x)
    np.testing.assert_allclose(sd.distance, np.linalg.norm(x, axis=-1) - 0.7, atol=4 * EPS)
    hs = np.array([0.5, 0.7, 0.9])
    q = np.abs(x) - hs
    ref = np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(-1), 0)
    np.testing.assert_allclose(geo.signed_distance("box", hs, x).distance, ref, atol=4 * EPS)
    r, h = 0.4, 0.6
    qc = np.stack([np.hypot(x[:, 0], x[:, 1]) - r, np.abs(x[:, 2]) - h], -1)
    ref = np.linalg.norm(np.maximum(qc, 0), axis=-1) + np.minimum(qc.max(-1), 0)
    np.testing.assert_allclose(geo.signed_distance("cylinder", [r, h], x).distance, ref, atol=4 * EPS)
    zc = np.clip(x[:, 2], -h, h)
    ref = np.linalg.norm(x - np.stack([0 * zc, 0 * zc, zc], -1), axis=-1) - r
    np.testing.assert_allclose(geo.signed_distance("capsule", [r, h], x).distance, ref, atol=4 * EPS)
    np.testing.assert_array_equal(geo.signed_distance("plane", 0, x).distance, x[:, 2])
    for kind, size in [("sphere", 0.7), ("box", hs), ("cylinder", [r, h]), ("capsule", [r, h])]:
        sd = geo.signed_distance(kind, size, x)
        on_surface = geo.signed_distance(kind, size, sd.closest).distance
        np.testing.assert_allclose(on_surface, 0, atol=8 * EPS)
        out = sd.distance > 0
        np.testing.assert_allclose((x - sd.closest)[out], (sd.distance[:, None] * sd.normal)[out], atol=1e-14)


@HYP
@given(a=st.lists(st.floats(-1.5, 1.5), min_size=3, max_size=3),
       y=st.lists(st.floats(-2, 2), min_size=3, max_size=3))
def test_ellipsoid_signed_distance_optimality(a, y) -> None:
    """KKT: nearest point on the surface, y - x along the normal at x, sign by the quadric; vs sampling."""
    ax = 0.5 * 10.0 ** np.array(a)
    y = np.array(y) * ax * 1.5
    sd = geo.signed_distance("ellipsoid", ax, y)
    x = sd.closest
    assert abs(((x / ax) ** 2).sum() - 1.0) <= 64 * EPS
    v = y - x
    assert np.linalg.norm(v - sd.distance * sd.normal) <= 1e-9 * ax.max()
    assert np.sign(sd.distance) == np.sign(((y / ax) ** 2).sum() - 1.0) or sd.distance == 0
    # no sampled surface point is nearer
    w = _sphere_dir(*np.meshgrid(np.linspace(0, 1, 200), np.linspace(0, 1, 200)))
    brute = np.linalg.norm(w.reshape(-1, 3) * ax - y, axis=-1).min()
    assert abs(sd.distance) <= brute + 1e-12


def test_ellipsoid_interior_off_axis_nearest_point() -> None:
    # a point near the centre on the mid-plane of the smallest semi-axis: nearest point off-axis
    ax = np.array([2.0, 1.5, 1.0])
    y = np.array([0.3, 0.0, 0.0])
    sd = geo.signed_distance("ellipsoid", ax, y)
    # closed form in the xz plane: x0 = a^2 y0 / (a^2 - c^2), z = c sqrt(1 - (x0/a)^2)
    x0 = ax[0] ** 2 * y[0] / (ax[0] ** 2 - ax[2] ** 2)
    np.testing.assert_allclose(sd.closest, [x0, 0, ax[2] * np.sqrt(1 - (x0 / ax[0]) ** 2)], rtol=1e-14)
    assert sd.distance < 0
    # y on the minor axis itself (depth exactly the semi-axis)
    sd = geo.signed_distance("ellipsoid", ax, [0.0, 0.0, 0.5])
    np.testing.assert_allclose(sd.distance, -0.5, rtol=1e-14)


@pytest.mark.parametrize("kind", ["sphere", "capsule", "cylinder", "ellipsoid", "box"])
def test_inside_with_tolerance(kind: str) -> None:
    rng = np.random.default_rng(9)
    size = make_size(kind, np.full(500, 0.5), rng.uniform(-0.5, 0.5, (500, 3)))
    p, n = surface_sample(kind, size, rng.uniform(0, 1, (500, 4)), margin=0.05)
    delta = 1e-3
    assert not geo.inside(kind, size, p + delta * n).any()
    assert not geo.inside(kind, size, p, tol=1e-12).any()  # on the surface up to rounding
    deep = p - delta * n
    assert geo.inside(kind, size, deep, tol=0.0).all()
    assert not geo.inside(kind, size, deep, tol=1.01 * delta).any()  # depth <= delta
    if kind in ("sphere", "box", "cylinder"):  # depth exactly delta away from edges
        assert geo.inside(kind, size, deep, tol=0.99 * delta).all()


@pytest.mark.parametrize("kind", KINDS)
def test_surface_normal_matches_crossings(kind: str) -> None:
    b = random_batch(kind, 3000, seed=13, far=10.0, theta_min_deg=1.0)
    h = geo.intersect(kind, b["size"], b["o"], b["d"])
    nn = geo.surface_normal(kind, b["size"], h.points[:, 0])
    np.testing.assert_allclose(nn, h.normals[:, 0], atol=1e-9)
    np.testing.assert_allclose(nn, b["n"], atol=1e-6)


def test_bench_runs() -> None:
    from ftc_hw.bench.geometry import bench

    r = bench(2000, repeat=1, reference=geo)
    assert set(r) == set(KINDS)
    assert all(v[q] > 0 for v in r.values() for q in ("crossings", "inside", "closest", "reference_intersect"))
