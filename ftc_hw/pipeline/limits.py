"""Contact events against the cell's body limits (ISO/TS 15066 power and force limiting; docs/limits.md).

Each event gets a :class:`~ftc_hw.bus.LimitCheck`: its body region (a zone holding the point, else its link's,
else the default), the limit that applies by the contact's class (transient or quasi-static; a contact
without a class is taken as quasi-static, the stricter, and says so), the margin to it, the arm's effective
mass at the point along the contact's normal (the pipeline's model: identified where a calibration says so),
the arm's speed there at the onset, and the region's permissible speed (ISO/TS 15066 A.3.3, the
two-body model):

    mu = (1/m_H + 1/m_R)^-1,   v_max = F_transient / sqrt(mu k)

(``m_H`` and ``k`` the region's effective mass and spring constant, ``m_R`` the arm's effective mass).
The mass is taken along the contact's normal ``n``, the touched surface's, pointing from the arm into
what it touches (the direction the body is compressed in; :func:`~ftc_hw.model.contact_normal.contact_normal`:
on the surface the pipeline answers on, within the force's friction cone); the force's line leans off it
by friction. The onset speed is taken along the force's line, ``-f/|f|`` (``f`` applied to the arm): at
an onset the point, and any surface normal at it, is at its least certain while the force's line is
measured (docs/limits.md says why this is the standard's closing speed or above it). Each event's own
point: a few millimetres off, and the normal and the effective mass turn with it (measured, docs/limits.md).
A contact whose force goes past its limit gets an ``exceedance`` event as well, once per contact and limit
kind.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import replace

import mujoco
import numpy as np

from ftc_hw.bus import ContactEvent, LimitCheck
from ftc_hw.model import ArmModel
from ftc_hw.model.contact_normal import contact_normal
from ftc_hw.model.effective_mass import effective_mass, point_speed, pose_for_inertia
from ftc_hw.model.mesh_surface import pipeline_mesh_shell
from ftc_hw.scene import Scene
from ftc_hw.scene.limits import BodyRegion, CellLimits

from .contact import corrected_scene
from .settings import PipelineSettings

# kg: the effective mass of a point the joints cannot move along the normal (on the base): finite, so every
# format carries it; the permissible speed is then the body region's alone (mu = m_H)
IMMOVABLE_KG = 1e9
RECENT_FRAMES = 64  # the joint states kept to find the onset's (the onset is n_on frames back)
CLASS_LIMIT_KINDS = {"transient": "transient", "quasi_static": "quasi_static", "quasi-static": "quasi_static",
                     "clamping": "quasi_static"}


def contact_class_of(ev: ContactEvent) -> str | None:
    """The contact's class as the classifier put it on the event (``contact_class``: ``transient`` or
    ``quasi_static``), or None where it has none (no classifier, or not yet decided)."""
    value = getattr(ev, "contact_class", None)  # the classifier's field (issue 39), where the event has it
    return CLASS_LIMIT_KINDS.get(value) if isinstance(value, str) else None


def permissible_speed(region: BodyRegion, robot_mass_kg: float) -> float:
    """m/s: ISO/TS 15066's permissible relative speed of a transient contact of a robot part of effective mass
    ``robot_mass_kg`` with ``region``: ``F_transient / sqrt(mu k)``, ``mu = (1/m_H + 1/m_R)^-1``."""
    mu = 1.0 / (1.0 / region.effective_mass_kg + 1.0 / robot_mass_kg)
    return region.transient_n / math.sqrt(mu * region.spring_constant_n_per_m)


class LimitAssessor:
    """The monitor's judge of events against ``limits``: :meth:`observe` every frame's joint state, then
    :meth:`judge` its events. Owns its own model of the arm (the pipeline's, with its corrections)."""

    def __init__(self, scene: Scene, settings: PipelineSettings, limits: CellLimits) -> None:
        c = settings.corrections
        self.arm = ArmModel(corrected_scene(scene, settings), c.payload, c.inertials)
        limits.check_links(self.arm.link_names)
        self.limits = limits
        # the surface the events' points are on: the meshes where the pipeline answers on them
        self.shell = pipeline_mesh_shell(scene) if settings.localization.surface == "meshes" else None
        self.mu = settings.joint.friction_mu
        self._data = mujoco.MjData(self.arm.model)
        self._recent: deque[tuple[int, np.ndarray, np.ndarray]] = deque(maxlen=RECENT_FRAMES)
        self._onset_speed: dict[int, float] = {}
        # per open contact: the joint state at its onset (its first judged event may come later: an impact's
        # onset has no estimate yet), whose velocities give the onset speed at the first judged point
        self._onset_state: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._exceeded: set[tuple[int, str]] = set()

    def observe(self, t_ns: int, q: np.ndarray, qd: np.ndarray) -> None:
        """A frame's joint state (rad, rad/s) at host time t_ns."""
        self._recent.append((t_ns, q, qd))

    def judge(self, events: tuple[ContactEvent, ...] | list[ContactEvent]) -> list[ContactEvent]:
        """The events with their limit checks, each exceedance after the event that crossed."""
        out: list[ContactEvent] = []
        for ev in events:
            if ev.kind == "onset":
                self._onset_state[ev.contact_id] = self._state_at(ev.t_host_ns) if self._recent else None
                self._onset_speed.pop(ev.contact_id, None)
            check = self.check(ev)
            if check is None:
                out.append(ev)
                continue
            judged = replace(ev, limits=check)
            out.append(judged)
            key = (ev.contact_id, check.limit_kind)
            if check.margin_n < 0.0 and key not in self._exceeded:
                self._exceeded.add(key)
                out.append(replace(judged, kind="exceedance"))
            if ev.kind == "offset":
                self._onset_speed.pop(ev.contact_id, None)
                self._onset_state.pop(ev.contact_id, None)
        return out

    def check(self, ev: ContactEvent) -> LimitCheck | None:
        """The event against its region's limit (None: an event without a force or on no link of the arm)."""
        force = np.asarray(ev.force, dtype=float)
        magnitude = float(np.linalg.norm(force))
        if magnitude == 0.0 or "no_estimate" in ev.flags or ev.link not in self.arm.link_names or not self._recent:
            return None
        body = self.arm.model.body(ev.link).id
        m, d, joints = self.arm.model, self._data, self.arm.joints
        if ev.contact_id not in self._onset_speed:  # the contact's first judged event: at the onset's state
            q, qd = self._onset_state.get(ev.contact_id) or self._state_at(ev.t_host_ns)
            pose_for_inertia(m, d, joints, q)
            self._onset_speed[ev.contact_id] = point_speed(m, d, joints, body, ev.point, -force, qd)
        q = self._state_at(ev.t_host_ns if ev.kind == "onset" else None)[0]
        normal = self._normal(ev, q)
        pose_for_inertia(m, d, joints, q)
        mass = min(effective_mass(m, d, joints, body, ev.point, normal), IMMOVABLE_KG)
        region, origin = self.limits.region_at(ev.link, ev.point)
        kind = contact_class_of(ev)
        limit_kind = kind or "quasi_static"
        limit = region.limit_n(limit_kind)
        return LimitCheck(region.name, origin, limit_kind, kind is None, limit, limit - magnitude, mass,
                          self._onset_speed[ev.contact_id], permissible_speed(region, mass))

    def _normal(self, ev: ContactEvent, q: np.ndarray) -> np.ndarray:
        """The contact's normal at joint positions q (unit, base frame): the arm's outward surface normal, from
        the arm into what it touches."""
        return contact_normal(arm=self.arm, shell=self.shell, link=ev.link, q=q, point=ev.point,
                               force=np.asarray(ev.force, dtype=float), mu=self.mu)

    def _state_at(self, t_ns: int | None) -> tuple[np.ndarray, np.ndarray]:
        """The newest joint state at or before t_ns (None: the newest; the oldest kept if all are after)."""
        if t_ns is not None:
            for t, q, qd in reversed(self._recent):
                if t <= t_ns:
                    return q, qd
            return self._recent[0][1], self._recent[0][2]
        return self._recent[-1][1], self._recent[-1][2]
