"""The events stage: a contact's track (its point fused over its frames) and its onset, update and offset
events, each with the contact's id and figures, its point's uncertainty with the errors no number of
frames averages away, and its point on the link's meshes."""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from ftc_hw.bus import ContactEvent
from ftc_hw.detection import Detection
from ftc_hw.model import ArmModel
from ftc_hw.model.arm import link_reach
from ftc_hw.model.inertials import skew
from ftc_hw.model.mesh_surface import MeshShell, pipeline_mesh_shell
from ftc_hw.scene import Scene
from ftc_hw.solver import ContactEstimate
from ftc_hw.tracking import FUSED_FLAGS, ContactTrack, fuse_point, link_pose, report

from .classify import ContactClassifier
from .settings import PipelineSettings

# frames a second of a scene without an F/T sensor (its frames are joint samples): the recent wrench's ring
NO_SENSOR_RATE_HZ = 1000.0


class PreviousFrame(NamedTuple):
    """The last frame the pipeline judged, as the onset's track fuses it (the sample before the onset)."""

    t_ns: int
    external: np.ndarray  # (6,) sensor frame
    q: np.ndarray  # (n,) rad
    model_error: np.ndarray | None  # (k, 6) covariance rows of the compensation's error
    saturated: bool


@dataclass
class _ContactRun:
    """The open (or last) contact: its id, its figures so far and its last event with an estimate."""

    contact_id: int = 0
    onset_ns: int = 0
    last_ns: int = 0
    peak: float = 0.0
    impulse: float = 0.0
    last_event: ContactEvent | None = None  # the last with an estimate
    last_trusted: ContactEvent | None = None  # the last whose estimate the track would fuse (flags: grazing)
    onset_link: str = ""

    def add(self, t_ns: int, external: np.ndarray) -> None:
        f = math.sqrt(float(external[0] ** 2 + external[1] ** 2 + external[2] ** 2))
        self.impulse += f * max(t_ns - self.last_ns, 0) * 1e-9
        self.peak = max(self.peak, f)
        self.last_ns = t_ns

    def stamp(self, ev: ContactEvent, final: bool = False, **changes: object) -> ContactEvent:
        """``ev`` with the contact's id and figures (and ``changes`` to its fields)."""
        out = replace(ev, contact_id=self.contact_id, duration_s=max(ev.t_host_ns - self.onset_ns, 0) * 1e-9,
                      peak_force=self.peak, impulse=self.impulse, **changes)
        if not final and "no_estimate" not in ev.flags:
            self.last_event = out
            if FUSED_FLAGS.issuperset(f for f in ev.flags if f != "uncertain"):
                self.last_trusted = out
        return out


class ContactEvents:
    """The contact's track (``track``; None: each event carries its frame's own estimate) and its events.
    ``previous`` is the last judged frame (kept only with a track)."""

    def __init__(self, scene: Scene, model: ArmModel, body_poses, settings: PipelineSettings) -> None:
        ev, loc = settings.events, settings.localization
        self.update_period_ns = int(ev.update_period_s * 1e9)
        self._last_update_ns = 0
        self.last_estimate: ContactEstimate | None = None
        self._contact = _ContactRun()
        self.track = (None if ev.track_slide is None
                      else ContactTrack(model, slide=ev.track_slide, body_poses=body_poses))
        if self.track is not None:
            # a bias given (calibration file, scene) is taken as known to a tenth of one sample's noise
            self.track.set_bias(ev.bias_var_ratio)
        self.previous: PreviousFrame | None = None
        # an event whose point is less certain than the touched link is big says nothing of where
        self._link_reach = link_reach(model) if loc.flag_uncertain else None
        # m, 1 sigma per link (the scene's, and a mesh fit's), looked up once per link
        self._surface = functools.cache(model.surface_tolerance)
        self.mesh_shell = pipeline_mesh_shell(scene) if loc.surface == "meshes" else None
        self.surface_source = "meshes" if self.mesh_shell is not None else "primitives"
        # the contact's external wrench over the last update period: the line of action followed into the meshes
        # (a ring and its running sum: np.mean over a deque took 22 us an event, measured by ftc bench pipeline)
        rate = scene.sensor.rate_hz if scene.sensor is not None else NO_SENSOR_RATE_HZ
        self._recent_ring = np.zeros((max(1, round(ev.update_period_s * rate)), 6))
        self._recent_sum = np.zeros(6)
        self._recent_count = 0
        self._gain_var = gain_std_of(scene) ** 2
        self._k_work = np.empty((3, 6))  # _systematic's point-from-wrench map
        self._sensor_pose = model.base_T_sensor
        self.classifier = ContactClassifier()

    @staticmethod
    def warm_up() -> None:
        """Call the track's compiled kernels once (numba loads each from its cache on its first call)."""
        poses = (np.zeros((2, 3)), np.ones((2, 4)))
        fuse_point(np.zeros(3), np.eye(3), np.zeros(3), np.eye(6), *poses, 1, 0.0, 0.0, 1.0, np.zeros((4, 3)),
                   np.zeros((3, 4)))
        link_pose(*poses, 1, np.zeros((3, 4)))
        report(np.zeros(3), np.eye(3), np.zeros((4, 3)), 0.0, np.zeros((3, 4)), np.zeros(3), np.zeros((3, 3)))

    def fuse(self, t_ns: int, estimate: ContactEstimate, q: np.ndarray, poses) -> None:
        """A frame's estimate in contact: the last one, and fused into the track (``poses``: the solved
        frame's link poses)."""
        self.last_estimate = estimate
        if self.track is not None:
            self.track.update(t_ns, estimate, q, poses)

    def set_bias(self, ratio: float, t_ns: int) -> None:
        """The bias is now known to ``ratio`` of one sample's noise variance (a tare)."""
        if self.track is not None:
            self.track.set_bias(ratio, t_ns)

    def frame_events(self, t_ns: int, det: Detection, estimate: ContactEstimate | None,
                     external: np.ndarray, q: np.ndarray, power: float | None = None) -> list[ContactEvent]:
        """This frame's onset, update or offset, stamped with the contact's id, figures and class so far.
        ``power`` (W): the power ``F . v`` the contact puts into the arm this frame (None: not known)."""
        track = self.track if self.track is not None and self.track.active else None
        force = math.sqrt(float(external[0] ** 2 + external[1] ** 2 + external[2] ** 2))
        if det.change == "onset":
            onset = det.onset_t_ns or t_ns
            self._contact = _ContactRun(self._contact.contact_id + 1, onset, onset)
            self.classifier.begin(onset)
            self.classifier.add(t_ns, force, power)
            self._contact.add(t_ns, external)
            self._recent_count = 0
            self._recent_sum[:] = 0.0
            self._add_recent(external)
            self._last_update_ns = t_ns
            ev = contact_event(onset, "onset", estimate, det.probability, track, self._link_reach)
            self._contact.onset_link = ev.link
        elif det.change == "offset":
            return [self.close_contact(t_ns, det.probability)]
        else:
            self.classifier.add(t_ns, force, power)
            self._contact.add(t_ns, external)
            self._add_recent(external)
            if t_ns - self._last_update_ns < self.update_period_ns:
                return []
            ev = contact_event(t_ns, "update", estimate, det.probability, track, self._link_reach)
            self._last_update_ns = t_ns
        return [self._contact.stamp(ev, **self._shipping(ev, external, q), **self.classifier.result().event_fields())]

    def close_contact(self, t_ns: int, probability: float | None = None, *, lost: bool = False) -> ContactEvent:
        """The open contact's offset at host time t_ns: its last estimate (as its last onset or update
        with a sound estimate said, one the track would fuse; else its last with any estimate; else the
        last frame's own) with its duration, peak force and impulse; flagged ``relinked`` when that
        names another link than the onset did, ``lost`` when a stream was lost. ``probability``: the
        offset frame's (default: the last event's)."""
        run = self._contact
        # a contact's last low-force or ambiguous estimate (its release) says less than its last sound one
        last = run.last_trusted or run.last_event
        if last is None:
            last = contact_event(t_ns, "offset", self.last_estimate, probability or 0.0)
        # the track settled on another link than the onset's provisional estimate: said, not hidden
        flags = (*last.flags, *(("relinked",) if last.link != run.onset_link else ()), *(("lost",) if lost else ()))
        p = last.probability if probability is None else probability
        ev = run.stamp(ContactEvent.make(t_ns, "offset", last.link, last.point, last.force, last.point_std,
                                         flags=flags, probability=p), final=True,
                       **self.classifier.result(released=not lost).event_fields())
        self.last_estimate = None
        if self.track is not None:
            self.track.reset()
        return ev

    def recent_external(self) -> np.ndarray | None:
        """The open contact's external wrench (sensor frame) averaged over the last update period."""
        n = min(self._recent_count, len(self._recent_ring))
        return self._recent_sum / n if n else None

    def on_meshes(self, ev: ContactEvent, q: np.ndarray, shell: MeshShell | None = None,
                  wrench: np.ndarray | None = None) -> ContactEvent:
        """The event with its point where the contact's line of action enters its link's meshes
        (``shell``, else the pipeline's own; unchanged where there are none or the line misses them).
        The line is the one ``wrench`` (external, sensor frame, e.g. :meth:`recent_external`) acts
        along, taken where it passes closest to the event's point: the solver's point lies on the
        primitives, and where the real shell stands out of them the true line misses them, so the
        solver's point is off it. Without a wrench: the line through the event's point along its force.
        In the point's uncertainty the real shell's distance from the meshes (the vendor's tolerance,
        or the scene's ``surface_tolerance_m`` for its own meshes) takes the place of its distance from
        the primitives (``surface_tolerance_m`` and a mesh fit's RMS; :meth:`_systematic`)."""
        if "no_estimate" in ev.flags:
            return ev
        moved = self._mesh_point(ev, q, ev.point_std, shell, wrench, None)
        return ev if moved is None else replace(ev, point=moved[0], point_std=moved[1])

    def _add_recent(self, external: np.ndarray) -> None:
        k = self._recent_count % len(self._recent_ring)
        if self._recent_count >= len(self._recent_ring):
            self._recent_sum -= self._recent_ring[k]
        self._recent_ring[k] = external
        self._recent_sum += self._recent_ring[k]
        self._recent_count += 1

    def _shipping(self, ev: ContactEvent, external: np.ndarray, q: np.ndarray) -> dict[str, np.ndarray]:
        """What changes in the event as it goes out: its point's uncertainty with the systematic errors
        (:meth:`_systematic`), then its point on the meshes along the recent wrench's line (:meth:`on_meshes`).
        The frame's sensor pose is shared, and the changes go into the stamped event: one new event
        instead of three (an event frame's thread CPU 297 -> 217 us, median, with the pose kept per q;
        docs/measurements/monitor.md)."""
        if "no_estimate" in ev.flags:
            return {}
        b_T_s = self._sensor_pose(q)
        std = self._systematic(ev, external, b_T_s)
        moved = self._mesh_point(ev, q, std, None, self.recent_external(), b_T_s)
        if moved is not None:
            return {"point": moved[0], "point_std": moved[1]}
        return {} if std is ev.point_std else {"point_std": std}

    def _systematic(self, ev: ContactEvent, external: np.ndarray, b_T_s: np.ndarray) -> np.ndarray:
        """The event's point uncertainty with what no number of frames averages away: the real shell's
        distance from the model's (the touched link's surface tolerance, every axis) and the sensor's gain and
        crosstalk error on the contact's own wrench (``gain_std``: 1 sigma per entry), carried to the
        point across the force's line: ``dc = ([f]x dm - [f]x [c]x df) / |f|^2`` (sensor frame; ``b_T_s``
        the sensor's pose). Its ``point_std`` itself where the event has no force."""
        f = np.asarray(ev.force, dtype=float)
        f2 = float(f @ f)
        if f2 == 0.0:
            return ev.point_std
        r = b_T_s[:3, :3]
        f_s, c_s = r.T @ f, r.T @ (np.asarray(ev.point, dtype=float) - b_T_s[:3, 3])
        sigma_w = np.sqrt(self._gain_var @ (np.asarray(external, dtype=float) ** 2))  # per wrench axis
        k = self._k_work
        k[:, 3:] = skew(f_s)
        k[:, :3] = -k[:, 3:] @ skew(c_s)
        k /= f2
        cov = r @ (k * sigma_w**2) @ k.T @ r.T
        var = np.maximum(cov.diagonal(), 0.0)
        var += self._surface(ev.link) ** 2
        return np.sqrt(np.asarray(ev.point_std, dtype=float) ** 2 + var)

    def _mesh_point(self, ev: ContactEvent, q: np.ndarray, point_std: np.ndarray, shell: MeshShell | None,
                    wrench: np.ndarray | None, b_T_s: np.ndarray | None) -> tuple[np.ndarray, np.ndarray] | None:
        """:meth:`on_meshes`' point and its std (the event's being ``point_std``); None: unchanged.
        ``b_T_s``: the sensor's pose at q where the caller has it."""
        shell = shell or self.mesh_shell
        if shell is None:
            return None
        point, force = np.asarray(ev.point, dtype=float), np.asarray(ev.force, dtype=float)
        f_s = None if wrench is None else np.asarray(wrench[:3], dtype=float)
        if f_s is not None and float(f_s @ f_s) > 0.0:
            if b_T_s is None:
                b_T_s = self._sensor_pose(q)
            on_line = b_T_s[:3, :3] @ (_cross(f_s, wrench[3:]) / float(f_s @ f_s)) + b_T_s[:3, 3]
            force = b_T_s[:3, :3] @ f_s
            u = force / np.linalg.norm(force)
            point = on_line + float((point - on_line) @ u) * u
        entry = shell.entry(ev.link, q, point, force)
        if entry is None:
            return None
        surface = self._surface(ev.link)
        var = np.asarray(point_std, dtype=float) ** 2 - surface**2
        return entry, np.sqrt(np.maximum(var, 0.0) + shell.tolerance.get(ev.link, surface) ** 2)


def contact_event(t_ns: int, kind: str, e: ContactEstimate | None, probability: float,
           track: ContactTrack | None = None, reach: dict[str, float] | None = None) -> ContactEvent:
    """The event always goes out (an onset above all). With a track, its point is the contact's
    fused point and the frame's estimate gives the force and flags; otherwise the frame's own
    estimate, and one it cannot carry (none, no contact, no link or a non-finite value) gives
    zeros and the ``no_estimate`` flag. ``reach``: per link, the size beyond which a point's
    uncertainty (the norm of its standard deviations) says nothing of where on the link it is:
    such an event is flagged ``uncertain``."""
    if track is not None:
        force = e.force if e is not None and math.isfinite(float(e.force.sum())) else np.zeros(3)
        point, std = track.point_and_std()
        flags = _with_uncertain(e.flags if e is not None else (), track.link, std, reach)
        return ContactEvent.make(t_ns, kind, track.link, point, force, std, flags=flags,
                                 probability=probability)
    if e is not None and e.contact and e.link:
        std = e.point_std
        if math.isfinite(float(e.point.sum() + e.force.sum() + std.sum())):
            return ContactEvent.make(t_ns, kind, e.link, e.point, e.force, std,
                                     flags=_with_uncertain(e.flags, e.link, std, reach),
                                     probability=probability)
    z = np.zeros(3)
    flags = (*e.flags, "no_estimate") if e is not None else ("no_estimate",)
    link = e.link if e is not None and e.link else "unknown"
    return ContactEvent.make(t_ns, kind, link, z, z, z, flags=flags, probability=probability)


def gain_std_of(scene: Scene) -> np.ndarray:
    """1 sigma of each entry of the sensor's linear error on a contact's wrench (6 x 6): the scene's
    ``sensor.accuracy`` (relative; an off-diagonal term scaled by the two axes' ranges, as crosstalk is
    specified in per cent of full scale). Not the identification's posterior, though the identified gain
    is undone on the contact's wrench: what free motion tells of the gain leans on the link masses it
    fits beside and on the arm's own loads (its weight along z, the moments of gravity), and its
    posterior under-covered (measured, ur5e typical: coverage 0.77 with the posterior, 0.89 with the
    accuracy). Zeros where the scene has no F/T sensor (its contacts' wrenches come from joint signals)."""
    if scene.sensor is None:
        return np.zeros((6, 6))
    rng = np.asarray(scene.sensor.range, dtype=float)
    return scene.sensor.accuracy * rng[:, None] / rng[None, :]


def _with_uncertain(flags: tuple[str, ...], link: str, std: np.ndarray,
                    reach: dict[str, float] | None) -> tuple[str, ...]:
    size = None if reach is None else reach.get(link)
    if size is None or float(np.linalg.norm(std)) <= size:
        return tuple(flags)
    return (*flags, "uncertain")


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of two 3-vectors, the same products and differences, without its axis handling
    (15 us a call against 1, measured hot)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])
