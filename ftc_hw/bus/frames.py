"""Typed, immutable frames carried by the bus.

Every frame has ``t_host_ns``: the host ``time.monotonic_ns()`` at which it was received (or, for
events, produced). Sensor frames also carry ``t_device_ns`` (the device's own clock, ``None`` when the
device sends none), ``seq`` (a monotonically increasing counter; readers unwrap 16/32-bit device
counters so that a gap is ``seq - last_seq - 1``) and ``source`` (the device name, e.g. ``"ft0"``).

Array fields are float64, read-only (``flags.writeable == False``) and SI: N, N m, rad, rad/s, A, m.
Build frames with the ``make()`` classmethods, which copy, convert and validate (non-finite values
raise :class:`FrameError`). The plain constructors trust their arguments (already read-only float64
arrays of the right shape) and exist for hot paths such as interpolation.

Frames compare by identity (``eq=False``): element-wise array equality has no single truth value.
"""

from __future__ import annotations

import enum
import math
import operator
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Literal, get_args

import numpy as np
import numpy.typing as npt

__all__ = [
    "CONTACT_KINDS",
    "DEVICE_EVENT_KINDS",
    "ContactEvent",
    "ContactKind",
    "DeviceEvent",
    "DeviceEventKind",
    "Frame",
    "FrameError",
    "JointFlag",
    "JointFrame",
    "LimitCheck",
    "WrenchFlag",
    "WrenchFrame",
]


class FrameError(ValueError):
    """A frame could not be built: wrong shape, non-finite value, bad kind or header field."""


class WrenchFlag(enum.IntFlag):
    """Quality flags of a :class:`WrenchFrame` (bit values shared with :class:`JointFlag`)."""

    NONE = 0
    SATURATED = 1  # a gauge/ADC channel hit its limit: the wrench is a lower bound
    OUT_OF_RANGE = 2  # beyond the calibrated range of the sensor
    SEQ_GAP = 4  # frames were lost just before this one
    CLOCK_SUSPECT = 8  # device timestamp inconsistent (reset, jump, alignment not ready)
    INTERPOLATED = 16  # made by Bus.sample_at between two stored frames
    HELD = 32  # made by Bus.sample_at by holding the newest frame (zero-order hold)
    DEVICE_ERROR = 64  # the device's status word reports an error: the reading may be wrong


class JointFlag(enum.IntFlag):
    """Quality flags of a :class:`JointFrame` (bit values shared with :class:`WrenchFlag`)."""

    NONE = 0
    OUT_OF_RANGE = 2  # a joint outside its position limits
    SEQ_GAP = 4
    CLOCK_SUSPECT = 8
    INTERPOLATED = 16
    HELD = 32


# exceedance: the contact's force went past its body region's limit (its ``limits`` say which and by how much)
ContactKind = Literal["onset", "update", "offset", "exceedance"]
# a contact's class (issue 39; ftc_hw/pipeline/classify.py): "" not classified (an older recording), "unknown"
# when neither value is probable enough
CONTACT_CLASSES: frozenset[str] = frozenset({"", "transient", "quasi_static", "unknown"})
INTENTS: frozenset[str] = frozenset({"", "impact", "guidance", "unknown"})
# sensor_lost / arm_lost: the monitor lost the F/T or the joint stream (it is blind: no contact is
# judged; an open contact is closed by an offset flagged "lost"); sensor_back / arm_back: it returned
# stopped: an arm's reader stopped it on a remote monitor's command (ftc serve), its latency in the counters
# counters: a reader process's adapter counters (ftc serve: every second, and a final one flagged "final")
# retreat_short: a retreat (--reflex retreat) that moves some point the contact may be at less than its
# distance (cut to its time limit, its length cap or a joint range): what it does instead, in the message
# provisional_onset: the monitor judged a contact at once, on the joint state extrapolated past the newest joint
# sample (t_host_ns: its first frame's time; the stop reflex acts on it); provisional_unconfirmed: the confirmed
# judgement (on the interpolated joint state) found no contact near such an onset (docs/monitor.md)
DeviceEventKind = Literal["connect", "disconnect", "error", "stale", "recovered", "reconnecting",
                          "sensor_lost", "sensor_back", "arm_lost", "arm_back", "stopped", "counters",
                          "retreat_short", "provisional_onset", "provisional_unconfirmed"]
CONTACT_KINDS: frozenset[str] = frozenset(get_args(ContactKind))
DEVICE_EVENT_KINDS: frozenset[str] = frozenset(get_args(DeviceEventKind))
STREAM_EVENT_KINDS: frozenset[str] = frozenset({"sensor_lost", "sensor_back", "arm_lost", "arm_back"})
PROVISIONAL_EVENT_KINDS: frozenset[str] = frozenset({"provisional_onset", "provisional_unconfirmed"})

FloatArray = npt.NDArray[np.float64]


def _vector(name: str, value: npt.ArrayLike, n: int | None = None) -> FloatArray:
    """Copy ``value`` into a read-only finite float64 vector of length ``n`` (any length if None)."""
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise FrameError(f"{name}: cannot convert to float64 ({exc})") from exc
    if a.ndim != 1 or (n is not None and a.shape[0] != n):
        want = f"({n},)" if n is not None else "(n,)"
        raise FrameError(f"{name}: expected shape {want}, got {a.shape}")
    # a finite sum has no NaN or Inf in it (they propagate); only a non-finite one is looked into
    if not math.isfinite(np.add.reduce(a)) and not (finite := np.isfinite(a)).all():
        bad = np.flatnonzero(~finite).tolist()
        raise FrameError(f"{name}: non-finite value(s) at index {bad}: {a.tolist()}")
    a.flags.writeable = False
    return a


def _int(name: str, value: object) -> int:
    try:
        return operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise FrameError(f"{name}: expected an integer, got {value!r}") from None


def _source(value: object) -> str:
    if not isinstance(value, str) or not value:
        raise FrameError(f"source: expected a non-empty string, got {value!r}")
    return value


def _header(t_host_ns: object, t_device_ns: object, seq: object, source: object) -> tuple:
    t_dev = None if t_device_ns is None else _int("t_device_ns", t_device_ns)
    return _int("t_host_ns", t_host_ns), t_dev, _int("seq", seq), _source(source)


@dataclass(frozen=True, slots=True, eq=False)
class WrenchFrame:
    """One 6-axis force/torque sample: ``wrench = [fx, fy, fz, tx, ty, tz]`` in N and N m."""

    t_host_ns: int
    t_device_ns: int | None
    seq: int
    source: str
    wrench: FloatArray
    flags: WrenchFlag = WrenchFlag.NONE

    @classmethod
    def make(
        cls,
        t_host_ns: int,
        wrench: npt.ArrayLike,
        *,
        source: str,
        seq: int,
        t_device_ns: int | None = None,
        flags: WrenchFlag | int = WrenchFlag.NONE,
    ) -> WrenchFrame:
        """Validate and build; raises :class:`FrameError` on bad shape or NaN/Inf."""
        t_host, t_dev, s, src = _header(t_host_ns, t_device_ns, seq, source)
        return cls(t_host, t_dev, s, src, _vector("wrench", wrench, 6),
                   flags if type(flags) is WrenchFlag else WrenchFlag(flags))

    @property
    def force(self) -> FloatArray:
        """``[fx, fy, fz]`` in N (read-only view)."""
        return self.wrench[:3]

    @property
    def torque(self) -> FloatArray:
        """``[tx, ty, tz]`` in N m (read-only view)."""
        return self.wrench[3:]


@dataclass(frozen=True, slots=True, eq=False)
class JointFrame:
    """Joint state of one arm: ``q`` rad, ``qd`` rad/s, ``current`` A, ``tau`` N m (None if absent)."""

    t_host_ns: int
    t_device_ns: int | None
    seq: int
    source: str
    q: FloatArray
    qd: FloatArray
    current: FloatArray
    tau: FloatArray | None = None
    flags: JointFlag = JointFlag.NONE

    @classmethod
    def make(
        cls,
        t_host_ns: int,
        q: npt.ArrayLike,
        qd: npt.ArrayLike,
        current: npt.ArrayLike,
        tau: npt.ArrayLike | None = None,
        *,
        source: str,
        seq: int,
        t_device_ns: int | None = None,
        flags: JointFlag | int = JointFlag.NONE,
    ) -> JointFrame:
        """Validate and build; all arrays must have the same length n_joints >= 1."""
        t_host, t_dev, s, src = _header(t_host_ns, t_device_ns, seq, source)
        q_a = _vector("q", q)
        if q_a.shape[0] == 0:
            raise FrameError("q: at least one joint expected")
        n = q_a.shape[0]
        tau_a = None if tau is None else _vector("tau", tau, n)
        return cls(
            t_host,
            t_dev,
            s,
            src,
            q_a,
            _vector("qd", qd, n),
            _vector("current", current, n),
            tau_a,
            JointFlag(flags),
        )

    @property
    def n_joints(self) -> int:
        return int(self.q.shape[0])


@dataclass(frozen=True, slots=True)
class LimitCheck:
    """A contact event against its body region's limits (ISO/TS 15066, docs/limits.md): the ``region``
    (and ``region_from``: ``zone``, ``link`` or ``default``), the limit that applies by the contact's class
    (``limit_kind``: ``transient`` or ``quasi_static``; ``class_assumed``: the contact had no class, so the
    stricter quasi-static limit), that limit ``limit_n`` (N) and the ``margin_n`` to it (N, the limit less
    the event's force: < 0 exceeded); the arm's ``effective_mass_kg`` at the point along the contact's
    normal (the touched surface's), the arm's ``speed_mps`` there along the force's line at the onset (m/s,
    > 0 into the contact) and the region's ``permissible_speed_mps`` for a transient contact with that mass."""

    region: str
    region_from: str
    limit_kind: str
    class_assumed: bool
    limit_n: float
    margin_n: float
    effective_mass_kg: float
    speed_mps: float
    permissible_speed_mps: float


@dataclass(frozen=True, slots=True, eq=False)
class ContactEvent:
    """A contact estimate: ``point`` (m, base frame) where ``force`` (N, applied to the arm) acts.
    ``contact_id`` (from 1 in a run; 0: none) pairs a contact's onset, updates and offset; the
    contact's figures so far: ``duration_s`` (s since its onset), ``peak_force`` (N, the largest
    external force) and ``impulse`` (N s, the external force's magnitude integrated over time).
    ``limits``: the event against its body region's limits (None: not judged).
    Its class so far (provisional at the onset and updates, final at the offset; docs/contacts.md):
    ``contact_class`` ``transient`` | ``quasi_static`` (ISO/TS 15066: clamped, the arm cannot move away)
    | ``unknown`` (neither probable enough) | ``""`` (not classified), with ``p_quasi_static``;
    ``intent`` ``impact`` (accidental) | ``guidance`` (a person leading the arm) | ``unknown`` | ``""``, with
    ``p_guidance``; ``class_features``: the features the class was drawn from (name -> value, SI)."""

    t_host_ns: int
    kind: ContactKind
    link: str
    point: FloatArray
    force: FloatArray
    point_std: FloatArray
    flags: tuple[str, ...] = ()
    probability: float = 1.0
    contact_id: int = 0
    duration_s: float = 0.0
    peak_force: float = 0.0
    impulse: float = 0.0
    limits: LimitCheck | None = None
    contact_class: str = ""
    p_quasi_static: float = 0.5
    intent: str = ""
    p_guidance: float = 0.5
    class_features: Mapping[str, float] = field(default_factory=lambda: _NO_COUNTERS)

    @classmethod
    def make(
        cls,
        t_host_ns: int,
        kind: ContactKind,
        link: str,
        point: npt.ArrayLike,
        force: npt.ArrayLike,
        point_std: npt.ArrayLike = (0.0, 0.0, 0.0),
        *,
        flags: tuple[str, ...] | list[str] = (),
        probability: float = 1.0,
        contact_id: int = 0,
        duration_s: float = 0.0,
        peak_force: float = 0.0,
        impulse: float = 0.0,
        limits: LimitCheck | None = None,
        contact_class: str = "",
        p_quasi_static: float = 0.5,
        intent: str = "",
        p_guidance: float = 0.5,
        class_features: Mapping[str, float] | None = None,
    ) -> ContactEvent:
        """Validate and build; ``point_std`` (m) must be >= 0, ``probability`` and the class's
        probabilities in [0, 1], the contact's id and figures >= 0, its class one of the known."""
        if kind not in CONTACT_KINDS:
            raise FrameError(f"kind: expected one of {sorted(CONTACT_KINDS)}, got {kind!r}")
        if not isinstance(link, str) or not link:
            raise FrameError(f"link: expected a non-empty string, got {link!r}")
        std = _vector("point_std", point_std, 3)
        if (std < 0).any():
            raise FrameError(f"point_std: must be >= 0, got {std.tolist()}")
        p = float(probability)
        if not 0.0 <= p <= 1.0:  # also rejects NaN
            raise FrameError(f"probability: must be in [0, 1], got {probability!r}")
        if contact_class not in CONTACT_CLASSES or intent not in INTENTS:
            raise FrameError(f"class: expected one of {sorted(CONTACT_CLASSES)} and {sorted(INTENTS)}, "
                             f"got {contact_class!r}, {intent!r}")
        for name, v in (("p_quasi_static", p_quasi_static), ("p_guidance", p_guidance)):
            if not 0.0 <= float(v) <= 1.0:
                raise FrameError(f"{name}: must be in [0, 1], got {v!r}")
        features = MappingProxyType({str(k): float(v) for k, v in (class_features or {}).items()})
        if not all(map(math.isfinite, features.values())):
            raise FrameError("class_features: a non-finite value")
        return cls(
            _int("t_host_ns", t_host_ns),
            kind,
            link,
            _vector("point", point, 3),
            _vector("force", force, 3),
            std,
            tuple(str(f) for f in flags),
            p,
            _count("contact_id", contact_id),
            *(_non_negative(k, v) for k, v in (("duration_s", duration_s), ("peak_force", peak_force),
                                               ("impulse", impulse))),
            limits,
            contact_class, float(p_quasi_static), intent, float(p_guidance), features,
        )


def _count(name: str, value: object) -> int:
    n = _int(name, value)
    if n < 0:
        raise FrameError(f"{name}: must be >= 0, got {n}")
    return n


def _non_negative(name: str, value: object) -> float:
    x = float(value)  # type: ignore[arg-type]
    if not x >= 0.0 or not math.isfinite(x):  # also rejects NaN
        raise FrameError(f"{name}: must be a finite number >= 0, got {value!r}")
    return x


_NO_COUNTERS: Mapping[str, float] = MappingProxyType({})


@dataclass(frozen=True, slots=True, eq=False)
class DeviceEvent:
    """Something happened to a device or stream: connect, disconnect, error, stale, recovered, ..."""

    t_host_ns: int
    source: str
    kind: DeviceEventKind
    message: str = ""
    counters: Mapping[str, float] = field(default_factory=lambda: _NO_COUNTERS)

    @classmethod
    def make(
        cls,
        t_host_ns: int,
        source: str,
        kind: DeviceEventKind,
        message: str = "",
        counters: Mapping[str, float] | None = None,
    ) -> DeviceEvent:
        """Validate and build; ``counters`` is copied into a read-only mapping."""
        if kind not in DEVICE_EVENT_KINDS:
            raise FrameError(f"kind: expected one of {sorted(DEVICE_EVENT_KINDS)}, got {kind!r}")
        c = _NO_COUNTERS if not counters else MappingProxyType(dict(counters))
        return cls(_int("t_host_ns", t_host_ns), _source(source), kind, str(message), c)


Frame = WrenchFrame | JointFrame | ContactEvent | DeviceEvent
"""Anything the bus carries. The bus itself only needs ``t_host_ns`` (and ``seq`` if present)."""
