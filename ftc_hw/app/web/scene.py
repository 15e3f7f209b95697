"""Foxglove's well-known primitives (a ``foxglove.SceneEntity`` as JSON: spheres, cubes, cylinders,
arrows, texts; :mod:`ftc_hw.record.foxglove_messages`) drawn as viser scene nodes under one name, so
the web page and a recording opened in Foxglove show the same shapes. Runs in the page's process.

An entity drawn again with the same primitives updates its nodes in place, and only the properties
that changed: each change is a message to every browser and a redraw there."""
from __future__ import annotations

from typing import Any

import numpy as np

Json = dict[str, Any]
Nodes = dict[str, tuple[str, dict[str, Any]]]  # node name -> (viser's add_<kind>, its arguments)
# set once, at creation
FIXED = ("subdivisions", "radial_segments", "anchor", "cast_shadow", "receive_shadow", "flat_shading")


def _xyz(v: Json) -> tuple[float, float, float]:
    return (float(v["x"]), float(v["y"]), float(v["z"]))


def _wxyz(q: Json) -> tuple[float, float, float, float]:
    return (float(q["w"]), float(q["x"]), float(q["y"]), float(q["z"]))


def rgb(c: Json) -> tuple[int, int, int]:
    return (round(255 * c["r"]), round(255 * c["g"]), round(255 * c["b"]))


def _rotate(q: tuple[float, float, float, float], v: np.ndarray) -> np.ndarray:
    w, u = q[0], np.array(q[1:])
    return v + 2 * np.cross(u, np.cross(u, v) + w * v)


def _solid(p: Json) -> dict[str, Any]:
    a = p["color"].get("a", 1.0)
    return {"color": rgb(p["color"]), "opacity": a if a < 1 else None, "position": _xyz(p["pose"]["position"]),
            "wxyz": _wxyz(p["pose"]["orientation"]), "cast_shadow": False, "receive_shadow": False}


def entity_nodes(name: str, ent: Json) -> Nodes:
    """The nodes of an entity: ``name/<kind><i>``, their poses in the parent's frame; Foxglove's sizes
    are diameters and full lengths."""
    nodes: Nodes = {}
    for i, s in enumerate(ent.get("spheres", [])):
        # flat-shaded like the boxes: the browser compiles one shader fewer when the first contact comes
        nodes[f"{name}/sphere{i}"] = ("icosphere", {**_solid(s), "radius": 1.0, "subdivisions": 2,
                                                    "flat_shading": True,
                                                    "scale": tuple(np.array(_xyz(s["size"])) / 2)})
    for i, c in enumerate(ent.get("cubes", [])):
        nodes[f"{name}/cube{i}"] = ("box", {**_solid(c), "dimensions": _xyz(c["size"])})
    for i, c in enumerate(ent.get("cylinders", [])):
        size = _xyz(c["size"])
        nodes[f"{name}/cylinder{i}"] = ("cylinder", {**_solid(c), "radius": size[0] / 2, "height": size[2],
                                                     "radial_segments": 16})
    arrows = ent.get("arrows", [])
    if arrows:
        points, colors = [], []
        for a in arrows:  # Foxglove's arrows point along their pose's +x
            tail = np.array(_xyz(a["pose"]["position"]))
            along = _rotate(_wxyz(a["pose"]["orientation"]), np.array([1.0, 0.0, 0.0]))
            points.append([tail, tail + along * (a["shaft_length"] + a["head_length"])])
            colors.append(rgb(a["color"]))
        a0 = arrows[0]
        nodes[f"{name}/arrows"] = ("arrows", {"points": np.array(points, dtype=np.float32),
                                              "colors": np.array(colors, dtype=np.uint8),
                                              "shaft_radius": a0["shaft_diameter"] / 2,
                                              "head_radius": a0["head_diameter"] / 2,
                                              "head_length": max(a0["head_length"], 1e-4)})
    for i, t in enumerate(ent.get("texts", [])):
        nodes[f"{name}/text{i}"] = ("label", {"text": t["text"], "position": _xyz(t["pose"]["position"]),
                                              "anchor": "bottom-center"})
    return nodes


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.shape(a) == np.shape(b) and np.array_equal(a, b)
    return a == b


class DrawnEntity:
    """An entity's viser nodes; ``draw(ent)`` creates them, or updates what changed."""

    def __init__(self, scene: Any, name: str) -> None:
        self.scene, self.name = scene, name
        self.handles: dict[str, Any] = {}
        self.args: dict[str, dict[str, Any]] = {}

    def draw(self, ent: Json) -> None:
        nodes = entity_nodes(self.name, ent)
        if set(nodes) != set(self.handles) or any(kind != self.args[n]["_kind"] for n, (kind, _) in nodes.items()):
            self.remove()
            for node, (kind, kwargs) in nodes.items():
                self.handles[node] = getattr(self.scene, f"add_{kind}")(node, **kwargs)
                self.args[node] = {**kwargs, "_kind": kind}
            return
        for node, (_, kwargs) in nodes.items():
            old, h = self.args[node], self.handles[node]
            for key, value in kwargs.items():
                if key not in FIXED and not _same(old[key], value):
                    setattr(h, key, value)
                    old[key] = value

    def remove(self) -> None:
        for h in self.handles.values():
            h.remove()
        self.handles, self.args = {}, {}
