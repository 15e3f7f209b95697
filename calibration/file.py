"""The calibration file: TOML with a schema version, the sensor's serial, the scene, the date, the
parameters with their standard errors, the fit's figures and the pose set.

``load_calibration(path, scene=..., sensor_serial=...)`` checks it against the setup it is meant for
and raises :class:`CalibrationError` (with the file and the key) on anything wrong: schema, scene,
sensor serial, missing or malformed values. ``cal.corrections(scene)`` gives ``ContactPipeline``
(:class:`~ftc_hw.pipeline.Corrections`) everything the file estimates: bias, payload, and
(:mod:`.applied`) the mount yaw, gravity tilt, arm-gravity corrections and ``[identification]``
(``ftc identify``: link inertials, the load gain; or, from the joints' own signals, link inertials,
torque constants, joint friction, rotor inertias, torque sensors' offsets and the joint residuals' std).
"""
from __future__ import annotations

import dataclasses
import datetime as dt
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from ftc_hw.model import Payload
from ftc_hw.pipeline import Corrections, ModelErrorSpec
from ftc_hw.scene import Scene, load_scene

from .applied import extra_corrections, merge_inertials

SCHEMA = 1
KIND = "ftc-hw calibration"
JOINT_KEYS = ("torque_constant", "friction_viscous", "friction_coulomb")  # per joint, >= 0 (kt > 0)
SIGNED_JOINT_KEYS = ("rotor_inertia", "torque_offset")  # per joint, any sign (corrections about the model)
SIGNALS = ("currents", "joint_torques")


class CalibrationError(Exception):
    """A calibration file that cannot be used: malformed, another schema, scene or sensor."""


@dataclass
class Identification:
    """``ftc identify``'s result: what the pipeline applies and how far to trust it."""

    date: str
    source: str  # the recording, or what the simulated run was
    verdict: str
    reasons: list[str]
    gain: np.ndarray  # 6 x 6: the sensor's linear error on the arm's loads (reading = gain @ loads + bias)
    inertials: dict[str, np.ndarray]  # body -> 10 standard-parameter corrections
    untold: list[str] = field(default_factory=list)
    figures: dict[str, Any] = field(default_factory=dict)  # residual RMS before/after, samples, stds
    joints: dict[str, np.ndarray] = field(default_factory=dict)  # torque_constant, friction_viscous, _coulomb
    # the posterior covariance of [10 per body of ``inertials`` (in its order), 36 of the gain (if fitted)]
    covariance: np.ndarray | None = None
    gain_fitted: bool = True
    # what the pipeline undoes on a contact's wrench: the gain in the directions the data told
    # (FreeMotionFit.told_gain); None in files written before it was kept
    contact_gain: np.ndarray | None = None
    # what it was identified from: "base_ft" (and currents, for the joints' friction), or the joint
    # signals ("currents", "joint_torques", comma-separated)
    sensing: str = "base_ft"
    joint_residual_std: dict[str, np.ndarray] = field(default_factory=dict)  # signal -> (n,) N m
    joint_noise_std: dict[str, np.ndarray] = field(default_factory=dict)  # signal -> (n,) N m
    # the per-joint terms ``covariance`` holds after the bodies' block (joint-signal identification: keys of
    # ``joints``, n each, their own units), fitted with the inertials
    covariance_joints: tuple[str, ...] = ()

    def told_gain(self) -> np.ndarray:
        """What the pipeline undoes on a contact's wrench: ``contact_gain``; for a file without it, the
        gain when the data told every one of its terms, else nothing (the identity)."""
        if self.contact_gain is not None:
            return self.contact_gain.copy()
        if any(u.startswith("gain[") for u in self.untold):
            return np.eye(6)
        return self.gain.copy()

    def model_error(self) -> ModelErrorSpec | None:
        """What the identified model may still get wrong, as the pipeline takes it."""
        if self.covariance is None:
            return None
        return ModelErrorSpec(tuple(self.inertials), self.covariance.copy(), self.gain_fitted, self.covariance_joints)

    def to_dict(self) -> dict[str, Any]:
        out = {"date": self.date, "source": self.source, "verdict": self.verdict, "reasons": list(self.reasons),
               "load_gain": [_floats(r) for r in self.gain], "untold": list(self.untold),
               "inertials": {k: _floats(v) for k, v in self.inertials.items()},
               "figures": {k: _clean(v) for k, v in self.figures.items()}}
        if self.joints:
            out["joints"] = {k: _floats(v) for k, v in self.joints.items()}
        if self.covariance is not None:
            out["covariance"] = [_floats(r) for r in self.covariance]
            out["gain_fitted"] = self.gain_fitted
            if self.covariance_joints:
                out["covariance_joints"] = list(self.covariance_joints)
        if self.contact_gain is not None:
            out["contact_gain"] = [_floats(r) for r in self.contact_gain]
        out["sensing"] = self.sensing
        for key in ("joint_residual_std", "joint_noise_std"):
            if getattr(self, key):
                out[key] = {k: _floats(v) for k, v in getattr(self, key).items()}
        return out

    @staticmethod
    def from_dict(data: Any, where: str) -> Identification:
        if not isinstance(data, dict):
            raise CalibrationError(f"{where}: expected a table")
        gain = _gain_matrix(data, "load_gain", where)
        contact_gain = _gain_matrix(data, "contact_gain", where) if "contact_gain" in data else None
        table = _get(data, "inertials", dict, where)
        inertials = {str(k): _vec(table, k, 10, f"{where}: inertials") for k in table}
        joints = {}
        jt = data.get("joints", {})
        for key in (*JOINT_KEYS, *SIGNED_JOINT_KEYS):
            if key in jt:
                v = _joint_vector(jt, key, f"{where}: joints")
                if key in JOINT_KEYS and (np.any(v < 0) or (key == "torque_constant" and np.any(v <= 0))):
                    raise CalibrationError(f"{where}: joints: {key}: expected finite numbers >= 0 (> 0 for a "
                                           f"torque constant), got {jt[key]!r}")
                joints[key] = v
        stds = {}
        for key in ("joint_residual_std", "joint_noise_std"):
            table = data.get(key, {})
            if not isinstance(table, dict) or set(table) - set(SIGNALS):
                raise CalibrationError(f"{where}: {key}: expected a table of {', '.join(SIGNALS)}")
            stds[key] = {k: _joint_vector(table, k, f"{where}: {key}") for k in table}
            if any(np.any(v < 0) for v in stds[key].values()):
                raise CalibrationError(f"{where}: {key}: expected standard deviations >= 0")
        cov = None
        cov_joints = tuple(str(k) for k in data.get("covariance_joints", ()))
        if set(cov_joints) - set(joints):
            raise CalibrationError(f"{where}: covariance_joints: expected keys of joints, got {list(cov_joints)}")
        if "covariance" in data:
            n = 10 * len(inertials) + (36 if data.get("gain_fitted", True) else 0)
            n += sum(joints[k].size for k in cov_joints)
            try:
                cov = np.array(data["covariance"], dtype=float)
            except (TypeError, ValueError):
                cov = None
            if cov is None or cov.shape != (n, n) or not np.all(np.isfinite(cov)):
                raise CalibrationError(f"{where}: covariance: expected {n} x {n} finite numbers")
        return Identification(str(data.get("date", "")), str(data.get("source", "")), str(data.get("verdict", "")),
                              [str(r) for r in data.get("reasons", [])], gain, inertials,
                              [str(u) for u in data.get("untold", [])], dict(data.get("figures", {})), joints,
                              cov, bool(data.get("gain_fitted", True)), contact_gain,
                              str(data.get("sensing", "base_ft")), stds["joint_residual_std"], stds["joint_noise_std"],
                              cov_joints)


def _joint_vector(table: dict, key: str, where: str) -> np.ndarray:
    try:
        v = np.asarray(_get(table, key, list, where), dtype=float)
    except (TypeError, ValueError):
        raise CalibrationError(f"{where}: {key}: expected a list of numbers, got {table[key]!r}") from None
    if v.ndim != 1 or not np.all(np.isfinite(v)):
        raise CalibrationError(f"{where}: {key}: expected finite numbers, got {table[key]!r}")
    return v


def _gain_matrix(data: dict, key: str, where: str) -> np.ndarray:
    rows = _get(data, key, list, where)
    if len(rows) != 6:
        raise CalibrationError(f"{where}: {key}: expected 6 rows of 6 numbers")
    gain = np.array([_vec({"row": r}, "row", 6, f"{where}: {key}") for r in rows])
    if abs(np.linalg.det(gain)) < 1e-6:
        raise CalibrationError(f"{where}: {key}: singular")
    return gain


@dataclass
class Calibration:
    scene: str
    sensor_serial: str | None
    date: str  # ISO 8601, UTC
    bias: np.ndarray  # [fx, fy, fz, tx, ty, tz] N, N m: what the sensor reads with nothing on it
    payload: Payload | None  # mass kg, com m in the flange frame
    std: dict[str, Any] = field(default_factory=dict)  # 1-sigma: force_bias, torque_bias, mass, com, ...
    verdict: str = "good"
    reasons: list[str] = field(default_factory=list)
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (N, n) rad
    samples_per_pose: int = 0
    extras: dict[str, Any] = field(default_factory=dict)  # mount_yaw, gravity_tilt_*, arm_gravity_*
    fit: dict[str, Any] = field(default_factory=dict)  # residual_rms, condition_number, chi2, dof
    rezero: list[dict[str, Any]] = field(default_factory=list)  # {date, bias}: re-zero history
    identification: Identification | None = None  # ftc identify's result

    def corrections(self, scene: Scene | None = None) -> Corrections:
        """Everything the file estimates, as the pipeline takes it (``PipelineSettings(corrections=...)``).
        ``scene``: the one it was made for (None: the built-in scene of that name, when it has extras)."""
        out: dict[str, Any] = {"bias": self.bias.copy(), "payload": self.payload}
        extras = {}
        if any(not isinstance(v, str) and np.any(np.asarray(v, dtype=float) != 0) for v in self.extras.values()):
            if scene is None:
                try:
                    scene = load_scene(self.scene)
                except ValueError as exc:
                    raise CalibrationError(f"its corrections need the scene {self.scene!r}: {exc}") from None
            extras = extra_corrections(self.extras, scene)
        out.update({k: v for k, v in extras.items() if k != "inertials"})
        tables = [extras.get("inertials", {})]
        if self.identification is not None:
            tables.append(self.identification.inertials)
            out["gain"] = self.identification.gain.copy()
            out["contact_gain"] = self.identification.told_gain()
            if self.identification.joints:
                out["joints"] = {k: v.copy() for k, v in self.identification.joints.items()}
            out["model_error"] = self.identification.model_error()
            for key in ("joint_residual_std", "joint_noise_std"):
                if getattr(self.identification, key):
                    out[key] = {k: v.copy() for k, v in getattr(self.identification, key).items()}
        inertials = merge_inertials(*tables)
        if inertials:
            out["inertials"] = inertials
        return Corrections(**out)

    def with_bias(self, bias, when: str | None = None) -> Calibration:
        """A copy with a new bias (a re-zero), the old one kept in the history."""
        when = when or now_iso()
        history = [*self.rezero, {"date": when, "bias": [float(x) for x in bias]}]
        return dataclasses.replace(self, bias=np.asarray(bias, dtype=float).copy(), rezero=history)

    def to_dict(self) -> dict[str, Any]:
        params: dict[str, Any] = {"force_bias_N": _floats(self.bias[:3]), "torque_bias_Nm": _floats(self.bias[3:])}
        if self.payload is not None:
            params["mass_kg"] = float(self.payload.mass)
            params["com_m"] = _floats(self.payload.com)
        else:
            params["mass_kg"] = 0.0
        params.update({k: _clean(v) for k, v in self.extras.items()})
        out: dict[str, Any] = {
            "schema": SCHEMA, "kind": KIND, "scene": self.scene, "sensor_serial": self.sensor_serial or "",
            "date": self.date, "verdict": self.verdict, "reasons": list(self.reasons),
            "parameters": params, "uncertainty": {k: _clean(v) for k, v in self.std.items() if v is not None},
            "fit": {k: _clean(v) for k, v in self.fit.items()},
            "poses": {"q_rad": [_floats(q) for q in self.poses], "samples_per_pose": int(self.samples_per_pose)},
        }
        if self.rezero:
            out["rezero"] = [{"date": r["date"], "bias": _floats(r["bias"])} for r in self.rezero]
        if self.identification is not None:
            out["identification"] = self.identification.to_dict()
        return out


def now_iso() -> str:
    return dt.datetime.now(dt.UTC).replace(microsecond=0).isoformat().replace("+00:00", "Z")


def _floats(v) -> list[float]:
    return [float(x) for x in np.asarray(v, dtype=float).ravel()]


def _clean(v: Any) -> Any:
    """TOML has no null and no inf: drop None, write non-finite numbers as the string "inf"."""
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items() if x is not None}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_clean(x) for x in (v.tolist() if isinstance(v, np.ndarray) else v)]
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf" if v < 0 else "nan")
    if isinstance(v, np.integer):
        return int(v)
    return v


def save_calibration(cal: Calibration, path: str | Path) -> Path:
    path = Path(path)
    path.write_text(tomli_w.dumps(cal.to_dict()))
    return path


def _get(data: dict, key: str, kind: type | tuple[type, ...], where: str) -> Any:
    if key not in data:
        raise CalibrationError(f"{where}: {key}: missing")
    v = data[key]
    if not isinstance(v, kind) or isinstance(v, bool) and kind is not bool:
        raise CalibrationError(f"{where}: {key}: expected {getattr(kind, '__name__', kind)}, got {v!r}")
    return v


def _vec(data: dict, key: str, n: int, where: str) -> np.ndarray:
    v = _get(data, key, list, where)
    try:
        a = np.array(v, dtype=float)
    except (TypeError, ValueError):
        raise CalibrationError(f"{where}: {key}: expected {n} numbers, got {v!r}") from None
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise CalibrationError(f"{where}: {key}: expected {n} finite numbers, got {v!r}")
    return a


def load_calibration(path: str | Path, scene: Scene | str | None = None,
                     sensor_serial: str | None = None) -> Calibration:
    """Read and check a calibration file. ``scene`` (a Scene or its name) and ``sensor_serial``: what
    it must have been made for (None: not checked). A file without a serial (the sensor reports none)
    passes any serial; a file with one must match the given serial exactly."""
    path = Path(path)
    where = path.name
    try:
        data = tomllib.loads(path.read_text())
    except OSError as exc:
        raise CalibrationError(f"{where}: cannot read: {exc}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise CalibrationError(f"{where}: not valid TOML: {exc}") from exc
    schema = _get(data, "schema", int, where)
    if schema != SCHEMA:
        raise CalibrationError(f"{where}: schema: this version reads schema {SCHEMA}, the file has {schema}")
    if data.get("kind", KIND) != KIND:
        raise CalibrationError(f"{where}: kind: expected {KIND!r}, got {data.get('kind')!r}")
    scene_name = _get(data, "scene", str, where)
    if scene is not None:
        want = scene if isinstance(scene, str) else scene.name
        if want != scene_name:
            raise CalibrationError(f"{where}: scene: made for scene {scene_name!r}, not {want!r}")
    serial = str(data.get("sensor_serial", "")) or None
    if sensor_serial is not None and serial is not None and str(sensor_serial) != serial:
        raise CalibrationError(f"{where}: sensor_serial: made for sensor {serial!r}, but the connected sensor is "
                               f"{sensor_serial!r}: calibrate this sensor (ftc calibrate)")
    params = _get(data, "parameters", dict, where)
    pw = f"{where}: parameters"
    bias = np.concatenate([_vec(params, "force_bias_N", 3, pw), _vec(params, "torque_bias_Nm", 3, pw)])
    mass = float(_get(params, "mass_kg", (int, float), pw))
    payload = None
    if mass > 0:
        com = _vec(params, "com_m", 3, pw)
        payload = Payload(mass, (float(com[0]), float(com[1]), float(com[2])))
    elif mass < 0 or not math.isfinite(mass):
        raise CalibrationError(f"{pw}: mass_kg: expected a mass >= 0 kg, got {mass}")
    extras = {k: v for k, v in params.items() if k not in ("force_bias_N", "torque_bias_Nm", "mass_kg", "com_m")}
    poses = data.get("poses", {})
    try:
        q = np.array(poses.get("q_rad", []), dtype=float)
    except (TypeError, ValueError):
        raise CalibrationError(f"{where}: poses: q_rad: expected a list of joint vectors") from None
    return Calibration(scene=scene_name, sensor_serial=serial, date=str(data.get("date", "")), bias=bias,
                       payload=payload, std=dict(data.get("uncertainty", {})), verdict=str(data.get("verdict", "")),
                       reasons=list(data.get("reasons", [])), poses=q,
                       samples_per_pose=int(poses.get("samples_per_pose", 0)), extras=extras,
                       fit=dict(data.get("fit", {})), rezero=list(data.get("rezero", [])),
                       identification=(Identification.from_dict(data["identification"], f"{where}: identification")
                                       if "identification" in data else None))


def calibration_from_fit(fit, scene: Scene, sensor_serial: str | None, poses: np.ndarray,
                         samples_per_pose: int) -> Calibration:
    """A Calibration from :class:`ftc_hw.calibration.identify.Fit`. No payload when the fit found none."""
    d, s = fit.derived, fit.derived_std
    payload = None
    if d.get("com") is not None and fit.mass > 0:
        c = d["com"]
        payload = Payload(float(fit.mass), (float(c[0]), float(c[1]), float(c[2])))
    extras = {k: float(d[k]) for k in fit.names[10:]}
    std = {"force_bias_N": s["force_bias"], "torque_bias_Nm": s["torque_bias"], "mass_kg": s["mass"]}
    if s.get("com") is not None:
        std["com_m"] = s["com"]
    std.update({k: s[k] for k in fit.names[10:]})
    figures = {"residual_rms": fit.residual_rms.tolist(), "condition_number": fit.condition_number,
               "chi2": fit.chi2, "dof": fit.dof, "parameters": list(fit.names), "covariance": fit.cov.tolist()}
    return Calibration(scene=scene.name, sensor_serial=sensor_serial, date=now_iso(), bias=fit.bias, payload=payload,
                       std=std, verdict=fit.verdict, reasons=list(fit.reasons), poses=np.asarray(poses, dtype=float),
                       samples_per_pose=int(samples_per_pose), extras=extras, fit=figures)
