"""Micro-benchmark of the vectorised line/primitive queries (not a test).

Run: ``python -m ftc_hw.bench.geometry [n]``.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from ftc_hw.solver import geometry as geo

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
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return n / best


def bench(n: int = 100_000, repeat: int = 3, seed: int = 0) -> dict[str, dict[str, float]]:
    """Lines (or points) per second per primitive, best of ``repeat``, for ``n`` lines in one call.

    Returns ``{kind: {"intersect": .., "closest": .., "signed_distance": .., "hit_fraction": ..}}``.
    """
    rng = np.random.default_rng(seed)
    o, d = _lines(n, rng)
    out: dict[str, dict[str, float]] = {}
    for kind, size in _SIZES.items():
        hits = geo.intersect(kind, size, o, d)
        out[kind] = {
            "intersect": _rate(lambda k=kind, s=size: geo.intersect(k, s, o, d), n, repeat),
            "closest": _rate(lambda k=kind, s=size: geo.closest_point_on_surface_to_line(k, s, o, d),
                             n, repeat),
            "signed_distance": _rate(lambda k=kind, s=size: geo.signed_distance(k, s, o), n, repeat),
            "hit_fraction": float(hits.hit[..., 0].mean()),
        }
    return out


if __name__ == "__main__":
    n_lines = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
    for kind, r in bench(n_lines).items():
        print(f"{kind:10s} intersect {r['intersect']:12.3g}/s  closest {r['closest']:12.3g}/s  "
              f"signed_distance {r['signed_distance']:12.3g}/s  hit {r['hit_fraction']:.2f}")
