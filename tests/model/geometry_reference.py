"""The numpy reference of the geometry engine (ftc_hw.geometry), for the tests only: line / primitive
geometry in the primitive's local frame (metres), vectorised and robust to the last ulp, slower.
test_geometry.py tests it; test_geometry_engine.py holds the engine against it.

Everything here works in the local frame of one primitive (MuJoCo geom conventions, centre at the
origin, axis along local z); the caller transforms the line ``x(s) = o + s*d`` into that frame.

Primitives and their size parameters (as MuJoCo ``geom_size`` uses them):

=============  ============================  =====================================================
kind           size                          solid
=============  ============================  =====================================================
``sphere``     ``r``                         ``|x| <= r``
``capsule``    ``r, h`` (h: half-length)     points within ``r`` of the segment z in [-h, h]
``cylinder``   ``r, h`` (h: half-length)     ``x^2 + y^2 <= r^2`` and ``|z| <= h`` (flat caps)
``ellipsoid``  ``a, b, c`` (semi-axes)       ``(x/a)^2 + (y/b)^2 + (z/c)^2 <= 1`` (``inf`` allowed)
``box``        ``hx, hy, hz`` (half sizes)   ``|x| <= hx, |y| <= hy, |z| <= hz``
``plane``      (ignored)                     half-space ``z <= 0``, surface ``z = 0``, normal +z
=============  ============================  =====================================================

The ellipsoid is the unified quadric ``|k * x| = 1`` with inverse semi-axes ``k >= 0``
(:func:`intersect_quadric`); ``k_i = 0`` means infinite extent, so ``k = (1/r, 1/r, 0)`` is an
infinite cylinder along z and ``k = (0, 0, 1/t)`` the slab ``|z| <= t``.

Conventions shared by all functions:

* Inputs broadcast over leading dimensions; they are converted to float64 (float32 in, float64 out).
* ``d`` need not be unit length: it is normalised, and ``s`` is the signed distance in metres along
  ``d/|d|`` (so ``points ~= o + s*d/|d|``).  Crossings with ``s < 0`` are reported too.
* Invalid lines (any NaN/Inf in ``o`` or ``d``, ``d == 0``, or ``|o_i| > MAX_COORD``) never raise and
  never warn: they report ``hit = False`` (``valid = False`` for the closest-point/distance queries).
  Invalid *sizes* (NaN, negative, outside ``[MIN_SIZE, MAX_SIZE]``) raise :class:`ValueError`:
  they are model errors, not measurement noise.
* Entries with ``hit == False`` hold 0 (never NaN/Inf).
* ``cos_incidence = d . n`` is the continuous grazing indicator (-1 head-on entry, 0 grazing,
  +1 head-on exit).  ``tangent`` flags lines tangent within rounding (``_TOL_ULPS`` ulps of the
  size plus the rounding of ``o`` across the line): on a curved surface a line missing or crossing
  by less than that is one double root (both slots equal); on flat faces a chord lying in a face
  plane (box, cylinder caps) or along the side of a cylinder/capsule keeps its two ends and is
  flagged.
* Accuracy: the point of a line crossing at grazing angle ``theta`` is within ~``eps * (size + |o|)
  / sin(theta)`` of the exact crossing (measured <= 1.4x that), and satisfies the surface equation
  to a few ulps (the ellipsoid gets one Newton step along the line for this).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

EPS = float(np.finfo(np.float64).eps)
MAX_COORD = 1e15
"""Lines/points with a coordinate beyond this (m) are treated as invalid (keeps every square finite)."""
MIN_SIZE = 1e-12
MAX_SIZE = 1e12
_TOL_ULPS = 4.0  # measured rounding of the line-to-centre distance: <= 0.6 ulps of the scale
_TOL = _TOL_ULPS * EPS
# Squared in-plane speed below which a line counts as parallel to an infinite axis; its crossings
# would lie beyond ~1e125 * size anyway.
_A_MIN = 1e-250
_BISECT_ITERS = 66  # geometric bisection over up to 2^-1075..2^180: relative width -> eps
_LINE_BISECT_ITERS = 58

KINDS = ("sphere", "capsule", "cylinder", "ellipsoid", "box", "plane")
N_CROSSINGS = {"sphere": 2, "capsule": 2, "cylinder": 2, "ellipsoid": 2, "box": 2, "plane": 1}
"""K, the number of crossing slots per kind (entry, exit; the plane has one)."""
_N_SIZE = {"sphere": 1, "capsule": 2, "cylinder": 2, "ellipsoid": 3, "box": 3, "plane": 0}
_MJ_GEOM = {0: "plane", 2: "sphere", 3: "capsule", 4: "ellipsoid", 5: "cylinder", 6: "box"}


class LineHits(NamedTuple):
    """Crossings of lines with one primitive kind, sorted by ``s`` (slot 0 entry, slot 1 exit).

    Shapes: ``s, hit, cos_incidence, tangent, edge`` are ``(..., K)``; ``points, normals`` are
    ``(..., K, 3)``; local frame, metres.
    """

    s: FloatArray
    """Signed distance along the unit direction from ``o`` (m)."""
    points: FloatArray
    """Crossing points on the surface (m)."""
    normals: FloatArray
    """Outward unit surface normals at ``points``."""
    hit: BoolArray
    """Slot holds a crossing."""
    cos_incidence: FloatArray
    """``d . n``: negative entering, positive exiting, ~0 grazing."""
    tangent: BoolArray
    """Line tangent to the surface within rounding (double root / chord lying in a face)."""
    edge: BoolArray
    """Point on an edge / corner (box) or rim (cylinder) within ``edge_tol``: normal is a choice."""


class LineClosest(NamedTuple):
    """Surface point nearest to a line (entry point when the line hits). Shapes ``(...)``/``(..., 3)``."""

    point: FloatArray
    """Surface point (m)."""
    normal: FloatArray
    """Outward unit normal at ``point``."""
    distance: FloatArray
    """Line-to-solid distance (m), 0 for lines that hit.  A line inside an unbounded solid that never
    crosses its surface (below a plane, along a slab / infinite cylinder) gets its distance to the
    surface."""
    s: FloatArray
    """Parameter of the line point nearest to ``point`` (m along the unit direction)."""
    hit: BoolArray
    """The line crosses the surface."""
    valid: BoolArray
    """Finite input; False entries hold zeros."""


class SurfaceDistance(NamedTuple):
    """Signed distance of points to a primitive surface (negative inside)."""

    distance: FloatArray
    """Signed distance (m), ``(...)``."""
    closest: FloatArray
    """Nearest surface point (m), ``(..., 3)``."""
    normal: FloatArray
    """Outward unit normal at ``closest``, ``(..., 3)``."""
    valid: BoolArray
    """Finite input; False entries hold zeros."""


class _Line(NamedTuple):
    d: FloatArray  # (..., 3) unit direction
    p0: FloatArray  # (..., 3) line point closest to the local origin
    s0: FloatArray  # (...) its parameter
    scale: FloatArray  # (...) rounding scale of o and p0 across the line (m), for interval tolerances
    rnd: FloatArray  # (..., 3) per-axis magnitudes rounded in o and in forming p0 (m)
    valid: BoolArray  # (...)
    shape: tuple[int, ...]


# ------------------------------------------------------------------------------- helpers


def _f64(x: ArrayLike) -> FloatArray:
    return np.asarray(x, dtype=np.float64)


def _dot(a: FloatArray, b: FloatArray) -> FloatArray:
    return (a * b).sum(-1)


def _norm(v: FloatArray) -> FloatArray:
    return np.sqrt((v * v).sum(-1))


def _unit(v: FloatArray) -> FloatArray:
    """Unit vectors along the last axis; zero vectors stay zero.  Scaled first, so never over/underflows."""
    m = np.abs(v).max(-1, keepdims=True)
    w = v / np.where(m > 0, m, 1.0)
    n = np.sqrt((w * w).sum(-1, keepdims=True))
    return w / np.where(n > 0, n, 1.0)


def _radial(x: FloatArray, rho: FloatArray) -> FloatArray:
    """Unit radial (xy) direction of ``x``; +x on the axis."""
    return np.where((rho > 0)[..., None], _unit(x * np.array([1.0, 1.0, 0.0])), np.array([1.0, 0.0, 0.0]))


def _stack3(x: ArrayLike, y: ArrayLike, z: ArrayLike) -> FloatArray:
    return np.stack(np.broadcast_arrays(_f64(x), _f64(y), _f64(z)), axis=-1)


def _prep_line(o: ArrayLike, d: ArrayLike, batch_shapes: list[tuple[int, ...]]) -> _Line:
    o = _f64(o)
    d = _f64(d)
    if o.shape[-1:] != (3,) or d.shape[-1:] != (3,):
        raise ValueError(f"o and d must have a trailing dimension of 3, got {o.shape} and {d.shape}")
    shape = np.broadcast_shapes(o.shape[:-1], d.shape[:-1], *batch_shapes)
    o = np.broadcast_to(o, (*shape, 3))
    d = np.broadcast_to(d, (*shape, 3))
    fin = np.isfinite(o).all(-1) & np.isfinite(d).all(-1)
    o = np.where(fin[..., None], o, 0.0)
    d = np.where(fin[..., None], d, 0.0)
    dmax = np.abs(d).max(-1)
    valid = fin & (np.abs(o).max(-1) <= MAX_COORD) & (dmax > 0)
    o = np.where(valid[..., None], o, 0.0)
    d = np.where(valid[..., None], d / np.where(valid, dmax, 1.0)[..., None], np.array([0.0, 0.0, 1.0]))
    d = d / _norm(d)[..., None]
    # Shift to the point closest to the origin (twice: the second pass removes the rounding residue
    # along d), so all later arithmetic is on O(size) numbers even when |o| >> size.
    s0 = -_dot(o, d)
    p0 = o + s0[..., None] * d
    s1 = -_dot(p0, d)
    p0 = p0 + s1[..., None] * d
    rnd = np.abs(o) + np.abs(s0[..., None] * d)
    # Rounding errors ~eps rnd_i along axis i move the line only by their part across it.
    across = _norm(np.eye(3) - d[..., :, None] * d[..., None, :])
    return _Line(d=d, p0=p0, s0=s0 + s1, scale=_dot(rnd, across), rnd=rnd, valid=valid, shape=shape)


def _size(x: ArrayLike, shape: tuple[int, ...], name: str, *, allow_zero: bool = False,
          allow_inf: bool = False) -> FloatArray:
    x = _f64(x)
    ok = np.isfinite(x) & (x >= MIN_SIZE) & (x <= MAX_SIZE)
    if allow_zero:
        ok |= x == 0
    if allow_inf:
        ok |= x == np.inf
    if not np.all(ok):
        raise ValueError(f"{name} must lie in [{MIN_SIZE:g}, {MAX_SIZE:g}] m"
                         + (" or be 0" if allow_zero else "") + (" or inf" if allow_inf else "")
                         + f", got {x[~ok].ravel()[:3]}")
    return np.broadcast_to(x, shape)


def _points(p0: FloatArray, d: FloatArray, t: FloatArray) -> FloatArray:
    """``p0 + t d`` for t of shape (..., K) -> (..., K, 3)."""
    return p0[..., None, :] + t[..., None] * d[..., None, :]


def _ball_roots(u: FloatArray, v: FloatArray, R: ArrayLike, rnd: FloatArray
                ) -> tuple[FloatArray, BoolArray, BoolArray]:
    """Roots of ``|u + t v|^2 = R^2``, sorted, as ``(t (...,2), real, tangent)``.

    Quadratic ``a t^2 + 2 b t + c`` with ``b^2 - a c = a (R - m)(R + m)``, ``m = |u x v|/|v|`` the
    distance of the line from the centre (no cancellation), ``c = (|u| - R)(|u| + R)``, and the
    stable pair ``q = -(b + sign(b) sqrt(b^2 - a c))``, ``t = q/a, c/q``.

    ``|R - m| <= tol`` (tangent within rounding, including a miss by less than ``tol``) gives the
    double root ``-b/a``.  ``tol`` is the first-order effect on ``m`` of rounding errors
    ``eps * rnd_i`` along axis i (in u's units): ``dm = w . du`` with ``w`` the unit vector from the
    centre to the line's closest point (errors along the line or sideways to it do not count).
    """
    R = _f64(R)
    a = _dot(v, v)
    b = _dot(u, v)
    un = _norm(u)
    c = (un - R) * (un + R)
    ok = a > _A_MIN
    a_s = np.where(ok, a, 1.0)
    sa = np.sqrt(a_s)
    m = _norm(np.cross(u, v)) / sa
    w = _unit(u - (b / a_s)[..., None] * v)
    tol = _TOL * (R + un + _dot(rnd, np.abs(w)))
    gap = R - m
    real = ok & (gap >= -tol)
    tangent = real & (gap <= tol)
    sq = sa * np.sqrt(np.maximum(gap, 0.0) * (R + m))
    q = -(b + np.copysign(sq, b))
    double = tangent | (q == 0)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        t1 = np.where(double, -b / a_s, q / a_s)
        t2 = np.where(double, -b / a_s, c / np.where(q == 0, 1.0, q))
    real &= np.isfinite(t1) & np.isfinite(t2)
    t = np.stack([np.minimum(t1, t2), np.maximum(t1, t2)], axis=-1)
    return np.where(real[..., None], t, 0.0), real, tangent


def _clip_interval(lo: FloatArray, hi: FloatArray, tol: FloatArray
                   ) -> tuple[FloatArray, FloatArray, BoolArray, BoolArray]:
    """Non-empty ``[lo, hi]`` within ``tol``; a touch (``lo > hi`` by < tol) collapses to its midpoint."""
    hit = np.isfinite(lo) & np.isfinite(hi) & (lo <= hi + tol)
    lo = np.where(hit, lo, 0.0)
    hi = np.where(hit, hi, 0.0)
    touch = hit & (lo > hi)
    mid = 0.5 * (lo + hi)
    return np.where(touch, mid, lo), np.where(touch, mid, hi), hit, touch


def _pack(L: _Line, t: FloatArray, pts: FloatArray, nrm: FloatArray, hit: BoolArray,
          tangent: BoolArray, edge: BoolArray) -> LineHits:
    hit = hit & L.valid[..., None]
    h3 = hit[..., None]
    nrm = np.where(h3, nrm, 0.0)
    return LineHits(
        s=np.where(hit, L.s0[..., None] + t, 0.0),
        points=np.where(h3, pts, 0.0),
        normals=nrm,
        hit=hit,
        cos_incidence=_dot(nrm, L.d[..., None, :]),
        tangent=tangent & hit,
        edge=edge & hit,
    )


# ------------------------------------------------------------------------------- kinds


def _hits_sphere(L: _Line, r: FloatArray) -> LineHits:
    t, real, tan = _ball_roots(L.p0, L.d, r, L.rnd)
    pts = _points(L.p0, L.d, t)
    hit = np.broadcast_to(real[..., None], t.shape)
    tan2 = np.broadcast_to(tan[..., None], t.shape)
    return _pack(L, t, pts, _unit(pts), hit, tan2, np.zeros_like(hit))


class _CylInterval(NamedTuple):
    side_lo: FloatArray
    side_hi: FloatArray
    cap_lo: FloatArray
    cap_hi: FloatArray
    lo: FloatArray
    hi: FloatArray
    hit: BoolArray
    grazing: BoolArray  # touch, or a chord lying in the side or in a cap plane
    side_tangent: BoolArray
    along_side: BoolArray  # line parallel to the axis on the side surface
    touch: BoolArray  # empty by less than the tolerance, collapsed to a point


def _cyl_interval(L: _Line, r: FloatArray, h: FloatArray, tol: FloatArray) -> _CylInterval:
    """Parameter interval of the closed cylinder: infinite-cylinder interval ∩ slab |z| <= h."""
    p0, d = L.p0, L.d
    xy = np.array([1.0, 1.0, 0.0])
    ts, real_s, tan_s = _ball_roots(p0 * xy, d * xy, r, L.rnd * xy)
    par = d[..., 0] ** 2 + d[..., 1] ** 2 <= _A_MIN
    rho0 = np.hypot(p0[..., 0], p0[..., 1])
    in_side = rho0 <= r + tol
    side_lo = np.where(par, np.where(in_side, -np.inf, np.inf), np.where(real_s, ts[..., 0], np.inf))
    side_hi = np.where(par, np.where(in_side, np.inf, -np.inf), np.where(real_s, ts[..., 1], -np.inf))
    dz = d[..., 2]
    zpar = dz == 0
    dzs = np.where(zpar, 1.0, dz)
    with np.errstate(over="ignore"):  # +-inf is the right slab bound for a near-parallel line
        ta = (-h - p0[..., 2]) / dzs
        tb = (h - p0[..., 2]) / dzs
    in_slab = np.abs(p0[..., 2]) <= h + tol
    cap_lo = np.where(zpar, np.where(in_slab, -np.inf, np.inf), np.minimum(ta, tb))
    cap_hi = np.where(zpar, np.where(in_slab, np.inf, -np.inf), np.maximum(ta, tb))
    lo, hi, hit, touch = _clip_interval(np.maximum(side_lo, cap_lo), np.minimum(side_hi, cap_hi), tol)
    along = par & (np.abs(rho0 - r) <= tol)
    grazing = ((hi - lo) <= tol) | along | (zpar & (np.abs(np.abs(p0[..., 2]) - h) <= tol))
    return _CylInterval(side_lo, side_hi, cap_lo, cap_hi, lo, hi, hit, grazing & hit, tan_s, along & hit,
                        touch)


def _hits_capsule(L: _Line, r: FloatArray, h: FloatArray) -> LineHits:
    p0, d = L.p0, L.d
    tol = _TOL * (r + h + _norm(L.p0) + L.scale)
    # Capsule = closed cylinder ∪ two end balls, all convex with a convex union: its chord is the
    # union of the three chords (entry = earliest entry, exit = latest exit).  No seam tests, so no
    # crossing can be lost to rounding at |z| = h, and a seam crossing is reported once.
    cyl = _cyl_interval(L, r, h, tol)
    # The cylinder's caps are internal here: only its side can be grazed, and a numerical touch of
    # its rim is dropped (the balls contain the rim and give an exact crossing there).
    lo_l, hi_l, ok_l, tan_l = [cyl.lo], [cyl.hi], [cyl.hit & ~cyl.touch], [cyl.along_side | cyl.side_tangent]
    pin_l, pout_l = [p0 + cyl.lo[..., None] * d], [p0 + cyl.hi[..., None] * d]
    for sgn in (1.0, -1.0):
        c = _stack3(0.0, 0.0, sgn * h)
        oc = p0 - c
        sc = -_dot(oc, d)
        w0 = oc + sc[..., None] * d
        tau, real_c, tan_c = _ball_roots(w0, d, r, L.rnd)
        lo_l.append(sc + tau[..., 0])
        hi_l.append(sc + tau[..., 1])
        ok_l.append(real_c)
        tan_l.append(tan_c)
        pin_l.append(c + w0 + tau[..., 0, None] * d)
        pout_l.append(c + w0 + tau[..., 1, None] * d)
    ok = np.stack(ok_l, -1)
    lo_all, hi_all = np.stack(lo_l, -1), np.stack(hi_l, -1)
    i_in = np.argmin(np.where(ok, lo_all, np.inf), -1)[..., None]
    i_out = np.argmax(np.where(ok, hi_all, -np.inf), -1)[..., None]
    any_hit = ok.any(-1)
    t = np.where(any_hit[..., None], np.concatenate(
        [np.take_along_axis(lo_all, i_in, -1), np.take_along_axis(hi_all, i_out, -1)], -1), 0.0)
    pts = np.stack([np.take_along_axis(np.stack(pin_l, -2), i_in[..., None], -2)[..., 0, :],
                    np.take_along_axis(np.stack(pout_l, -2), i_out[..., None], -2)[..., 0, :]], -2)
    tan_all = np.stack(tan_l, -1)
    tan = np.concatenate([np.take_along_axis(tan_all, i_in, -1), np.take_along_axis(tan_all, i_out, -1)], -1)
    # Tangent near the seam: entry and exit may come from different pieces, the side's double root
    # and the ball's clamped one.  A tangency within tol locates its root only to ~sqrt(tol * r),
    # so two tangent roots that close are one double root.
    span = t[..., 1] - t[..., 0]
    touch = (span <= 16.0 * tol) | (tan.all(-1) & (span <= 8.0 * np.sqrt(tol * (r + h))))
    t = np.where(touch[..., None], t[..., :1], t)
    pts = np.where(touch[..., None, None], pts[..., :1, :], pts)
    tan |= touch[..., None]
    axis_pt = pts * np.array([0.0, 0.0, 1.0])
    axis_pt[..., 2] = np.clip(axis_pt[..., 2], -h[..., None], h[..., None])
    nrm = _unit(pts - axis_pt)
    hit = np.broadcast_to(any_hit[..., None], t.shape)
    return _pack(L, t, pts, nrm, hit, tan, np.zeros_like(hit))


def _cyl_slot(L: _Line, t: FloatArray, r: FloatArray, h: FloatArray, etol: FloatArray,
              cap_primary: BoolArray, sgn: float) -> tuple[FloatArray, FloatArray, BoolArray, BoolArray]:
    """Point, normal, edge flag and cap choice for entry (sgn=-1) or exit (sgn=+1) of a cylinder."""
    d = L.d
    x = L.p0 + t[..., None] * d
    rho = np.hypot(x[..., 0], x[..., 1])
    z, dz = x[..., 2], d[..., 2]
    n_side = _unit(x * np.array([1.0, 1.0, 0.0]))
    dn_side = _dot(d, n_side)
    edge = (np.abs(z) >= h - etol) & (rho >= r - etol)
    # At the rim both faces qualify; keep the one the line meets most head-on (largest |d.n|).
    cand_cap = cap_primary | (edge & (sgn * z * dz > 0))
    cand_side = ~cap_primary | (edge & (sgn * dn_side > 0))
    use_cap = cand_cap & (~cand_side | (np.abs(dz) >= np.abs(dn_side)))
    cap_sign = sgn * np.sign(dz)
    nrm = np.where(use_cap[..., None], _stack3(0.0, 0.0, cap_sign), n_side)
    fxy = np.where(use_cap & (rho > r), r / np.where(rho > r, rho, 1.0), 1.0)
    x = _stack3(x[..., 0] * fxy, x[..., 1] * fxy, np.where(use_cap, cap_sign * h, np.clip(z, -h, h)))
    return x, nrm, edge, use_cap


def _hits_cylinder(L: _Line, r: FloatArray, h: FloatArray, edge_tol: float) -> LineHits:
    tol = _TOL * (r + h + _norm(L.p0) + L.scale)
    etol = edge_tol * np.maximum(r, h) + tol
    c = _cyl_interval(L, r, h, tol)
    lo, hi = c.lo, c.hi
    x_in, n_in, e_in, cap_in = _cyl_slot(L, lo, r, h, etol, c.cap_lo >= c.side_lo, -1.0)
    x_out, n_out, e_out, cap_out = _cyl_slot(L, hi, r, h, etol, c.cap_hi <= c.side_hi, 1.0)
    tan = np.stack([c.grazing | (c.side_tangent & ~cap_in), c.grazing | (c.side_tangent & ~cap_out)], -1)
    t = np.stack([lo, hi], -1)
    return _pack(L, t, np.stack([x_in, x_out], -2), np.stack([n_in, n_out], -2),
                 np.broadcast_to(c.hit[..., None], t.shape), tan, np.stack([e_in, e_out], -1))


def _quadric_k(k: ArrayLike) -> FloatArray:
    k = _f64(k)
    if k.shape[-1:] != (3,):
        raise ValueError(f"inverse semi-axes must have a trailing dimension of 3, got {k.shape}")
    ok = np.isfinite(k) & (k >= 0) & (k <= 1.0 / MIN_SIZE)
    if not np.all(ok) or not np.all(k.max(-1) > 0):
        raise ValueError("inverse semi-axes must be finite, >= 0, <= 1/MIN_SIZE, not all 0")
    return k


def _semi_axes_to_k(semi_axes: ArrayLike) -> FloatArray:
    a = _f64(semi_axes)
    if a.shape[-1:] != (3,):
        raise ValueError(f"semi_axes must have a trailing dimension of 3, got {a.shape}")
    _size(a, a.shape, "semi_axes", allow_inf=True)
    if not np.all(np.isfinite(a).any(-1)):
        raise ValueError("at least one semi-axis must be finite")
    return np.where(np.isinf(a), 0.0, 1.0 / a)


def _hits_quadric(L: _Line, k: FloatArray) -> LineHits:
    u = k * L.p0
    v = k * L.d
    t, real, tan = _ball_roots(u, v, 1.0, k * L.rnd)
    pts = _points(L.p0, L.d, t)
    # One Newton step along the line on f = |k x|^2 - 1: p0 + t d rounds small coordinates of x to
    # eps * |t d| (hundreds of ulps of f for thin axes); the correction is tiny, so x + dt d rounds
    # only relative to x.  Skipped near tangency, where it could jump towards the other root.
    kx = k[..., None, :] * pts
    kxn = _norm(kx)
    f = (kxn - 1.0) * (kxn + 1.0)
    fp = 2.0 * _dot(kx, v[..., None, :])
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):  # unused unless finite, below
        dt = -f / fp
    use = np.isfinite(dt) & (np.abs(dt) < 0.25 * (t[..., 1:] - t[..., :1]))
    use &= real[..., None] & ~tan[..., None]
    dt = np.where(use, dt, 0.0)
    t = t + dt
    pts = pts + dt[..., None] * L.d[..., None, :]
    nrm = _unit(k[..., None, :] * (k[..., None, :] * pts))
    hit = np.broadcast_to(real[..., None], t.shape)
    return _pack(L, t, pts, nrm, hit, np.broadcast_to(tan[..., None], t.shape), np.zeros_like(hit))


def _box_slot(L: _Line, t: FloatArray, hs: FloatArray, etol: FloatArray, primary: NDArray[np.intp],
              sgn: float) -> tuple[FloatArray, FloatArray, BoolArray, BoolArray]:
    """Point, normal, edge flag and per-axis 'on face plane' for entry (sgn=-1) / exit (sgn=+1)."""
    d = L.d
    x = L.p0 + t[..., None] * d
    near = np.abs(x) >= hs - etol[..., None]
    onehot = np.arange(3) == primary[..., None]
    # At an edge/corner every face the line passes through qualifies; take the most head-on one.
    cand = onehot | (near & (sgn * x * d > 0))
    face = np.argmax(np.where(cand, np.abs(d), -1.0), -1)
    fsel = np.arange(3) == face[..., None]
    fsign = sgn * np.sign(np.take_along_axis(d, face[..., None], -1))
    nrm = np.where(fsel, fsign, 0.0)
    x = np.where(fsel, fsign * hs, np.clip(x, -hs, hs))
    return x, nrm, near.sum(-1) >= 2, near


def _hits_box(L: _Line, hs: FloatArray, edge_tol: float) -> LineHits:
    p0, d = L.p0, L.d
    hmax = hs.max(-1)
    tol = _TOL * (hmax + _norm(L.p0) + L.scale)
    etol = edge_tol * hmax + tol
    par = d == 0
    ds = np.where(par, 1.0, d)
    with np.errstate(over="ignore"):  # +-inf is the right slab bound for a near-parallel axis
        ta = (-hs - p0) / ds
        tb = (hs - p0) / ds
    inside = np.abs(p0) <= hs + tol[..., None]
    lo_i = np.where(par, np.where(inside, -np.inf, np.inf), np.minimum(ta, tb))
    hi_i = np.where(par, np.where(inside, np.inf, -np.inf), np.maximum(ta, tb))
    lo, hi, hit, _ = _clip_interval(lo_i.max(-1), hi_i.min(-1), tol)
    x_in, n_in, e_in, near_in = _box_slot(L, lo, hs, etol, np.argmax(lo_i, -1), -1.0)
    x_out, n_out, e_out, near_out = _box_slot(L, hi, hs, etol, np.argmin(hi_i, -1), 1.0)
    # Both ends on the same face plane: the chord lies in that face (grazing along it).
    in_face = (near_in & near_out & (np.sign(x_in) == np.sign(x_out))).any(-1)
    grazing = ((hi - lo) <= tol) | in_face
    t = np.stack([lo, hi], -1)
    return _pack(L, t, np.stack([x_in, x_out], -2), np.stack([n_in, n_out], -2),
                 np.broadcast_to(hit[..., None], t.shape), np.stack([grazing, grazing], -1),
                 np.stack([e_in, e_out], -1))


def _hits_plane(L: _Line) -> LineHits:
    dz = L.d[..., 2]
    ok = dz != 0
    with np.errstate(over="ignore", divide="ignore"):  # overflowing s is dropped below
        t = -L.p0[..., 2] / np.where(ok, dz, 1.0)
    hit = ok & np.isfinite(t)
    t = np.where(hit, t, 0.0)[..., None]
    pts = _points(L.p0, L.d, t)
    pts[..., 2] = 0.0
    nrm = np.broadcast_to(np.array([0.0, 0.0, 1.0]), pts.shape)
    tan = (hit & (np.abs(dz) <= _TOL))[..., None]
    return _pack(L, t, pts, nrm, hit[..., None], tan, np.zeros_like(tan))


# ------------------------------------------------------------------------------- public: intersection


def intersect_sphere(o: ArrayLike, d: ArrayLike, radius: ArrayLike) -> LineHits:
    """Crossings of lines ``o + s d`` (local frame, m) with spheres of ``radius`` (m), K = 2."""
    r_in = _f64(radius)
    L = _prep_line(o, d, [r_in.shape])
    return _hits_sphere(L, _size(r_in, L.shape, "radius"))


def intersect_capsule(o: ArrayLike, d: ArrayLike, radius: ArrayLike, half_length: ArrayLike) -> LineHits:
    """Entry/exit of lines with capsules (axis z, segment z in [-h, h], radius r; m), K = 2.

    A crossing exactly on a seam (|z| = h) is reported once; normals are ``(x - seg(x))/r``.
    """
    r_in, h_in = _f64(radius), _f64(half_length)
    L = _prep_line(o, d, [r_in.shape, h_in.shape])
    return _hits_capsule(L, _size(r_in, L.shape, "radius"),
                         _size(h_in, L.shape, "half_length", allow_zero=True))


def intersect_cylinder(o: ArrayLike, d: ArrayLike, radius: ArrayLike, half_length: ArrayLike,
                       edge_tol: float = 1e-9) -> LineHits:
    """Entry/exit of lines with closed cylinders (axis z, caps at z = +-h; m), K = 2.

    Cap normals are +-z, side normals radial.  A crossing within ``edge_tol * max(r, h)`` of a
    rim sets ``edge``; its normal is the cap or side normal the line meets most head-on.
    """
    r_in, h_in = _f64(radius), _f64(half_length)
    L = _prep_line(o, d, [r_in.shape, h_in.shape])
    return _hits_cylinder(L, _size(r_in, L.shape, "radius"), _size(h_in, L.shape, "half_length"), edge_tol)


def intersect_quadric(o: ArrayLike, d: ArrayLike, inv_semi_axes: ArrayLike) -> LineHits:
    """Crossings with the quadric ``|k * x| = 1``, ``k = inv_semi_axes (..., 3) >= 0`` (1/m), K = 2.

    ``k_i = 0`` is an infinite extent (``(1/r, 1/r, 0)``: infinite cylinder; ``(0, 0, 1/t)``:
    slab ``|z| <= t``).  Lines parallel to all infinite axes miss.
    """
    k_in = _quadric_k(inv_semi_axes)
    L = _prep_line(o, d, [k_in.shape[:-1]])
    return _hits_quadric(L, np.broadcast_to(k_in, (*L.shape, 3)))


def intersect_ellipsoid(o: ArrayLike, d: ArrayLike, semi_axes: ArrayLike) -> LineHits:
    """Crossings with ellipsoids of ``semi_axes (..., 3)`` (m, ``inf`` allowed), K = 2."""
    return intersect_quadric(o, d, _semi_axes_to_k(semi_axes))


def intersect_box(o: ArrayLike, d: ArrayLike, half_sizes: ArrayLike, edge_tol: float = 1e-9) -> LineHits:
    """Entry/exit of lines with boxes of ``half_sizes (..., 3)`` (m), slab method, K = 2.

    Normals are face normals.  A crossing within ``edge_tol * max(h)`` of another face plane sets
    ``edge``; its normal is that of the face the line meets most head-on (largest ``|d_i|``,
    lowest axis on ties).  A line lying in a face plane hits with ``tangent = True``.
    """
    h_in = _f64(half_sizes)
    if h_in.shape[-1:] != (3,):
        raise ValueError(f"half_sizes must have a trailing dimension of 3, got {h_in.shape}")
    L = _prep_line(o, d, [h_in.shape[:-1]])
    return _hits_box(L, _size(h_in, (*L.shape, 3), "half_sizes"), edge_tol)


def intersect_plane(o: ArrayLike, d: ArrayLike) -> LineHits:
    """Crossing with the plane z = 0 (normal +z), K = 1; lines parallel to it miss."""
    return _hits_plane(_prep_line(o, d, []))


def _kind(kind: str | int) -> str:
    if isinstance(kind, (int, np.integer)) and int(kind) in _MJ_GEOM:
        return _MJ_GEOM[int(kind)]
    k = str(kind).lower()
    if k not in KINDS:
        raise ValueError(f"unknown primitive kind {kind!r}; expected one of {KINDS}")
    return k


def _split_size(kind: str, size: ArrayLike) -> list[FloatArray]:
    n = _N_SIZE[kind]
    if n == 0:
        return []
    size = _f64(size)
    if size.ndim == 0 and n == 1:
        size = size[None]
    # The trailing axis is the size vector: n entries or a MuJoCo geom_size row of 3 (so P sphere
    # radii must be passed as (P, 1), not (P,), which would read as one size vector).
    if size.ndim == 0 or size.shape[-1] not in (n, 3):
        raise ValueError(f"{kind} size needs a trailing dimension of {n} or 3, got shape {size.shape}")
    if n == 3:
        return [size[..., :3]]
    return [size[..., i] for i in range(n)]


def _prep_kind(kind: str, size: ArrayLike, o: ArrayLike, d: ArrayLike
               ) -> tuple[_Line, list[FloatArray]]:
    parts = _split_size(kind, size)
    if kind in ("ellipsoid", "box"):
        L = _prep_line(o, d, [parts[0].shape[:-1]])
        if kind == "ellipsoid":
            return L, [np.broadcast_to(_semi_axes_to_k(parts[0]), (*L.shape, 3))]
        return L, [_size(parts[0], (*L.shape, 3), "half_sizes")]
    L = _prep_line(o, d, [p.shape for p in parts])
    if kind == "sphere":
        return L, [_size(parts[0], L.shape, "radius")]
    if kind in ("capsule", "cylinder"):
        return L, [_size(parts[0], L.shape, "radius"),
                   _size(parts[1], L.shape, "half_length", allow_zero=kind == "capsule")]
    return L, []


def _hits(kind: str, L: _Line, sz: list[FloatArray], edge_tol: float) -> LineHits:
    if kind == "sphere":
        return _hits_sphere(L, *sz)
    if kind == "capsule":
        return _hits_capsule(L, *sz)
    if kind == "cylinder":
        return _hits_cylinder(L, *sz, edge_tol)
    if kind == "ellipsoid":
        return _hits_quadric(L, *sz)
    if kind == "box":
        return _hits_box(L, *sz, edge_tol)
    return _hits_plane(L)


def intersect(kind: str | int, size: ArrayLike, o: ArrayLike, d: ArrayLike,
              edge_tol: float = 1e-9) -> LineHits:
    """Dispatch on ``kind`` (name or MuJoCo ``mjtGeom`` int) with a MuJoCo ``geom_size``-style ``size``.

    ``size (..., n)`` with n = 1 (sphere: r), 2 (capsule, cylinder: r, h) or 3 (ellipsoid, box), or
    a MuJoCo ``geom_size`` row ``(..., 3)`` whose first n entries are used; a scalar is fine for a
    sphere; ignored for a plane.  Sizes broadcast against the lines' leading dimensions.  Returns
    :class:`LineHits` with K = ``N_CROSSINGS[kind]`` (slot 0 entry, slot 1 exit).
    """
    k = _kind(kind)
    L, sz = _prep_kind(k, size, o, d)
    return _hits(k, L, sz, edge_tol)


# ------------------------------------------------------------------------------- distances


def _sd_quadric_nd(y: FloatArray, k: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Signed distance, nearest point and normal of points ``y (..., n)`` to ``|k * x| = 1``.

    Nearest point ``x_i = y_i / f_i`` with ``f_i = 1 + lam k_i^2`` and the Lagrange multiplier
    ``lam`` the root of ``F = sum (k_i y_i / f_i)^2 - 1`` (decreasing in lam).  It is found by
    geometric bisection on ``w = 1 + lam kmax^2`` (``f_i = (1 - rho_i) + w rho_i``, ``rho_i =
    (k_i/kmax)^2``, a sum of non-negative terms, so each f_i keeps full relative precision):
    ``w in [kmax |y_top|, 1]`` inside, ``[1, 1 + kmax^2 lam_hi]`` outside (Eberly's robust scheme).
    Inside with ``y = 0`` on every largest-k axis the nearest point may lie off-axis (closed form).
    """
    y, k = np.broadcast_arrays(y, k)
    ay = np.abs(y)
    kmax = k.max(-1, keepdims=True)
    # Points within 1e-100 semi-axes of the centre move out radially to that distance (far below any
    # rounding of the result), so the bisection never sees subnormal numbers.
    m = ay.max(-1, keepdims=True) * kmax
    ay = np.where((m > 0) & (m < 1e-100), ay * (1e-100 / np.where(m > 0, m, 1.0)), ay)
    rho = (k / kmax) ** 2
    omr = (kmax - k) * (kmax + k) / kmax**2  # 1 - rho without cancellation
    ky = k * ay
    kyn = _norm(ky)
    g = (kyn - 1.0) * (kyn + 1.0)
    out = g > 0
    inn = g < 0
    top = k == kmax
    ytop = np.where(top, ay, 0.0).max(-1)
    pos = k > 0
    lam_hi = np.minimum(_dot(ay, ay) / 4.0, _norm(np.where(pos, ay / np.where(pos, k, 1.0), 0.0)))
    kmax1 = kmax[..., 0]
    # F(kmax |y_top|) >= 0 (its top term alone is 1); 5e-324 only guards ytop = 0.
    lo = np.where(out, 1.0, np.maximum(kmax1 * ytop, 5e-324))
    hi = np.where(out, 1.0 + kmax1**2 * lam_hi, 1.0)
    hi = np.maximum(hi, lo)
    for _ in range(_BISECT_ITERS):
        mid = np.sqrt(lo) * np.sqrt(hi)
        f = omr + mid[..., None] * rho
        F = _dot(ky / f, ky / f) - 1.0
        up = F > 0
        lo = np.where(up, mid, lo)
        hi = np.where(up, hi, mid)
    w = np.where(out | inn, np.sqrt(lo) * np.sqrt(hi), 1.0)
    f = omr + w[..., None] * rho
    x = ay / f
    diff = ay * ((w[..., None] - 1.0) * rho) / f
    # Inside, on (or within 1e-100 semi-axes of) the mid-plane(s) of the smallest semi-axis: the
    # nearest point is off-axis when G <= 0, in closed form (else the bisection root above is right).
    nt = ~top
    ratio = np.where(nt, ky / np.where(nt, omr, 1.0), 0.0)
    G = _dot(ratio, ratio) - 1.0
    special = inn & (kmax1 * ytop <= 1e-100) & (G <= 0)
    first_top = np.arange(k.shape[-1]) == np.argmax(np.where(top, ay, -1.0), -1)[..., None]
    x_top = np.where(first_top, np.sqrt(np.maximum(-G, 0.0))[..., None] / kmax, 0.0)
    xs = np.where(nt, ay / np.where(nt, omr, 1.0), x_top)
    x = np.where(special[..., None], xs, x)
    diff = np.where(special[..., None], ay - xs, diff)
    sgn = np.where(y < 0, -1.0, 1.0)
    x = sgn * x
    dist = np.where(out, 1.0, -1.0) * _norm(diff)
    dist = np.where(out | inn, dist, 0.0)
    x = np.where((out | inn)[..., None], x, y)
    return dist, x, _unit(k * (k * x))


def _prep_points(points: ArrayLike, batch_shapes: list[tuple[int, ...]]
                 ) -> tuple[FloatArray, BoolArray, tuple[int, ...]]:
    p = _f64(points)
    if p.shape[-1:] != (3,):
        raise ValueError(f"points must have a trailing dimension of 3, got {p.shape}")
    shape = np.broadcast_shapes(p.shape[:-1], *batch_shapes)
    p = np.broadcast_to(p, (*shape, 3))
    fin = np.isfinite(p).all(-1)
    p = np.where(fin[..., None], p, 0.0)
    valid = fin & (np.abs(p).max(-1) <= MAX_COORD)
    return np.where(valid[..., None], p, 0.0), valid, shape


def _sd(kind: str, x: FloatArray, sz: list[FloatArray]) -> tuple[FloatArray, FloatArray, FloatArray]:
    ez = np.array([0.0, 0.0, 1.0])
    if kind == "sphere":
        (r,) = sz
        n = _norm(x)
        nrm = np.where((n > 0)[..., None], _unit(x), ez)
        return n - r, r[..., None] * nrm, nrm
    if kind == "capsule":
        r, h = sz
        c = x * ez
        c[..., 2] = np.clip(c[..., 2], -h, h)
        v = x - c
        n = _norm(v)
        nrm = np.where((n > 0)[..., None], _unit(v), np.array([1.0, 0.0, 0.0]))
        return n - r, c + r[..., None] * nrm, nrm
    if kind == "cylinder":
        r, h = sz
        rho = np.hypot(x[..., 0], x[..., 1])
        az = np.abs(x[..., 2])
        e_side, e_cap = rho - r, az - h
        radial = _radial(x, rho)
        zs = np.where(x[..., 2] < 0, -1.0, 1.0)
        proj = radial * np.minimum(rho, r)[..., None] + ez * (zs * np.minimum(az, h))[..., None]
        outside = (e_side > 0) | (e_cap > 0)
        # x - proj from the two excesses: exact direction (pure radial / pure axial off the rim),
        # whereas subtracting coordinates leaves rounding noise as large as a tiny offset.
        diff = radial * np.maximum(e_side, 0.0)[..., None] + ez * (zs * np.maximum(e_cap, 0.0))[..., None]
        dout = _norm(diff)
        use_cap = e_cap >= e_side
        n_face = np.where(use_cap[..., None], ez * zs[..., None], radial)
        c_face = np.where(use_cap[..., None], _stack3(x[..., 0], x[..., 1], zs * h),
                          radial * r[..., None] + ez * x[..., 2:3])
        nrm = np.where(outside[..., None], _unit(diff), n_face)
        return (np.where(outside, dout, np.maximum(e_side, e_cap)),
                np.where(outside[..., None], proj, c_face), nrm)
    if kind == "box":
        (hs,) = sz
        q = np.abs(x) - hs
        outside = (q > 0).any(-1)
        proj = np.clip(x, -hs, hs)
        diff = x - proj
        face = np.argmax(q, -1)
        fsel = np.arange(3) == face[..., None]
        xs = np.where(x < 0, -1.0, 1.0)
        n_face = np.where(fsel, xs, 0.0)
        c_face = np.where(fsel, xs * hs, x)
        nrm = np.where(outside[..., None], _unit(diff), n_face)
        return (np.where(outside, _norm(diff), q.max(-1)), np.where(outside[..., None], proj, c_face), nrm)
    if kind == "ellipsoid":
        (k,) = sz
        return _sd_quadric_nd(x, k)
    c = x.copy()
    c[..., 2] = 0.0
    return x[..., 2], c, np.broadcast_to(ez, x.shape)


def _prep_kind_points(kind: str, size: ArrayLike, points: ArrayLike
                      ) -> tuple[FloatArray, BoolArray, list[FloatArray]]:
    parts = _split_size(kind, size)
    if kind in ("ellipsoid", "box"):
        x, valid, shape = _prep_points(points, [parts[0].shape[:-1]])
        if kind == "ellipsoid":
            return x, valid, [np.broadcast_to(_semi_axes_to_k(parts[0]), (*shape, 3))]
        return x, valid, [_size(parts[0], (*shape, 3), "half_sizes")]
    x, valid, shape = _prep_points(points, [p.shape for p in parts])
    if kind == "sphere":
        return x, valid, [_size(parts[0], shape, "radius")]
    if kind in ("capsule", "cylinder"):
        return x, valid, [_size(parts[0], shape, "radius"),
                          _size(parts[1], shape, "half_length", allow_zero=kind == "capsule")]
    return x, valid, []


def signed_distance(kind: str | int, size: ArrayLike, points: ArrayLike) -> SurfaceDistance:
    """Signed distance (m, negative inside), nearest surface point and outward normal, ``points (..., 3)``.

    Exact closed forms except the ellipsoid (66-step geometric bisection on the Lagrange multiplier,
    converged to rounding).  For interior points of box/cylinder the nearest face is used (ties: the
    lowest box axis; cylinder ties go to the cap).
    """
    k = _kind(kind)
    x, valid, sz = _prep_kind_points(k, size, points)
    dist, c, n = _sd(k, x, sz)
    v3 = valid[..., None]
    return SurfaceDistance(np.where(valid, dist, 0.0), np.where(v3, c, 0.0), np.where(v3, n, 0.0), valid)


def inside(kind: str | int, size: ArrayLike, points: ArrayLike, tol: float = 0.0) -> BoolArray:
    """True where a point lies inside the solid deeper than ``tol`` (m); invalid points give False."""
    sd = signed_distance(kind, size, points)
    return sd.valid & (sd.distance < -tol)


def surface_normal(kind: str | int, size: ArrayLike, points: ArrayLike) -> FloatArray:
    """Outward unit normal at surface ``points (..., 3)`` (local frame); zeros for invalid points.

    Closed-form gradient, no projection: sphere ``x/|x|``, capsule ``(x - seg(x))/|.|``, plane +z,
    ellipsoid ``k^2 x / |k^2 x|``; box: normal of the face with the largest ``|x_i| - h_i`` (lowest
    axis on ties); cylinder: cap if ``|z| - h >= rho - r`` else radial.  For points off the surface
    use :func:`signed_distance` (normal at the nearest point).
    """
    k = _kind(kind)
    x, valid, sz = _prep_kind_points(k, size, points)
    if k == "ellipsoid":
        n = _unit(sz[0] * (sz[0] * x))
    elif k in ("box", "cylinder"):
        # Face attribution as for interior points, valid on the surface and outside a face too.
        if k == "box":
            q = np.abs(x) - sz[0]
            n = np.where(np.arange(3) == np.argmax(q, -1)[..., None], np.where(x < 0, -1.0, 1.0), 0.0)
        else:
            r, h = sz
            rho = np.hypot(x[..., 0], x[..., 1])
            radial = _radial(x, rho)
            cap = _stack3(0.0, 0.0, np.where(x[..., 2] < 0, -1.0, 1.0))
            n = np.where((np.abs(x[..., 2]) - h >= rho - r)[..., None], cap, radial)
    else:
        n = _sd(k, x, sz)[2]
    return np.where(valid[..., None], n, 0.0)


# ------------------------------------------------------------------------------- closest point to a line


def _closest_capsule(L: _Line, r: FloatArray, h: FloatArray) -> tuple[FloatArray, ...]:
    p0, d = L.p0, L.d
    a = d[..., 0] ** 2 + d[..., 1] ** 2  # |P e_z|^2 = 1 - dz^2 without cancellation
    # Segment point zc e_z minimising the (convex) line distance; its nearest line point is t = zc dz.
    zc = np.clip(np.where(a > _A_MIN, p0[..., 2] / np.where(a > _A_MIN, a, 1.0), 0.0), -h, h)
    t = zc * d[..., 2]
    lp = p0 + t[..., None] * d
    v = lp - _stack3(0.0, 0.0, zc)
    n = _norm(v)
    nrm = np.where((n > 0)[..., None], _unit(v), np.array([1.0, 0.0, 0.0]))
    return _stack3(0.0, 0.0, zc) + r[..., None] * nrm, nrm, n - r, t


def _closest_bisect(L: _Line, kind: str, sz: list[FloatArray], radius: FloatArray) -> tuple[FloatArray, ...]:
    """Convex 1-D problem: ``g(t) = dist(p0 + t d, solid)^2`` has the non-decreasing derivative
    ``2 (x - proj(x)) . d``; bisect its sign change over ``|t| <= T = |p0| + 2 radius`` (58 halvings:
    width < eps T / 30; g is flat at its minimum, so the distance is exact to rounding)."""
    p0, d = L.p0, L.d
    T = _norm(p0) + 2.0 * radius
    lo, hi = -T, T.copy()
    for _ in range(_LINE_BISECT_ITERS):
        mid = 0.5 * (lo + hi)
        x = p0 + mid[..., None] * d
        _, c, _ = _sd(kind, x, sz)
        up = _dot(x - c, d) > 0
        hi = np.where(up, mid, hi)
        lo = np.where(up, lo, mid)
    t = 0.5 * (lo + hi)
    x = p0 + t[..., None] * d
    dist, c, nrm = _sd(kind, x, sz)
    return c, nrm, np.maximum(dist, 0.0), t


def _onb(d: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Orthonormal e1, e2 with e1 x e2 = d (Duff et al. 2017, branch-free)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    sg = np.where(z >= 0, 1.0, -1.0)
    a = -1.0 / (sg + z)
    b = x * y * a
    return _stack3(1.0 + sg * x * x * a, sg * b, -sg * x), _stack3(b, sg + y * y * a, -y)


def _closest_quadric(L: _Line, k: FloatArray) -> tuple[FloatArray, ...]:
    p0, d = L.p0, L.d
    pos = k > 0
    a = np.where(pos, 1.0 / np.where(pos, k, 1.0), 0.0)  # semi-axes, 0 standing for infinite
    n_inf = (~pos).sum(-1)
    par = _dot(k * d, k * d) <= _A_MIN

    # (P) line along the infinite axes: its nearest point to the quadric is p0 itself.
    dist_p, pt_p, n_p = _sd_quadric_nd(p0, k)
    dist_p = np.abs(dist_p)  # a line inside an unbounded solid: report its distance to the surface
    t_p = np.zeros(L.shape)

    # (C) one infinite axis e_j: project along e_j and d; the gap is |p0.n| - support(n), n ~ d x e_j.
    j = np.argmin(k, -1)
    ej = (np.arange(3) == j[..., None]).astype(np.float64)
    cr = np.cross(d, ej)
    crn2 = _dot(cr, cr)
    n1 = _unit(cr)
    sp = _dot(p0, n1)
    n1 = n1 * np.where(sp >= 0, 1.0, -1.0)[..., None]
    an = a * n1
    hsup = _norm(an)
    x_perp = a * an / np.where(hsup > 0, hsup, 1.0)[..., None]
    dist_c = np.abs(sp) - hsup
    w = p0 - x_perp - dist_c[..., None] * n1
    dj = np.take_along_axis(d, j[..., None], -1)[..., 0]
    wj = np.take_along_axis(w, j[..., None], -1)[..., 0]
    t_c = (dj * wj - _dot(w, d)) / np.where(crn2 > 0, crn2, 1.0)
    pt_c = x_perp + ((wj + t_c * dj)[..., None]) * ej

    # (F) finite ellipsoid: project along d onto the plane (e1, e2); the shadow is an ellipse with
    # shape Q = B^T diag(a^2) B.  det Q by Cauchy-Binet (sum of squares, no cancellation).
    e1, e2 = _onb(d)
    a2 = a * a
    q11, q12, q22 = _dot(a2, e1 * e1), _dot(a2, e1 * e2), _dot(a2, e2 * e2)
    det = (a2[..., 0] * a2[..., 1] * d[..., 2] ** 2 + a2[..., 0] * a2[..., 2] * d[..., 1] ** 2
           + a2[..., 1] * a2[..., 2] * d[..., 0] ** 2)
    lam_big = 0.5 * (q11 + q22 + np.hypot(q11 - q22, 2.0 * q12))
    lam_big = np.where(lam_big > 0, lam_big, 1.0)
    lam_small = np.where(det > 0, det / lam_big, lam_big)
    th = 0.5 * np.arctan2(2.0 * q12, q11 - q22)
    cs, sn = np.cos(th), np.sin(th)
    y1, y2 = _dot(p0, e1), _dot(p0, e2)
    yr = np.stack([cs * y1 + sn * y2, -sn * y1 + cs * y2], -1)
    k2 = np.stack([1.0 / np.sqrt(lam_big), 1.0 / np.sqrt(lam_small)], -1)
    dist_f, _, n2r = _sd_quadric_nd(yr, k2)
    n2a = cs * n2r[..., 0] - sn * n2r[..., 1]
    n2b = sn * n2r[..., 0] + cs * n2r[..., 1]
    n3 = _unit(n2a[..., None] * e1 + n2b[..., None] * e2)
    an3 = a * n3
    pt_f = a * an3 / np.where(_norm(an3) > 0, _norm(an3), 1.0)[..., None]
    t_f = _dot(pt_f - p0, d)

    use_c = (n_inf == 1) & ~par
    use_f = (n_inf == 0) & ~par
    pt = np.where(use_f[..., None], pt_f, np.where(use_c[..., None], pt_c, pt_p))
    dist = np.where(use_f, dist_f, np.where(use_c, dist_c, dist_p))
    t = np.where(use_f, t_f, np.where(use_c, t_c, t_p))
    nrm = np.where(par[..., None], n_p, _unit(k * (k * pt)))
    return pt, nrm, dist, t


def _closest_miss(kind: str, L: _Line, sz: list[FloatArray]) -> tuple[FloatArray, ...]:
    """Nearest surface point, normal, distance and line parameter (from p0) for lines that miss."""
    if kind == "sphere":
        (r,) = sz
        n = _norm(L.p0)
        nrm = np.where((n > 0)[..., None], _unit(L.p0), np.array([0.0, 0.0, 1.0]))
        return r[..., None] * nrm, nrm, n - r, np.zeros(L.shape)
    if kind == "capsule":
        return _closest_capsule(L, *sz)
    if kind == "cylinder":
        return _closest_bisect(L, kind, sz, np.hypot(*sz))
    if kind == "box":
        return _closest_bisect(L, kind, sz, _norm(sz[0]))
    if kind == "ellipsoid":
        return _closest_quadric(L, *sz)
    pt = L.p0 * np.array([1.0, 1.0, 0.0])
    return pt, np.broadcast_to(np.array([0.0, 0.0, 1.0]), pt.shape), np.abs(L.p0[..., 2]), np.zeros(L.shape)


def closest_point_on_surface_to_line(kind: str | int, size: ArrayLike, o: ArrayLike, d: ArrayLike
                                     ) -> LineClosest:
    """Surface point nearest to each line ``o + s d`` (local frame, m), vectorised like :func:`intersect`.

    Lines that hit give distance 0 and the entry crossing.  Misses: closed form for sphere, capsule,
    plane, and ellipsoids with an infinite axis; finite ellipsoid: exact projection along ``d`` onto
    a 2-D ellipse, then the 66-step bisection of :func:`signed_distance`; cylinder and box: bisection
    of the convex line-to-solid distance (58 halvings, converged to rounding; the cylinder's rim
    case is a quartic, hence no closed form).  ``s`` is the line parameter of the nearest line point.
    """
    kn = _kind(kind)
    L, sz = _prep_kind(kn, size, o, d)
    hits = _hits(kn, L, sz, 1e-9)
    # Only the valid misses need the (iterative for some kinds) nearest-point computation.
    miss = np.nonzero((L.valid & ~hits.hit[..., 0]).ravel())[0]
    n_all = int(np.prod(L.shape))
    Lm = _Line(d=L.d.reshape(-1, 3)[miss], p0=L.p0.reshape(-1, 3)[miss], s0=L.s0.reshape(-1)[miss],
               scale=L.scale.reshape(-1)[miss], rnd=L.rnd.reshape(-1, 3)[miss],
               valid=L.valid.reshape(-1)[miss], shape=(miss.size,))
    szm = [np.reshape(x, (n_all, *x.shape[len(L.shape):]))[miss] for x in sz]
    pt_m, nrm_m, dist_m, t_m = _closest_miss(kn, Lm, szm)
    pt, nrm = np.zeros((n_all, 3)), np.zeros((n_all, 3))
    dist, t = np.zeros(n_all), np.zeros(n_all)
    pt[miss], nrm[miss], dist[miss], t[miss] = pt_m, nrm_m, np.abs(dist_m), t_m
    pt, nrm = pt.reshape(*L.shape, 3), nrm.reshape(*L.shape, 3)
    dist, t = dist.reshape(L.shape), t.reshape(L.shape)
    h = hits.hit[..., 0]
    h3 = h[..., None]
    v, v3 = L.valid, L.valid[..., None]
    return LineClosest(
        point=np.where(v3, np.where(h3, hits.points[..., 0, :], pt), 0.0),
        normal=np.where(v3, np.where(h3, hits.normals[..., 0, :], nrm), 0.0),
        distance=dist,
        s=np.where(v, np.where(h, hits.s[..., 0], L.s0 + t), 0.0),
        hit=h,
        valid=v,
    )
