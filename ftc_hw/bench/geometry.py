"""``ftc bench geometry``: the geometry engine's numpy-facing queries, lines (or points) per second.

``bench(reference=...)`` times a vectorised numpy implementation with the interface of
``tests/model/geometry_reference.py`` beside the engine (its test passes that module: production
code does not import the tests).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from types import ModuleType

import numpy as np
from rich.table import Table

from ftc_hw import geometry as geo
from ftc_hw.bench.report import table_console

_SIZES = {
    "sphere": [0.05],
    "capsule": [0.04, 0.15],
    "cylinder": [0.04, 0.15],
    "ellipsoid": [0.05, 0.08, 0.2],
    "box": [0.05, 0.08, 0.2],
    "plane": [0.0],
}


def _lines(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random lines aimed at a 0.2 m cube around the primitive (roughly half of them hit)."""
    target = rng.uniform(-0.1, 0.1, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return target - rng.uniform(0.5, 2.0, (n, 1)) * d, d


def _rate(fn, n: int, repeat: int) -> float:
    fn()  # compiles (or loads) the kernels
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return n / best


def _closest(kind: str, size: list[float], points: np.ndarray) -> np.ndarray:
    """The engine's nearest surface points: closed forms, Eberly's bisection for ellipsoids."""
    if kind == "ellipsoid":
        return geo.quadric_closest(1.0 / np.asarray(size), points)[0]
    return geo.project(kind, size, points)


def bench(n: int = 100_000, repeat: int = 3, seed: int = 0,
          reference: ModuleType | None = None) -> dict[str, dict[str, float]]:
    """Lines (or points) per second per primitive, best of ``repeat``, for ``n`` in one call.

    Returns ``{kind: {"crossings": .., "inside": .., "closest": .., "hit_fraction": ..}}``, with
    ``reference_intersect`` and ``reference_signed_distance`` too when a reference module is given.
    """
    rng = np.random.default_rng(seed)
    o, d = _lines(n, rng)
    out: dict[str, dict[str, float]] = {}
    for kind, size in _SIZES.items():
        count, _ = geo.crossings(kind, size, o, d)
        r = out[kind] = {
            "crossings": _rate(lambda k=kind, s=size: geo.crossings(k, s, o, d), n, repeat),
            "inside": _rate(lambda k=kind, s=size: geo.inside(k, s, o), n, repeat),
            "closest": _rate(lambda k=kind, s=size: _closest(k, s, o), n, repeat),
            "hit_fraction": float((count > 0).mean()),
        }
        if reference is not None:
            r["reference_intersect"] = _rate(lambda k=kind, s=size: reference.intersect(k, s, o, d), n, repeat)
            r["reference_signed_distance"] = _rate(lambda k=kind, s=size: reference.signed_distance(k, s, o), n,
                                                   repeat)
    return out



def run(json_path: Path | None = None, lines: int = 100_000, repeat: int = 3, seed: int = 0) -> dict:
    """Print the table, write the figures as JSON if ``json_path``; returns them."""
    res = bench(lines, repeat, seed)
    t = Table(title=f"geometry engine: {lines} random lines (or points) per call, best of {repeat}")
    for col in ("primitive", "crossings /s", "inside /s", "closest /s", "lines that hit"):
        t.add_column(col, justify="left" if col == "primitive" else "right")
    for kind, r in res.items():
        t.add_row(kind, *(f"{r[k]:.3g}" for k in ("crossings", "inside", "closest")), f"{r['hit_fraction']:.2f}")
    table_console().print(t)
    if json_path is not None:
        Path(json_path).write_text(json.dumps({"lines": lines, "repeat": repeat, "seed": seed, "kinds": res},
                                              indent=2) + "\n")
    return res
