"""Where a scripted contact may touch the arm: visible surface points and forces pushing into them."""
from __future__ import annotations

import math

import numpy as np

from ftc_hw.geometry.kinds import KINDS
from ftc_hw.geometry.solid import inside_local
from ftc_hw.model import ArmModel
from ftc_hw.model.arm import GEOM_KINDS, SURFACE_GROUP, pose
from ftc_hw.model.sampling import SurfacePoint, sample_surface_points
from ftc_hw.scene import Scene

from .world import Probe


def poke_force_limit(scene: Scene) -> float:
    """Largest poke (N): a fifth of a base F/T sensor's smallest force range, at most 100 N (a flange
    sensor does not carry the arm's pokes: 100 N)."""
    s = scene.sensor
    return float(min(100.0, 0.2 * s.range[:3].min())) if s is not None and s.mount == "base" else 100.0


def random_pokes(model: ArmModel, q, rng: np.random.Generator, count: int, t0: float = 0.2,
                 period: float = 0.5, f_min: float = 5.0, f_max: float | None = None,
                 max_angle_deg: float = 45.0) -> tuple[Probe, ...]:
    """Pokes at points uniform on the touchable surfaces, pushing into the surface within a cone."""
    f_max = f_max or poke_force_limit(model.scene)
    points = sample_surface_points(model, q, count, rng, hidden=visible_filter(model, q))
    links = model.kinematics(q)
    probes = []
    for i, sp in enumerate(points):
        direction = _cone(-sp.normal, math.radians(max_angle_deg), rng)
        base_T_link = links[sp.link]
        point_link = base_T_link[:3, :3].T @ (sp.point - base_T_link[:3, 3])
        normal_link = base_T_link[:3, :3].T @ sp.normal
        probes.append(Probe(sp.link, point_link, direction, float(rng.uniform(f_min, f_max)), t0 + i * period,
                            normal_link=normal_link, geom=sp.geom))
    return tuple(probes)


def sample_contacts(model: ArmModel, q, n: int, rng: np.random.Generator, max_angle_deg: float,
                    f_range: tuple[float, float]) -> list[tuple[SurfacePoint, np.ndarray]]:
    """(surface point, force applied to the arm) pairs: points uniform on the visible touchable
    surfaces, forces pushing in within a cone about the inward normal, magnitudes uniform in f_range."""
    points = sample_surface_points(model, q, n, rng, hidden=visible_filter(model, q))
    return [(sp, _cone(-sp.normal, math.radians(max_angle_deg), rng) * rng.uniform(*f_range)) for sp in points]


def visible_filter(model: ArmModel, q, eps: float = 1e-8):
    """A ``hidden(point, normal, posed_surface)`` predicate: true when the point is not on the arm's
    outer surface, by the solver's own rule (the point just outside it lies inside another geom)."""
    others = all_arm_geoms(model, q)

    def hidden(point: np.ndarray, normal: np.ndarray, ps) -> bool:
        y = point + eps * normal
        for name, kind, size, b_T_g in others:
            if name == ps.surface.geom:
                continue
            local = b_T_g[:3, :3].T @ (y - b_T_g[:3, 3])
            if inside_local(KINDS[kind], size, local, 0.0):
                return True
        return False

    return hidden


def all_arm_geoms(model: ArmModel, q):
    """Every group-1 primitive of the arm (touchable or not) with its pose: what can hide a point."""
    model.kinematics(q)
    m, d = model.model, model.data
    out = []
    for g in range(m.ngeom):
        kind = GEOM_KINDS.get(int(m.geom_type[g]))
        if m.geom_group[g] != SURFACE_GROUP or kind is None:
            continue
        out.append((m.geom(g).name, kind, m.geom_size[g].copy(), pose(d.geom_xmat[g].reshape(3, 3), d.geom_xpos[g])))
    return out


def _cone(axis: np.ndarray, max_angle: float, rng: np.random.Generator) -> np.ndarray:
    """A unit vector within ``max_angle`` of ``axis`` (uniform over the cone's solid angle)."""
    axis = axis / np.linalg.norm(axis)
    cos_a = rng.uniform(math.cos(max_angle), 1.0)
    phi = rng.uniform(0.0, 2 * math.pi)
    helper = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    sin_a = math.sqrt(max(0.0, 1 - cos_a * cos_a))
    return cos_a * axis + sin_a * (math.cos(phi) * u + math.sin(phi) * v)
