"""The pipeline's settings: one frozen object, made once (from defaults, a calibration file, the
command line) and passed whole from the session through the monitor to the pipeline's stages.

    PipelineSettings
      corrections   Corrections          what a calibration file corrects (bias, payload, the
                                         identified model); None: not corrected
      motion        MotionSettings       the compensation level, the acceleration estimate, impacts
      detection     DetectionSettings    the detector's false-alarm rate, hysteresis, extra noise
      localization  LocalizationSettings the method and the surface a point is put on
      events        EventSettings        how often an open contact is reported, the track
      joint         JointSettings        the joint-signal pipeline's observer, noise and localizer
                                         (``JointContactPipeline``); optional in JSON (older recordings)

Units: SI (s, N, N m, kg, m, rad); arrays as the stages take them (shapes below). ``to_json`` writes
every field (a recording replays with the settings it was made with, whatever the defaults become);
``from_json`` reads that, and the flat keyword dict that recordings made before this object held
(``{"level": "dynamics", "bias": [...], ...}``), and names any field it does not know or misses.
"""
from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from ftc_hw.compensation.joint_offset import OffsetTracking
from ftc_hw.model import Payload
from ftc_hw.scene import CompensationLevel

SCHEMA = 2  # 1: the flat keyword dict of recordings made before these types (no "schema" key)
SURFACES = ("meshes", "primitives")
METHODS = ("ours", "leng2016")


class SettingsError(ValueError):
    """Settings that cannot be read: a field unknown to this version, a field missing, a bad value."""


@dataclass(frozen=True, eq=False)
class ModelErrorSpec:
    """The identified model's parameter covariance (:class:`~ftc_hw.compensation.ModelError`):
    ``bodies`` the identified bodies, ``cov`` their base parameters' covariance (p x p), ``gain``
    whether the sensor's gain was fitted beside them."""

    bodies: tuple[str, ...]
    cov: np.ndarray
    gain: bool
    # joint-signal identification: per-joint terms (JOINT_TERMS, n each, absolute units) after the bodies'
    # block, fitted with it: the currents' common scale lies along kt and the inertials at once
    joints: tuple[str, ...] = ()

    @property
    def body_cov(self) -> np.ndarray:
        """The bodies' parameters' (and the gain's) covariance alone: what an F/T sensor's wrench sees."""
        k = 10 * len(self.bodies) + (36 if self.gain else 0)
        return self.cov[:k, :k]


@dataclass(frozen=True, eq=False)
class Corrections:
    """What a calibration file corrects (:meth:`ftc_hw.calibration.file.Calibration.corrections`).

    ``bias`` (6,) N, N m: the reading with nothing on the sensor; ``payload`` on the flange;
    ``gain`` (6, 6) the sensor's linear error on the arm's loads; ``contact_gain`` (6, 6) what of it
    is undone on the contact's wrench (None: ``gain``); ``inertials`` body -> (10,) corrections to its
    standard inertial parameters; ``frame`` (6, 6) the sensor's true frame (a mount yaw); ``gravity``
    (3,) m/s^2 in the base frame (a tilt); ``joints`` ``torque_constant``, ``friction_viscous``,
    ``friction_coulomb`` -> (n,) per joint, and from joint-signal identification ``rotor_inertia``
    (kg m^2 beyond the model's armature, seen by the currents only) and ``torque_offset`` (N m, what
    the joint torque sensors read at zero torque); ``model_error`` what the identified model may still
    get wrong; ``joint_residual_std`` signal (``currents`` / ``joint_torques``) -> (n,) N m: the
    identified model's residual std per joint, on signals low-passed over 0.1 s (the model's error);
    ``joint_noise_std`` the same keys -> (n,) N m: each signal's white noise at its recorded rate."""

    bias: np.ndarray | None = None
    payload: Payload | None = None
    gain: np.ndarray | None = None
    contact_gain: np.ndarray | None = None
    inertials: Mapping[str, np.ndarray] | None = None
    frame: np.ndarray | None = None
    gravity: np.ndarray | None = None
    joints: Mapping[str, np.ndarray] | None = None
    model_error: ModelErrorSpec | None = None
    joint_residual_std: Mapping[str, np.ndarray] | None = None
    joint_noise_std: Mapping[str, np.ndarray] | None = None


@dataclass(frozen=True)
class MotionSettings:
    """``level``: the compensation level (None: the scene's); ``use_currents``: joint torques from the
    motor currents for the solver; ``qdd_tau`` s: the acceleration estimate's time constant (its lag
    window is 2 tau); ``impact_window_s``: how long after an onset the arm's reaction to the contact is
    refitted (None: never); ``refine``: with an identified model error, keep refining the model while
    the arm moves free (:class:`~ftc_hw.compensation.OnlineRefiner`)."""

    level: CompensationLevel | None = None
    use_currents: bool = True
    qdd_tau: float = 0.002
    impact_window_s: float | None = 0.005
    refine: bool = False


@dataclass(frozen=True, eq=False)
class DetectionSettings:
    """``p_false``: the false-alarm probability per frame of the chi-square test; ``n_on``/``n_off``:
    frames above / below the threshold for an onset / offset; ``extra_cov`` (6, 6): noise beside the
    sensor's (None: none); ``gap_hold_s``: over missed joint samples the lag error is held at its
    largest of the gap and this long before it (None: never widened)."""

    p_false: float = 1e-9
    n_on: int = 2
    n_off: int = 5
    extra_cov: np.ndarray | None = None
    gap_hold_s: float | None = 0.1


@dataclass(frozen=True)
class LocalizationSettings:
    """``method``: ``ours`` or ``leng2016`` (the reference paper's); ``surface``: ``meshes`` puts each
    event's point where its line of action enters the touched link's meshes, where the scene has them,
    ``primitives`` leaves it on the solver's primitives; ``flag_uncertain``: flag an event whose point
    is less certain than its link is big."""

    method: str = "ours"
    surface: str = "meshes"
    flag_uncertain: bool = True

    def __post_init__(self) -> None:
        if self.surface not in SURFACES:
            raise ValueError(f"surface: expected 'meshes' or 'primitives', got {self.surface!r}")


@dataclass(frozen=True)
class EventSettings:
    """``update_period_s``: an open contact's update event at most this often; ``track_slide`` m/sqrt(s):
    how fast the fused point may slide (None: no track, each event its frame's own estimate);
    ``bias_var_ratio``: a given bias (calibration, scene) is known to this fraction of one sample's
    noise variance."""

    update_period_s: float = 0.02
    track_slide: float | None = 0.01
    bias_var_ratio: float = 0.01


@dataclass(frozen=True)
class JointSettings:
    """The joint-signal pipeline (:mod:`ftc_hw.pipeline.joint`). ``observer_gain`` 1/s: the momentum
    observer's bandwidth (its lag 1/K: 6.7 ms at 150, for onsets within 20 ms; measured on ur5e, typical
    world: 50-100 N probes' median delay 10 ms at 150, 14 ms at 60, same false alarms (none));
    ``friction_rel_std``: 1 sigma of the friction model, relative (the typical world draws +-30 %:
    ``sim_devices/world/reality.py``);
    ``model_rel_std``: of the rigid-body model torque, relative; ``velocity_noise_std`` rad/s: the joint
    velocities' white noise (0: the arm reports a clean velocity); ``spacing_m``/``fine_spacing_m``: the
    localizer's candidate points, coarse and fine; ``friction_mu``: the friction cone a contact force lies in
    (ESTIMATE: 1.0, pushes up to 45 deg off the normal; rubber on painted metal reaches ~1); ``force_prior_n``:
    1 sigma of the force's Gaussian prior (weak: it only regularizes what r cannot tell);
    ``ambiguity_radius_m``/``ambiguity_mass``: flag ``ambiguous`` when more than that share of the
    posterior lies farther than that from the answer; ``significant_sigma``: a joint's residual beyond this
    bounds the touched link; ``localize_period_s``: in contact, localize at the onset and then at most this
    often (the frames between carry the last estimate: a localization costs several times a detection,
    and consecutive frames of the observer's lagged residual say nearly the same; 0: every frame);
    ``link_subspaces``: detect by the per-link matched-subspace tests (each link's joints alone, its own
    chi-square threshold: ``detection/joint.py``) besides the full test; False: the full test alone;
    ``offset``: the joint torque sensors' offsets tracked while the arm is clearly free
    (``compensation/joint_offset.py``; the currents have none)."""

    observer_gain: float = 150.0
    friction_rel_std: float = 0.25
    model_rel_std: float = 0.02
    velocity_noise_std: float = 0.0
    spacing_m: float = 0.02
    fine_spacing_m: float = 0.005
    friction_mu: float = 1.0
    force_prior_n: float = 300.0
    ambiguity_radius_m: float = 0.03
    ambiguity_mass: float = 0.1
    significant_sigma: float = 3.0
    localize_period_s: float = 0.004
    link_subspaces: bool = True
    offset: OffsetTracking = field(default_factory=OffsetTracking)

    def __post_init__(self) -> None:
        if not (self.observer_gain > 0 and self.spacing_m > 0 and self.fine_spacing_m > 0
                and self.localize_period_s >= 0):
            raise ValueError("observer_gain, spacing_m and fine_spacing_m must be > 0, localize_period_s >= 0")


@dataclass(frozen=True, eq=False)
class PipelineSettings:
    """Everything the pipeline is set by, besides its scene (see the module's docstring)."""

    corrections: Corrections = field(default_factory=Corrections)
    motion: MotionSettings = field(default_factory=MotionSettings)
    detection: DetectionSettings = field(default_factory=DetectionSettings)
    localization: LocalizationSettings = field(default_factory=LocalizationSettings)
    events: EventSettings = field(default_factory=EventSettings)
    joint: JointSettings = field(default_factory=JointSettings)

    def with_level(self, level: CompensationLevel | None) -> PipelineSettings:
        """These settings at another compensation level (None: unchanged)."""
        return self if level is None else self.replace(motion=dataclasses.replace(self.motion, level=level))

    def replace(self, **sections: Any) -> PipelineSettings:
        return dataclasses.replace(self, **sections)

    def to_json(self) -> str:
        return json.dumps({"schema": SCHEMA, **{f.name: _section_out(getattr(self, f.name)) for f in fields(self)}})

    @staticmethod
    def from_json(text: str) -> PipelineSettings:
        """The settings ``to_json`` wrote, or a recording's flat keyword dict from before (schema 1)."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise SettingsError(f"pipeline settings are not JSON: {exc}") from None
        if not isinstance(data, dict):
            raise SettingsError(f"pipeline settings: expected a JSON object, got {type(data).__name__}")
        if "schema" not in data:
            data = _from_flat(data)
        elif data["schema"] != SCHEMA:
            raise SettingsError(f"pipeline settings schema {data['schema']!r}: this version reads {SCHEMA}")
        names = set(SECTION_TYPES)
        _check_keys("pipeline settings", data.keys() - {"schema"}, names, names - OPTIONAL_SECTIONS)
        return PipelineSettings(**{name: _section_in(name, data[name]) for name in SECTION_TYPES if name in data})


# fields a recording made before them does not have (their defaults apply)
ADDED_SINCE: dict[str, set[str]] = {"corrections": {"joint_residual_std", "joint_noise_std"}, "joint": {"offset"}}
SECTION_TYPES: dict[str, type] = {"corrections": Corrections, "motion": MotionSettings,
                                   "detection": DetectionSettings, "localization": LocalizationSettings,
                                   "events": EventSettings, "joint": JointSettings}
# sections added since schema 2 was first written: a recording made before them reads with their defaults
OPTIONAL_SECTIONS = frozenset({"joint"})


def _from_flat(flat: dict[str, Any]) -> dict[str, Any]:
    """A flat keyword dict (schema 1: each key a ``ContactPipeline`` keyword) as sections, every field
    not given at its default (the defaults have not changed since)."""
    owner = {f.name: name for name, cls in SECTION_TYPES.items() for f in fields(cls)}
    unknown = sorted(flat.keys() - owner.keys())
    if unknown:
        raise SettingsError(f"recorded pipeline setting(s) {', '.join(unknown)} unknown to this version")
    out: dict[str, Any] = {name: _section_out(cls()) for name, cls in SECTION_TYPES.items()}
    for k, v in flat.items():
        out[owner[k]][k] = v
    return out


def _section_out(section: Any) -> dict[str, Any]:
    return {f.name: _value_out(getattr(section, f.name)) for f in fields(section)}


def _value_out(v: Any) -> Any:
    if isinstance(v, Payload):
        return {"mass": v.mass, "com": list(v.com)}
    if isinstance(v, ModelErrorSpec):
        return {"bodies": list(v.bodies), "cov": np.asarray(v.cov).tolist(), "gain": v.gain, "joints": list(v.joints)}
    if isinstance(v, Mapping):
        return {k: _value_out(x) for k, x in v.items()}
    if isinstance(v, OffsetTracking):
        return _section_out(v)
    return v.tolist() if hasattr(v, "tolist") else v


def _check_keys(where: str, given: set[str], known: set[str], required: set[str]) -> None:
    unknown, missing = sorted(given - known), sorted(required - given)
    if unknown:
        raise SettingsError(f"{where}: field(s) {', '.join(unknown)} unknown to this version")
    if missing:
        raise SettingsError(f"{where}: field(s) {', '.join(missing)} missing")


def _section_in(name: str, data: Any) -> Any:
    cls = SECTION_TYPES[name]
    if not isinstance(data, dict):
        raise SettingsError(f"pipeline settings {name}: expected an object, got {type(data).__name__}")
    names = {f.name for f in fields(cls)}
    _check_keys(f"pipeline settings {name}", set(data), names, names - ADDED_SINCE.get(name, set()))
    values = {k: _value_in(k, v) for k, v in data.items()} if cls is Corrections else dict(data)
    if cls is DetectionSettings and values["extra_cov"] is not None:
        values["extra_cov"] = np.asarray(values["extra_cov"], dtype=float)
    if cls is JointSettings and "offset" in values:
        values["offset"] = _offset_in(values["offset"])
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:
        raise SettingsError(f"pipeline settings {name}: {exc}") from None


def _offset_in(data: Any) -> OffsetTracking:
    """``joint.offset`` as JSON gave it (an older recording's lacks a field added since: its default)."""
    if not isinstance(data, dict):
        raise SettingsError(f"pipeline settings joint.offset: expected an object, got {type(data).__name__}")
    names = {f.name for f in fields(OffsetTracking)}
    _check_keys("pipeline settings joint.offset", set(data), names, set())
    try:
        return OffsetTracking(**data)
    except (TypeError, ValueError) as exc:
        raise SettingsError(f"pipeline settings joint.offset: {exc}") from None


def _value_in(key: str, v: Any) -> Any:
    """A correction as JSON gave it, typed: arrays of floats, a payload, the model error's spec."""
    if v is None:
        return None
    try:
        if key == "payload":
            return Payload(float(v["mass"]), tuple(float(x) for x in v["com"]))
        if key == "model_error":
            return ModelErrorSpec(tuple(v["bodies"]), np.asarray(v["cov"], dtype=float), bool(v["gain"]),
                                  tuple(v.get("joints", ())))
        if key in ("inertials", "joints", "joint_residual_std", "joint_noise_std"):
            return {k: np.asarray(x, dtype=float) for k, x in v.items()}
        return np.asarray(v, dtype=float)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise SettingsError(f"pipeline settings corrections.{key}: {exc!r}") from None
