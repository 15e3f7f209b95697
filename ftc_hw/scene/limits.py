"""A cell's body limits (ISO/TS 15066 power and force limiting): TOML to typed specs (docs/limits.md).

A file holds body regions (their quasi-static and transient force limits, N; the spring constant, N/m; the
region's effective mass, kg), which region a contact on each link takes, and workspace zones (a box or a
sphere in the base frame) whose region a contact point inside takes. A cell's file starts from the
built-in regions (``builtin_limits/iso-ts-15066.toml``, cited there) and overrides what it gives, key by key.

    [limits]
    default_region = "abdomen"      # a contact on no assigned link or zone
    base = "iso-ts-15066"           # the regions it starts from ("none": only its own)

    [regions.chest]                 # any key of a built-in region, overridden; a new name: all four keys
    quasi_static_n = 100.0

    [links]
    wrist_3_link = "hands_fingers"

    [[zones]]
    region = "chest"
    box = { center = [0.5, 0.0, 1.2], half_size = [0.3, 0.4, 0.25] }   # or sphere = { center, radius }

A bad file is a :class:`LimitsError` naming the file, the line and the key.
"""
from __future__ import annotations

import json
import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

BUILTIN_LIMITS_DIR = Path(__file__).resolve().parent / "builtin_limits"
DEFAULT_BASE = "iso-ts-15066"
REGION_KEYS = ("quasi_static_n", "transient_n", "spring_constant_n_per_m", "effective_mass_kg")
LIMIT_KINDS = ("transient", "quasi_static")


class LimitsError(ValueError):
    """A limits file that cannot be read: its path, the line (0: unknown) and the dotted key, and what is wrong."""

    def __init__(self, path: Path | str, line: int, key: str, problem: str) -> None:
        self.path, self.line, self.key, self.problem = str(path), int(line), key, problem
        where = f"{self.path}" + (f":{line}" if line else "") + (f": {key}" if key else "")
        super().__init__(f"{where}: {problem}")

    def __reduce__(self):
        return type(self), (self.path, self.line, self.key, self.problem)


@dataclass(frozen=True)
class BodyRegion:
    """One body region: the force limits (N) of a quasi-static (clamping) and a transient contact, the
    region's spring constant (N/m) and effective mass (kg) of ISO/TS 15066's two-body model."""

    name: str
    quasi_static_n: float
    transient_n: float
    spring_constant_n_per_m: float
    effective_mass_kg: float

    def limit_n(self, kind: str) -> float:
        """The force limit (N) of a ``transient`` or ``quasi_static`` contact."""
        return self.transient_n if kind == "transient" else self.quasi_static_n


@dataclass(frozen=True)
class Zone:
    """A workspace zone in the base frame: a box (``half_size`` m, axis-aligned) or a sphere (``radius`` m)
    about ``center`` (m). A contact point inside takes ``region``."""

    region: str
    center: tuple[float, float, float]
    half_size: tuple[float, float, float] | None = None
    radius: float | None = None

    def contains(self, point: np.ndarray) -> bool:
        d = np.asarray(point, dtype=float) - np.asarray(self.center)
        if self.radius is not None:
            return float(d @ d) <= self.radius**2
        return bool(np.all(np.abs(d) <= np.asarray(self.half_size)))


@dataclass(frozen=True, eq=False)
class CellLimits:
    """The regions by name, the default region, the links' regions and the zones (checked against each
    other; the links against a scene by :meth:`check_links`). ``source``: the file it was read from."""

    regions: Mapping[str, BodyRegion]
    default_region: str
    links: Mapping[str, str]
    zones: tuple[Zone, ...]
    source: str = ""

    def region_at(self, link: str, point: np.ndarray) -> tuple[BodyRegion, str]:
        """The region a contact on ``link`` at ``point`` (m, base frame) takes, and why: the zones holding
        the point (the one of the lowest quasi-static limit, when several do), else the link's, else the default."""
        inside = [self.regions[z.region] for z in self.zones if z.contains(point)]
        if inside:
            return min(inside, key=lambda r: r.quasi_static_n), "zone"
        if link in self.links:
            return self.regions[self.links[link]], "link"
        return self.regions[self.default_region], "default"

    def check_links(self, link_names: tuple[str, ...] | list[str]) -> None:
        """LimitsError for a link the scene's arm does not have."""
        for link in self.links:
            if link not in link_names:
                raise LimitsError(self.source, 0, f"links.{link}",
                                  f"no link {link!r} in the scene's arm (links: {', '.join(link_names)})")

    def to_json(self) -> str:
        """The limits as JSON (a recording keeps the ones it was made with)."""
        return json.dumps({"source": self.source, "default_region": self.default_region,
                           "regions": {n: {k: getattr(r, k) for k in REGION_KEYS} for n, r in self.regions.items()},
                           "links": dict(self.links),
                           "zones": [_zone_out(z) for z in self.zones]})

    @staticmethod
    def from_json(text: str) -> CellLimits:
        data = json.loads(text)
        return _parse({"limits": {"default_region": data["default_region"], "base": "none"},
                       "regions": data["regions"], "links": data["links"], "zones": data["zones"]},
                      data.get("source", "recorded limits"), "", {})


def builtin_limits_path(name: str = DEFAULT_BASE) -> Path:
    return BUILTIN_LIMITS_DIR / f"{name}.toml"


@cache
def builtin_limits(name: str = DEFAULT_BASE) -> CellLimits:
    """The built-in regions (``name``: a file in ``builtin_limits``), no links or zones assigned."""
    return load_limits(builtin_limits_path(name))


def load_limits(path: Path | str) -> CellLimits:
    """A limits TOML file, on top of the regions its ``[limits] base`` names (default: the built-in ISO/TS 15066)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise LimitsError(path, 0, "", f"cannot read: {exc.strerror or exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        raise LimitsError(path, int(m.group(1)) if m else 0, "", f"not valid TOML: {exc}") from None
    base = data.get("limits", {}).get("base", DEFAULT_BASE) if isinstance(data.get("limits"), dict) else DEFAULT_BASE
    inherited: dict[str, dict[str, float]] = {}
    if base != "none" and path.resolve() != builtin_limits_path(str(base)).resolve():
        if not isinstance(base, str) or not builtin_limits_path(base).is_file():
            known = ", ".join(sorted(p.stem for p in BUILTIN_LIMITS_DIR.glob("*.toml")))
            raise LimitsError(path, _line_of(text, "limits", "base"), "limits.base",
                              f"expected one of {known} or 'none', got {base!r}")
        b = builtin_limits(base)
        inherited = {n: {k: getattr(r, k) for k in REGION_KEYS} for n, r in b.regions.items()}
        data.setdefault("limits", {}).setdefault("default_region", b.default_region)
    return _parse(data, str(path), text, inherited)


def _parse(data: dict[str, Any], path: str, text: str, inherited: dict[str, dict[str, float]]) -> CellLimits:
    def fail(table: str, key: str, problem: str) -> LimitsError:
        m = re.match(r"zones\[(\d+)\]\.?(\w*)", key)
        line = _zone_line(text, int(m.group(1)), m.group(2)) if m else _line_of(text, table, key.rsplit(".", 1)[-1])
        return LimitsError(path, line, key, problem)

    unknown = sorted(set(data) - {"limits", "regions", "links", "zones"})
    if unknown:
        raise fail("", unknown[0], "unknown table (known: limits, regions, links, zones)")
    head = _table(data, "limits", fail)
    extra = sorted(set(head) - {"default_region", "base"})
    if extra:
        raise fail("limits", f"limits.{extra[0]}", "unknown key (known: default_region, base)")
    regions = {}
    given = _table(data, "regions", fail)
    for name in [*inherited, *(n for n in given if n not in inherited)]:
        regions[name] = _region(name, inherited.get(name, {}), given.get(name, {}), fail)
    default = head.get("default_region")
    if not isinstance(default, str) or default not in regions:
        raise fail("limits", "limits.default_region", f"expected a region ({', '.join(regions)}), got {default!r}")
    links = {}
    for link, region in _table(data, "links", fail).items():
        if not isinstance(region, str) or region not in regions:
            raise fail("links", f"links.{link}", f"expected a region ({', '.join(regions)}), got {region!r}")
        links[link] = region
    zones = data.get("zones", [])
    if not isinstance(zones, list):
        raise fail("", "zones", "expected an array of tables ([[zones]])")
    return CellLimits(MappingProxyType(regions), default, MappingProxyType(links),
                      tuple(_zone(i, z, regions, fail) for i, z in enumerate(zones)), path)


def _table(data: dict[str, Any], name: str, fail) -> dict[str, Any]:
    t = data.get(name, {})
    if not isinstance(t, dict):
        raise fail("", name, f"expected a table, got {type(t).__name__}")
    return t


def _region(name: str, base: dict[str, float], given: Any, fail) -> BodyRegion:
    table = f"regions.{name}"
    if not isinstance(given, dict):
        raise fail("regions", table, f"expected a table, got {type(given).__name__}")
    extra = sorted(set(given) - set(REGION_KEYS))
    if extra:
        raise fail(table, f"{table}.{extra[0]}", f"unknown key (known: {', '.join(REGION_KEYS)})")
    values = {**base, **given}
    missing = [k for k in REGION_KEYS if k not in values]
    if missing:
        raise fail(table, f"{table}.{missing[0]}", "missing (a region not among the built-ins needs all of "
                   f"{', '.join(REGION_KEYS)})")
    out = {}
    for k in REGION_KEYS:
        v = values[k]
        positive = k in ("spring_constant_n_per_m", "effective_mass_kg")
        number = isinstance(v, int | float) and not isinstance(v, bool)
        if not number or not math.isfinite(v) or v < 0 or (positive and v == 0):
            want = "a finite number > 0" if positive else "a finite number >= 0"
            raise fail(table, f"{table}.{k}", f"expected {want}, got {v!r}")
        out[k] = float(v)
    return BodyRegion(name, **out)


def _zone(i: int, z: Any, regions: dict[str, BodyRegion], fail) -> Zone:
    key = f"zones[{i}]"
    if not isinstance(z, dict):
        raise fail("", key, "expected a table")
    extra = sorted(set(z) - {"region", "box", "sphere"})
    if extra:
        raise fail("zones", f"{key}.{extra[0]}", "unknown key (known: region, box, sphere)")
    region = z.get("region")
    if region not in regions:
        raise fail("zones", f"{key}.region", f"expected a region ({', '.join(regions)}), got {region!r}")
    if ("box" in z) == ("sphere" in z):
        raise fail("zones", key, "expected exactly one of box = {center, half_size} or sphere = {center, radius}")
    shape = "box" if "box" in z else "sphere"
    spec = z[shape]
    size_key = "half_size" if shape == "box" else "radius"
    if not isinstance(spec, dict) or set(spec) != {"center", size_key}:
        raise fail("zones", f"{key}.{shape}", f"expected {{center = [x, y, z], {size_key} = ...}}, got {spec!r}")
    center = _vector3(spec["center"], lambda p: fail("zones", f"{key}.{shape}.center", p))
    if shape == "box":
        half = _vector3(spec["half_size"], lambda p: fail("zones", f"{key}.box.half_size", p), positive=True)
        return Zone(region, center, half_size=half)
    r = spec["radius"]
    if isinstance(r, bool) or not isinstance(r, int | float) or not (math.isfinite(r) and r > 0):
        raise fail("zones", f"{key}.sphere.radius", f"expected a number > 0 (m), got {r!r}")
    return Zone(region, center, radius=float(r))


def _vector3(v: Any, fail, positive: bool = False) -> tuple[float, float, float]:
    ok = isinstance(v, list) and len(v) == 3 and all(
        isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) and (x > 0 or not positive)
        for x in v)
    if not ok:
        raise fail(f"expected 3 finite numbers{' > 0' if positive else ''} (m, base frame), got {v!r}")
    return (float(v[0]), float(v[1]), float(v[2]))


def _zone_out(z: Zone) -> dict[str, Any]:
    if z.radius is not None:
        return {"region": z.region, "sphere": {"center": list(z.center), "radius": z.radius}}
    return {"region": z.region, "box": {"center": list(z.center), "half_size": list(z.half_size)}}


def _line_of(text: str, table: str, key: str) -> int:
    """The line (from 1) of ``key`` in ``[table]`` (``""``: the top level; for ``[[zones]]`` the first
    match), else of the table's header, else 0."""
    current, header = "", 0
    for i, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        m = re.fullmatch(r"\[\[?\s*([^\]]+?)\s*\]\]?", line)
        if m:
            current = m.group(1)
            if current == table and not header:
                header = i
            continue
        if (current == table or (table == "" and current == "")) and re.match(rf"{re.escape(key)}\s*=", line):
            return i
    if header:
        return header
    for i, raw in enumerate(text.splitlines(), 1):  # a table header given for a key that is a table itself
        if re.fullmatch(rf"\[\[?\s*{re.escape(table + '.' + key if table else key)}\s*\]\]?", raw.strip()):
            return i
    return 0


def _zone_line(text: str, index: int, key: str) -> int:
    """The line (from 1) of ``key`` in the ``index``-th ``[[zones]]`` table, else of its header, else 0."""
    seen, header = -1, 0
    for i, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if line.startswith("["):
            seen += line.replace(" ", "") == "[[zones]]"
            if seen == index and line.replace(" ", "") == "[[zones]]":
                header = i
            elif header:
                break
            continue
        if header and key and re.match(rf"{re.escape(key)}\s*=", line):
            return i
    return header
