"""Primitive kind codes of the compiled engine (MuJoCo's geom conventions; not MuJoCo's mjtGeom numbers).

Sizes are MuJoCo ``geom_size`` rows: sphere ``r``; capsule, cylinder ``r, h`` (h the half-length along
local z); ellipsoid ``a, b, c`` (semi-axes); box ``hx, hy, hz`` (half sizes); plane: ignored (the
half-space ``z <= 0``). Rows may be longer (the solver appends a bounding radius).
"""
from __future__ import annotations

SPHERE, CAPSULE, CYLINDER, ELLIPSOID, BOX, PLANE = 0, 1, 2, 3, 4, 5
KINDS = {"sphere": SPHERE, "capsule": CAPSULE, "cylinder": CYLINDER, "ellipsoid": ELLIPSOID, "box": BOX,
         "plane": PLANE}


def kind_code(kind: int | str) -> int:
    """The engine's code of a kind given by name or code."""
    if isinstance(kind, str):
        return KINDS[kind]
    code = int(kind)
    if code not in KINDS.values():
        raise ValueError(f"unknown primitive kind {kind!r}")
    return code
