"""The pipeline's stage roles, as :class:`ContactPipeline` calls them. A new sensor model (joint torques,
motor currents alone, a flange sensor) is a new implementation of a role, not a new branch in
``process``. Today's implementations: :class:`~ftc_hw.pipeline.motion.MotionStage`,
:class:`~ftc_hw.detection.ContactDetector`, :class:`~ftc_hw.pipeline.localization.LocalizationStage`,
:class:`~ftc_hw.pipeline.events.ContactEvents`.

Arrays: ``q``, ``qd``, ``qdd``, ``current`` (n,) in rad, rad/s, rad/s^2, A; wrenches (6,) [fx, fy, fz,
tx, ty, tz] in N, N m, sensor frame; times ns (host, or the device's where named).
"""
from __future__ import annotations

from typing import Protocol

import numpy as np

from ftc_hw.bus import ContactEvent
from ftc_hw.detection import Detection
from ftc_hw.solver import ContactEstimate

from .motion import Compensated


class Compensation(Protocol):
    """A reading and the joint state in; the external wrench and its error rows out."""

    level: str

    def warm_up(self) -> None: ...

    def compensate(self, t_ns: int, raw, q: np.ndarray, qd, qdd, *, joint_torques: bool, in_contact: bool,
                   t_device_ns: int | None = None, joint_gap_ns: int = 0) -> Compensated: ...

    def joint_torques(self, q: np.ndarray, qd, qdd, model_tau: np.ndarray | None) -> np.ndarray: ...

    def refine(self, t_ns: int, external: np.ndarray, q: np.ndarray, qd, qdd, *, touched: bool,
               clearly_free: bool) -> None: ...

    def tare(self, raw_mean, q) -> None: ...

    def restart(self) -> None: ...


class Detector(Protocol):
    """The external wrench and its error rows in; onset, in contact, offset out."""

    active: bool
    on: float

    def update(self, t_ns: int, external: np.ndarray, model_error: np.ndarray | None) -> Detection: ...

    def reset(self) -> None: ...


class Localization(Protocol):
    """A frame in contact: where on the arm and how hard, with covariance."""

    residuals: object | None  # the joint torques from the currents (None: not used)

    def warm_up(self, home: np.ndarray) -> None: ...

    def observe_currents(self, current, in_contact: bool) -> None: ...

    def clear_frame(self) -> None: ...

    def external_torques(self, model_tau: np.ndarray, current, qd) -> tuple[np.ndarray, np.ndarray]: ...

    def in_impact(self, det: Detection, t_ns: int) -> bool: ...

    def begin_contact(self) -> None: ...

    def restart(self) -> None: ...

    def solve(self, external, q, tau_ext, tau_std, saturated: bool, model_error,
              impact: bool) -> ContactEstimate: ...

    def solved_poses(self): ...


class PipelineView:
    """What the monitor, replay and the CLI read of a pipeline besides its frames, the same for
    :class:`~ftc_hw.pipeline.contact.ContactPipeline` and the joint-signal pipeline: whether a contact is
    open and where its events put their points. Needs ``detector`` and ``events`` attributes."""

    detector: Detector
    events: Events

    @property
    def surface_source(self) -> str:
        """Where events put their points: ``meshes`` or ``primitives``."""
        return self.events.surface_source

    @property
    def in_contact(self) -> bool:
        return self.detector.active


class Events(Protocol):
    """The contact's track and its onset, update and offset events."""

    track: object | None
    previous: object | None
    surface_source: str

    def warm_up(self) -> None: ...

    def fuse(self, t_ns: int, estimate: ContactEstimate, q: np.ndarray, poses) -> None: ...

    def set_bias(self, ratio: float, t_ns: int) -> None: ...

    def frame_events(self, t_ns: int, det: Detection, estimate: ContactEstimate | None, external: np.ndarray,
                     q: np.ndarray, power: float | None = None) -> list[ContactEvent]: ...

    def close_contact(self, t_ns: int, probability: float | None = None, *, lost: bool = False) -> ContactEvent: ...
