"""A contact event as ``visualization_msgs/Marker``s in the base frame: its point, its 95 % ellipsoid, the
force applied to the arm as an arrow whose head is on the point, the touched link's primitives highlighted
(at the link's pose at the event's time) and a label. The sizes are the Foxglove view's (docs/recording.md,
"Contacts"): the arm's reach sets them."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ftc_hw.bus import ContactEvent
from ftc_hw.model import Surface
from ftc_hw.record.foxglove_messages import K95_3D

from . import encode as enc

NS = "ftc_contact"
CONTACT_RGBA = (0.9, 0.15, 0.1, 1.0)
FLAGGED_RGBA = (1.0, 0.75, 0.0, 1.0)  # an estimate the solver flagged: ambiguous, uncertain, impact, ...
OFFSET_RGBA = (0.55, 0.55, 0.55, 1.0)
LINK_RGBA = (1.0, 0.45, 0.1, 0.45)
# marker ids within a contact's block of 100: its point, ellipsoid, arrow, label, then the link's primitives
POINT, ELLIPSOID, ARROW, LABEL, LINK = 0, 1, 2, 3, 10


@dataclass(frozen=True)
class MarkerScale:
    """``point_m`` the point's sphere across; ``m_per_n`` the arrow's length per N, at most ``max_m``."""

    point_m: float
    m_per_n: float
    max_m: float
    lifetime_s: float = 3.0


def contact_markers(t_ns: int, frame_id: str, ev: ContactEvent, surfaces: list[Surface],
                    base_T_link: np.ndarray | None, scale: MarkerScale) -> list:
    """The markers of one event (stamped ``t_ns``, ROS time), ids ``100 * contact_id + k``: a newer event of
    the same contact replaces them. ``surfaces``: the touched link's; ``base_T_link`` its pose then (None:
    no highlight)."""
    p, f, std = (np.asarray(v, dtype=float) for v in (ev.point, ev.force, ev.point_std))
    rgba = OFFSET_RGBA if ev.kind == "offset" else FLAGGED_RGBA if ev.flags else CONTACT_RGBA
    base, life = 100 * ev.contact_id, scale.lifetime_s

    def mk(k: int, kind: int, **kw) -> object:
        return enc.marker(t_ns, frame_id, NS, base + k, kind, lifetime_s=life, **kw)

    out = [mk(POINT, enc.SPHERE, position=p, scale=(scale.point_m,) * 3, rgba=rgba),
           mk(ELLIPSOID, enc.SPHERE, position=p, scale=tuple(np.maximum(2 * K95_3D * std, 1e-6)),
              rgba=rgba[:3] + (0.3,))]
    mag = float(np.linalg.norm(f))
    if mag > 0:
        length = min(mag * scale.m_per_n, scale.max_m)
        tail = p - f / mag * length
        out.append(mk(ARROW, enc.ARROW, points=(tail, p), scale=(scale.point_m / 4, scale.point_m / 2, 0.0),
                      rgba=rgba))
    flags = ",".join(ev.flags)
    label = f"#{ev.contact_id} {ev.kind} {ev.link} {mag:.1f} N" + (f" [{flags}]" if flags else "")
    out.append(mk(LABEL, enc.TEXT_VIEW_FACING, position=p + np.array([0.0, 0.0, 2.5 * scale.point_m]),
                  scale=(0.0, 0.0, scale.point_m), rgba=(0.9, 0.9, 0.9, 1.0), text=label))
    if base_T_link is not None:
        for i, (kind, pos, xyzw, size) in enumerate(p for s in surfaces for p in link_shapes(s, base_T_link)):
            out.append(mk(LINK + i, kind, position=pos, xyzw=xyzw, scale=size, rgba=LINK_RGBA))
    return out


def link_shapes(s: Surface, base_T_link: np.ndarray) -> list[tuple[int, np.ndarray, tuple, tuple]]:
    """A touchable primitive as marker shapes in the base frame: (type, position, quaternion, scale); a capsule
    is a cylinder and two spheres, a plane a 1 mm slab (1 m across where MuJoCo's size is 0)."""
    b_T_g = base_T_link @ s.link_T_geom
    r, rot, size = b_T_g[:3, 3], b_T_g[:3, :3], np.asarray(s.size, dtype=float)
    q = enc.quat_xyzw(rot)
    if s.kind in ("sphere", "ellipsoid"):
        d = 2 * size[:3] if s.kind == "ellipsoid" else np.full(3, 2 * size[0])
        return [(enc.SPHERE, r, q, tuple(d))]
    if s.kind == "box":
        return [(enc.CUBE, r, q, tuple(2 * size[:3]))]
    if s.kind in ("cylinder", "capsule"):
        out = [(enc.CYLINDER, r, q, (2 * size[0], 2 * size[0], 2 * size[1]))]
        if s.kind == "capsule":
            out += [(enc.SPHERE, r + rot[:, 2] * z, q, (2 * size[0],) * 3) for z in (-size[1], size[1])]
        return out
    if s.kind == "plane":
        half = [h if h > 0 else 0.5 for h in size[:2]]
        return [(enc.CUBE, r - rot[:, 2] * 0.0005, q, (2 * half[0], 2 * half[1], 0.001))]
    return []
