"""Points sampled uniformly (by area) on the touchable surfaces of an arm, for scenarios and benchmarks."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .arm import ArmModel, PosedSurface


@dataclass(frozen=True)
class SurfacePoint:
    link: str
    geom: str
    point: np.ndarray  # m, base frame
    normal: np.ndarray  # outward unit normal, base frame


def _area(kind: str, size: np.ndarray) -> float:
    r, h = size[0], size[1]
    if kind == "sphere":
        return 4 * np.pi * r * r
    if kind == "capsule":
        return 4 * np.pi * r * r + 2 * np.pi * r * 2 * h
    if kind == "cylinder":
        return 2 * np.pi * r * r + 2 * np.pi * r * 2 * h
    if kind == "box":
        x, y, z = size
        return 8 * (x * y + y * z + x * z)
    if kind == "ellipsoid":
        a, b, c = size  # Knud Thomsen's approximation, within 1.1 %: only weights the sampling
        p = 1.6075
        return 4 * np.pi * (((a * b) ** p + (a * c) ** p + (b * c) ** p) / 3) ** (1 / p)
    return 0.0  # planes are infinite: never sampled


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def sample_local(kind: str, size: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One point uniform by area on a primitive (local frame), with its outward normal."""
    r, h = size[0], size[1]
    if kind == "sphere":
        n = _unit(rng)
        return r * n, n
    if kind in ("capsule", "cylinder"):
        side = 2 * np.pi * r * 2 * h
        ends = 4 * np.pi * r * r if kind == "capsule" else 2 * np.pi * r * r
        if rng.uniform() * (side + ends) < side:
            phi = rng.uniform(0, 2 * np.pi)
            n = np.array([np.cos(phi), np.sin(phi), 0.0])
            return np.array([r * n[0], r * n[1], rng.uniform(-h, h)]), n
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        if kind == "capsule":
            n = _unit(rng)
            n[2] = sign * abs(n[2])
            return n * r + np.array([0, 0, sign * h]), n
        rho, phi = r * np.sqrt(rng.uniform()), rng.uniform(0, 2 * np.pi)
        return np.array([rho * np.cos(phi), rho * np.sin(phi), sign * h]), np.array([0, 0, sign])
    if kind == "box":
        areas = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]])
        axis = rng.choice(3, p=areas / areas.sum())
        p = rng.uniform(-1, 1, 3) * size
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        p[axis] = sign * size[axis]
        n = np.zeros(3)
        n[axis] = sign
        return p, n
    if kind == "ellipsoid":
        a, b, c = size
        gmax = max(b * c, a * c, a * b)
        while True:  # area element of the map from the unit sphere: |(bc u1, ac u2, ab u3)|
            u = _unit(rng)
            g = np.linalg.norm([b * c * u[0], a * c * u[1], a * b * u[2]])
            if rng.uniform() * gmax <= g:
                p = u * size
                n = p / size**2
                return p, n / np.linalg.norm(n)
    raise ValueError(f"cannot sample a {kind} surface")


def sample_surface_points(model: ArmModel, q, n: int, rng: np.random.Generator,
                          hidden=None) -> list[SurfacePoint]:
    """n points uniform by area on the touchable surfaces at joint angles q.

    ``hidden(point, normal, posed_surface) -> bool`` (base frame) rejects points that are not on the
    arm's outer surface (inside another primitive); by default every point of every primitive is kept.
    """
    posed: list[PosedSurface] = model.posed_surfaces(q)
    areas = np.array([_area(p.surface.kind, p.surface.size) for p in posed])
    if areas.sum() <= 0:
        raise ValueError("the scene has no finite touchable surface to sample")
    out: list[SurfacePoint] = []
    while len(out) < n:
        k = rng.choice(len(posed), p=areas / areas.sum())
        ps = posed[k]
        p_loc, n_loc = sample_local(ps.surface.kind, ps.surface.size, rng)
        rot, t = ps.base_T_geom[:3, :3], ps.base_T_geom[:3, 3]
        point = rot @ p_loc + t
        normal = rot @ n_loc
        if hidden is not None and hidden(point, normal, ps):
            continue
        out.append(SurfacePoint(ps.surface.link, ps.surface.geom, point, normal))
    return out
