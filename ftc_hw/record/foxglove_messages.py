"""Foxglove's well-known messages (``foxglove.FrameTransforms``, ``foxglove.SceneUpdate``) as the JSON
that Foxglove reads, built from the arm's poses, its surfaces, contact events and wrenches.

The schemas are Foxglove's own JSON Schemas, unchanged (``foxglove_schemas/``: their source and
licence are in ``SOURCE.md`` there). Field names, ``{"sec", "nsec"}`` times, ``{"x", "y", "z", "w"}``
quaternions (scalar last, unlike MuJoCo's) and every field present (the schemas require all) are
theirs. Floats are Python floats: ``json.dumps`` takes no numpy scalars.
"""
from __future__ import annotations

import json
import math
from functools import cache
from importlib import resources
from typing import Any

import mujoco
import numpy as np

from ftc_hw.bus import ContactEvent
from ftc_hw.model import Surface

FRAME_TRANSFORMS = "foxglove.FrameTransforms"
SCENE_UPDATE = "foxglove.SceneUpdate"
K95_3D = math.sqrt(7.814727903251178)  # chi-square, 3 dof, p = 0.95: a 3-D Gaussian's 95 % ellipsoid

Json = dict[str, Any]


@cache
def foxglove_schema(name: str) -> Json:
    """The JSON Schema of ``foxglove.<Name>`` (as shipped in ``foxglove_schemas/<Name>.json``)."""
    text = resources.files("ftc_hw.record").joinpath("foxglove_schemas", f"{name.split('.')[-1]}.json")
    return json.loads(text.read_text(encoding="utf-8"))


def stamp(t_ns: int) -> Json:
    t = int(t_ns)
    return {"sec": t // 1_000_000_000, "nsec": t % 1_000_000_000}


def duration(seconds: float) -> Json:
    return stamp(round(seconds * 1e9))


def vec3(v) -> Json:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def quat_wxyz(q) -> Json:
    """A MuJoCo quaternion (w, x, y, z) as Foxglove's (x, y, z, w)."""
    return {"x": float(q[1]), "y": float(q[2]), "z": float(q[3]), "w": float(q[0])}


def quat_of(rotation: np.ndarray) -> Json:
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(rotation, dtype=float).reshape(-1))
    return quat_wxyz(q)


def pose(position, rotation: np.ndarray | None = None) -> Json:
    return {"position": vec3(position),
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0} if rotation is None else quat_of(rotation)}


def color(r: float, g: float, b: float, a: float = 1.0) -> Json:
    return {"r": r, "g": g, "b": b, "a": a}


def transform(t_ns: int, parent: str, child: str, position, quaternion: Json) -> Json:
    return {"timestamp": stamp(t_ns), "parent_frame_id": parent, "child_frame_id": child,
            "translation": vec3(position), "rotation": quaternion}


def entity(t_ns: int, frame_id: str, entity_id: str, *, lifetime_s: float = 0.0, metadata: dict[str, str] | None = None,
           **primitives: list[Json]) -> Json:
    """A ``foxglove.SceneEntity`` that follows its frame (``frame_locked``); lifetime 0: until replaced."""
    out: Json = {"timestamp": stamp(t_ns), "frame_id": frame_id, "id": entity_id, "lifetime": duration(lifetime_s),
                 "frame_locked": True, "metadata": [{"key": k, "value": str(v)} for k, v in (metadata or {}).items()]}
    for kind in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"):
        out[kind] = primitives.pop(kind, [])
    if primitives:
        raise TypeError(f"not a primitive list of a SceneEntity: {sorted(primitives)}")
    return out


def scene_update(entities: list[Json]) -> Json:
    return {"deletions": [], "entities": entities}


def surface_primitives(s: Surface, rgba: Json) -> dict[str, list[Json]]:
    """A touchable primitive in its link's frame (MuJoCo's sizes: half-lengths, radii): a capsule is
    a cylinder and two spheres; a plane a 1 mm slab under z = 0 (its size, or 1 m where MuJoCo's is 0)."""
    r, rot, size = s.link_T_geom[:3, 3], s.link_T_geom[:3, :3], np.asarray(s.size, dtype=float)
    if s.kind in ("sphere", "ellipsoid"):
        d = 2 * size[:3] if s.kind == "ellipsoid" else np.full(3, 2 * size[0])
        return {"spheres": [{"pose": pose(r, rot), "size": vec3(d), "color": rgba}]}
    if s.kind == "box":
        return {"cubes": [{"pose": pose(r, rot), "size": vec3(2 * size[:3]), "color": rgba}]}
    if s.kind in ("cylinder", "capsule"):
        out = {"cylinders": [{"pose": pose(r, rot), "size": vec3((2 * size[0], 2 * size[0], 2 * size[1])),
                              "bottom_scale": 1.0, "top_scale": 1.0, "color": rgba}]}
        if s.kind == "capsule":
            ball = vec3(np.full(3, 2 * size[0]))
            out["spheres"] = [{"pose": pose(r + rot[:, 2] * z, rot), "size": ball, "color": rgba}
                              for z in (-size[1], size[1])]
        return out
    if s.kind == "plane":
        half = [h if h > 0 else 0.5 for h in size[:2]]
        return {"cubes": [{"pose": pose(r - rot[:, 2] * 0.0005, rot), "size": vec3((2 * half[0], 2 * half[1], 0.001)),
                           "color": rgba}]}
    raise ValueError(f"surface {s.geom!r}: unknown primitive kind {s.kind!r}")


def arrow(tail, direction, length: float, thickness: float, rgba: Json) -> Json:
    """An arrow of ``length`` (m) from ``tail`` along the unit vector ``direction`` (Foxglove's arrows
    point along their pose's +x)."""
    head = min(0.3 * length, 3 * thickness)
    return {"pose": {"position": vec3(tail), "orientation": _x_to(direction)}, "shaft_length": length - head,
            "shaft_diameter": thickness, "head_length": head, "head_diameter": 2 * thickness, "color": rgba}


def _x_to(u) -> Json:
    """The rotation taking +x onto the unit vector u (half-way quaternion; about z for u = -x)."""
    w, x, y, z = 1.0 + float(u[0]), 0.0, -float(u[2]), float(u[1])
    n = math.sqrt(w * w + y * y + z * z)
    if n < 1e-9:
        return {"x": 0.0, "y": 0.0, "z": 1.0, "w": 0.0}
    return {"x": x / n, "y": y / n, "z": z / n, "w": w / n}


def text(position, words: str, rgba: Json, size_px: float = 14.0) -> Json:
    return {"pose": pose(position), "billboard": True, "font_size": size_px, "scale_invariant": True,
            "color": rgba, "text": words}


CONTACT_RGBA = color(0.9, 0.15, 0.1)
FLAGGED_RGBA = color(1.0, 0.75, 0.0)  # an estimate the solver flagged: ambiguous, uncertain, impact, ...
OFFSET_RGBA = color(0.55, 0.55, 0.55)
FORCE_RGBA = color(0.1, 0.35, 0.95)
TORQUE_RGBA = color(0.1, 0.7, 0.2)
LABEL_RGBA = color(0.9, 0.9, 0.9)


def contact_entity(ev: ContactEvent, link_T_base: np.ndarray, *, marker_m: float, m_per_n: float, max_m: float,
                   lifetime_s: float) -> Json:
    """The event's contact in its link's frame: the point (a sphere), its 95 % ellipsoid (``point_std``
    is 1 sigma per base axis: the ellipsoid's axes are the base frame's at the event's pose), the force
    applied to the arm as an arrow whose head is at the point (``m_per_n`` m per N, at most ``max_m``)
    and a label; ``link_T_base`` is the link's pose at the event's time, inverted."""
    rot, shift = link_T_base[:3, :3], link_T_base[:3, 3]
    p = rot @ np.asarray(ev.point, dtype=float) + shift
    f = rot @ np.asarray(ev.force, dtype=float)
    mag = float(np.linalg.norm(f))
    rgba = OFFSET_RGBA if ev.kind == "offset" else FLAGGED_RGBA if ev.flags else CONTACT_RGBA
    arrows = []
    if mag > 0:
        length = min(mag * m_per_n, max_m)
        arrows.append(arrow(p - f / mag * length, f / mag, length, marker_m / 4, rgba))
    std = np.asarray(ev.point_std, dtype=float)
    spheres = [{"pose": pose(p), "size": vec3(np.full(3, marker_m)), "color": rgba},
               {"pose": pose(p, rot), "size": vec3(2 * K95_3D * std), "color": {**rgba, "a": 0.3}}]
    flags = ",".join(ev.flags)
    label = f"#{ev.contact_id} {ev.kind} {ev.link} {mag:.1f} N" + (f" [{flags}]" if flags else "")
    meta = {"contact_id": ev.contact_id, "kind": ev.kind, "link": ev.link, "flags": flags,
            "force_N": f"{mag:.3f}", "point_base_m": " ".join(f"{x:.5f}" for x in ev.point),
            "point_std_mm": " ".join(f"{1e3 * x:.2f}" for x in std), "probability": f"{ev.probability:.3f}",
            "t_host_ns": ev.t_host_ns}
    above = p + rot[:, 2] * 2.5 * marker_m  # the base frame's +z, in the link frame
    return entity(ev.t_host_ns, ev.link, f"contact/{ev.contact_id}", lifetime_s=lifetime_s, metadata=meta,
                  arrows=arrows, spheres=spheres, texts=[text(above, label, rgba)])


def wrench_entity(t_ns: int, frame_id: str, wrench, *, m_per_n: float, m_per_nm: float, max_m: float,
                  thickness: float, lifetime_s: float) -> Json:
    """The sensor's reading in its own frame: the force (blue) and the torque (green, right-hand rule)
    as arrows from the sensor's origin, with a label."""
    w = [float(x) for x in wrench]  # plain floats: this runs rate_hz times a second
    f, t = math.hypot(*w[:3]), math.hypot(*w[3:])
    arrows = [arrow((0.0, 0.0, 0.0), [x / mag for x in vec], min(mag * scale, max_m), thickness, rgba)
              for vec, mag, scale, rgba in ((w[:3], f, m_per_n, FORCE_RGBA), (w[3:], t, m_per_nm, TORQUE_RGBA))
              if mag > 0]
    meta = {"wrench": " ".join(f"{x:.4f}" for x in w), "m_per_N": f"{m_per_n:.5f}", "m_per_Nm": f"{m_per_nm:.5f}"}
    return entity(t_ns, frame_id, "wrench", lifetime_s=lifetime_s, metadata=meta, arrows=arrows,
                  texts=[text((0.0, 0.0, 0.0), f"F {f:.1f} N, T {t:.2f} N m", LABEL_RGBA)])
