"""Reading scene TOML files into `Scene` objects, with errors that name the file and the key."""
from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from .device_params import ParamError, check_params, check_transport, device_kind
from .errors import SceneError
from .schema import (
    COMPENSATION_LEVELS,
    SENSING_KINDS,
    SENSOR_MOUNTS,
    SIGN_CONVENTIONS,
    Coupling,
    DeviceSpec,
    JointTorqueSpec,
    RobotSpec,
    Scene,
    SensorSpec,
    TouchableLink,
    _frozen,
)
from .vendor import VENDOR_SHELLS
from .world_spec import IDEAL, InertialError, WorldSpec

SCHEMA_VERSION = 1
_BUILTIN_DIR = Path(__file__).resolve().parent / "builtin"


def builtin_dir() -> Path:
    return _BUILTIN_DIR


def builtin_names() -> list[str]:
    """The built-in scenes, each its own arm and sensor (what the benches and tests run by default)."""
    return sorted(p.stem for p in builtin_dir().glob("*.toml"))


def variant_names() -> list[str]:
    """Built-in variants: scenes that extend a built-in one (``ur5e-netft``: ur5e on another F/T
    interface), in ``builtin/variants``; loaded by name like the others."""
    return sorted(p.stem for p in (builtin_dir() / "variants").glob("*.toml"))


def resolve(name_or_path: str | Path) -> Path:
    """A built-in scene name (``ur5e``), a variant's (``ur5e-netft``), or a path to a TOML file."""
    text = str(name_or_path)
    if text in builtin_names():
        return builtin_dir() / f"{text}.toml"
    if text in variant_names():
        return builtin_dir() / "variants" / f"{text}.toml"
    path = Path(text)
    if path.suffix == ".toml" or path.exists() or "/" in text:
        return path
    names = ", ".join(builtin_names() + variant_names())
    raise SceneError(text, "", f"no built-in scene of that name (built-ins: {names}) and no such file")


def load_scene(name_or_path: str | Path) -> Scene:
    """Load a built-in scene by name or a user scene from a path."""
    path = resolve(name_or_path)
    return _Parser(path).scene(_read_extended(path, ()))


def _read_toml(path: Path) -> dict:
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise SceneError(path, "", f"cannot read the scene file ({exc.strerror or exc})") from exc
    try:
        return tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise SceneError(path, "", f"not UTF-8 text ({exc})") from exc
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(path, "", f"invalid TOML: {exc}") from exc


def _read_extended(path: Path, seen: tuple[Path, ...]) -> dict:
    """The file's tables, over those of the scene it ``extends`` (a path relative to it, or a built-in
    name): tables merge key by key, anything else (values, arrays, ``[[devices]]``) is replaced whole.
    Paths in the merged tables (``robot.model``) are relative to the extending file."""
    data = _read_toml(path)
    base = data.pop("extends", None)
    if base is None:
        return data
    if not isinstance(base, str):
        raise SceneError(path, "extends", f"expected a scene name or path, got {type(base).__name__}")
    base_path = builtin_dir() / f"{base}.toml" if base in builtin_names() else (path.parent / base).resolve()
    if base_path.resolve() in seen or base_path.resolve() == path.resolve():
        raise SceneError(path, "extends", f"{base!r} extends this scene again (a cycle)")
    if not base_path.is_file():
        raise SceneError(path, "extends", f"no built-in scene {base!r} and no file {base_path}")
    return _merged(_read_extended(base_path, (*seen, path.resolve())), data)


def _merged(base: dict, over: dict) -> dict:
    out = dict(base)
    for key, value in over.items():
        old = out.get(key)
        out[key] = _merged(old, value) if isinstance(old, dict) and isinstance(value, dict) else value
    return out


_JOINT_SENSING_KEYS = ("gear_ratio", "motor_angle_offset", "current_ripple", "cogging_torque",
                       "torque_constant_per_K", "friction_per_K", "winding_start_K", "winding_heating_K_per_A2",
                       "winding_tau_s", "joint_torque_offset", "joint_torque_drift_per_K")


class _Parser:
    def __init__(self, path: Path) -> None:
        self.path = path

    def fail(self, key: str, problem: str) -> SceneError:
        return SceneError(self.path, key, problem)

    # -- primitive readers -------------------------------------------------------------------------
    def table(self, data: dict, key: str, prefix: str = "") -> dict:
        full = f"{prefix}{key}"
        if key not in data:
            raise self.fail(full, "missing table")
        value = data[key]
        if not isinstance(value, dict):
            raise self.fail(full, f"expected a table, got {type(value).__name__}")
        return value

    def get(self, data: dict, key: str, prefix: str, kind: type | tuple[type, ...], default: Any = ...) -> Any:
        full = f"{prefix}{key}"
        if key not in data:
            if default is ...:
                raise self.fail(full, f"missing key (expected {_kind_name(kind)})")
            return default
        value = data[key]
        if isinstance(value, bool) and kind is not bool and bool not in _as_tuple(kind):
            raise self.fail(full, f"expected {_kind_name(kind)}, got a boolean")
        if not isinstance(value, kind):
            raise self.fail(full, f"expected {_kind_name(kind)}, got {type(value).__name__} {value!r}")
        return value

    def number(self, data: dict, key: str, prefix: str, *, positive: bool = False, default: Any = ...) -> float:
        value = float(self.get(data, key, prefix, (int, float), default))
        if not math.isfinite(value):
            raise self.fail(prefix + key, f"expected a finite number, got {value}")
        if positive and value <= 0:
            raise self.fail(prefix + key, f"expected a positive number, got {value}")
        return value

    def vector(self, data: dict, key: str, prefix: str, n: int, *, nonneg: bool = False,
               positive: bool = False, default: Any = ...) -> Any:
        full = f"{prefix}{key}"
        if key not in data and default is not ...:
            return None if default is None else _frozen(default)
        value = self.get(data, key, prefix, list)
        if len(value) != n:
            raise self.fail(full, f"expected a list of {n} numbers, got {len(value)}")
        for i, v in enumerate(value):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise self.fail(f"{full}[{i}]", f"expected a number, got {type(v).__name__} {v!r}")
            if not math.isfinite(v):
                raise self.fail(f"{full}[{i}]", f"expected a finite number, got {v}")
            if nonneg and v < 0:
                raise self.fail(f"{full}[{i}]", f"expected a number >= 0, got {v}")
            if positive and v <= 0:
                raise self.fail(f"{full}[{i}]", f"expected a number > 0, got {v}")
        return _frozen(value)

    def choice(self, data: dict, key: str, prefix: str, options: tuple[str, ...]) -> str:
        value = self.get(data, key, prefix, str)
        if value not in options:
            raise self.fail(prefix + key, f"expected one of {', '.join(options)}, got {value!r}")
        return value

    def unknown_keys(self, data: dict, allowed: set[str], prefix: str) -> None:
        extra = sorted(set(data) - allowed)
        if extra:
            raise self.fail(prefix + extra[0], f"unknown key (allowed: {', '.join(sorted(allowed))})")

    # -- sections --------------------------------------------------------------------------------------
    def scene(self, data: dict) -> Scene:
        self.unknown_keys(data, {"schema", "name", "description", "robot", "gravity", "sensor", "joint_torque",
                                 "sensing", "touchable", "compensation", "devices", "world"}, "")
        schema = self.get(data, "schema", "", int)
        if schema != SCHEMA_VERSION:
            raise self.fail("schema", f"expected schema version {SCHEMA_VERSION}, got {schema}")
        name = self.get(data, "name", "", str)
        if not name.strip():
            raise self.fail("name", "expected a non-empty string")
        robot = self.robot(self.table(data, "robot"))
        gravity = self.vector(self.table(data, "gravity"), "vector", "gravity.", 3)
        self.unknown_keys(data["gravity"], {"vector"}, "gravity.")
        sensor = self.sensor(self.table(data, "sensor")) if "sensor" in data else None
        joint_torque = self.joint_torque(self.table(data, "joint_torque"), len(robot.joints)) \
            if "joint_torque" in data else None
        has_currents = "torque_constant" in data["robot"]
        touchable = self.touchable(data.get("touchable"))
        comp = self.table(data, "compensation")
        self.unknown_keys(comp, {"level"}, "compensation.")
        level = self.choice(comp, "level", "compensation.", COMPENSATION_LEVELS)
        devices = self.devices(data.get("devices", []))
        world = self.world(self.table(data, "world"), robot.joints) if "world" in data else IDEAL
        scene = Scene(name=name, description=self.get(data, "description", "", str, ""), path=self.path,
                      robot=robot, gravity=gravity, sensor=sensor, touchable=touchable,
                      compensation=level, devices=devices, world=world, joint_torque=joint_torque,
                      has_currents=has_currents)
        if not scene.available.kinds:
            raise self.fail("sensor", "the scene senses nothing: give an F/T sensor ([sensor]), joint torque "
                                      "sensors ([joint_torque]) or motor currents ([robot] torque_constant)")
        return self.sensing(data["sensing"], scene) if "sensing" in data else scene

    def sensing(self, t: Any, scene: Scene) -> Scene:
        """``[sensing] uses``: which of what the scene has the pipeline uses."""
        if not isinstance(t, dict):
            raise self.fail("sensing", f"expected a table, got {type(t).__name__}")
        self.unknown_keys(t, {"uses"}, "sensing.")
        uses = self.get(t, "uses", "sensing.", list)
        if not all(isinstance(u, str) for u in uses) or len(set(uses)) != len(uses):
            raise self.fail("sensing.uses", f"expected distinct names of {', '.join(SENSING_KINDS)}")
        return scene.with_sensing(uses)

    def joint_torque(self, t: dict, n: int) -> JointTorqueSpec:
        p = "joint_torque."
        self.unknown_keys(t, {"noise_std", "range", "offset", "rate_hz"}, p)
        return JointTorqueSpec(noise_std=self.vector(t, "noise_std", p, n, nonneg=True),
                               range=self.vector(t, "range", p, n, positive=True),
                               offset=self.vector(t, "offset", p, n, default=[0.0] * n),
                               rate_hz=self.number(t, "rate_hz", p, positive=True, default=1000.0))

    def robot(self, t: dict) -> RobotSpec:
        p = "robot."
        self.unknown_keys(t, {"model", "joints", "home", "flange", "torque_constant", "friction_viscous",
                              "friction_coulomb", "kp", "kd", "current_noise_std", "couplings",
                              "surface_tolerance_m", "vendor_shell", "max_speed", "max_acceleration"}, p)
        model_path = self.model_file(t, p)
        joints = self.get(t, "joints", p, list)
        if not joints or not all(isinstance(j, str) and j for j in joints):
            raise self.fail(p + "joints", "expected a non-empty list of joint names")
        if len(set(joints)) != len(joints):
            raise self.fail(p + "joints", "joint names must be unique")
        n = len(joints)
        return RobotSpec(
            model_path=model_path,
            joints=tuple(joints),
            home=self.vector(t, "home", p, n, default=[0.0] * n),
            flange=self.get(t, "flange", p, str, None),
            torque_constant=self.vector(t, "torque_constant", p, n, positive=True, default=[1.0] * n),
            friction_viscous=self.vector(t, "friction_viscous", p, n, nonneg=True, default=[0.0] * n),
            friction_coulomb=self.vector(t, "friction_coulomb", p, n, nonneg=True, default=[0.0] * n),
            kp=self.vector(t, "kp", p, n, positive=True, default=[100.0] * n),
            kd=self.vector(t, "kd", p, n, nonneg=True, default=[10.0] * n),
            current_noise_std=self.vector(t, "current_noise_std", p, n, nonneg=True, default=[0.0] * n),
            couplings=self.couplings(t.get("couplings", []), tuple(joints)),
            surface_tolerance=self.tolerance(t, p),
            vendor_shell=self.vendor_shell(t, p),
            max_speed=self.vector(t, "max_speed", p, n, positive=True, default=None),
            max_acceleration=self.vector(t, "max_acceleration", p, n, positive=True, default=None),
        )

    def vendor_shell(self, t: dict, p: str) -> str | None:
        """``vendor_shell``: one of :data:`VENDOR_SHELLS` (its meshes are fetched by ``ftc scenes meshes``)."""
        name = self.get(t, "vendor_shell", p, str, None)
        if name is not None and name not in VENDOR_SHELLS:
            raise self.fail(p + "vendor_shell", f"unknown vendor shell {name!r} (known: {', '.join(VENDOR_SHELLS)})")
        return name

    def tolerance(self, t: dict, p: str) -> float:
        value = self.number(t, "surface_tolerance_m", p, default=0.0)
        if not 0.0 <= value <= 0.05:
            raise self.fail(p + "surface_tolerance_m", f"expected 0 to 0.05 m, got {value}")
        return value

    def model_file(self, t: dict, p: str) -> Path:
        """``model``: an MJCF or URDF file, relative to the scene file."""
        model = self.get(t, "model", p, str)
        model_path = (self.path.parent / model).resolve()
        if model_path.suffix.lower() not in (".xml", ".urdf"):
            raise self.fail(p + "model", f"expected an MJCF (.xml) or URDF (.urdf) file, got {model!r}")
        if not model_path.is_file():
            raise self.fail(p + "model", f"model file not found: {model_path}")
        return model_path

    def couplings(self, items: Any, joints: tuple[str, ...]) -> tuple[Coupling, ...]:
        p = "robot.couplings"
        if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
            raise self.fail(p, "expected an array of tables ([[robot.couplings]])")
        out: list[Coupling] = []
        driven: set[str] = set()
        for k, item in enumerate(items):
            q = f"{p}[{k}]."
            self.unknown_keys(item, {"joint", "drives", "ratios"}, q)
            joint = self.get(item, "joint", q, str)
            if joint not in joints:
                raise self.fail(q + "joint", f"{joint!r} is not one of robot.joints")
            if any(c.joint == joint for c in out):
                raise self.fail(q + "joint", f"{joint!r} is coupled twice")
            drives = self.get(item, "drives", q, list)
            if not drives or not all(isinstance(d, str) and d for d in drives) or len(set(drives)) != len(drives):
                raise self.fail(q + "drives", "expected a non-empty list of distinct model joint names")
            for d in drives:
                if d in joints:
                    raise self.fail(q + "drives", f"{d!r} is a scene joint itself: a coupling drives model joints "
                                                  "that robot.joints does not list")
                if d in driven:
                    raise self.fail(q + "drives", f"{d!r} is driven by two couplings")
                driven.add(d)
            ratios = self.vector(item, "ratios", q, len(drives))
            if any(r == 0 for r in ratios):
                raise self.fail(q + "ratios", "a ratio of 0 drives nothing")
            out.append(Coupling(joint, tuple(drives), tuple(float(r) for r in ratios)))
        return tuple(out)

    def sensor(self, t: dict) -> SensorSpec:
        p = "sensor."
        self.unknown_keys(t, {"site", "reports", "range", "noise_std", "quantization", "rate_hz", "bias",
                              "drift_per_s", "accuracy", "mount"}, p)
        accuracy = self.number(t, "accuracy", p, default=0.005)
        if not 0.0 <= accuracy <= 0.2:
            raise self.fail(p + "accuracy", f"expected 0 to 0.2 (relative), got {accuracy}")
        return SensorSpec(
            site=self.get(t, "site", p, str),
            reports=self.choice(t, "reports", p, SIGN_CONVENTIONS),  # type: ignore[arg-type]
            range=self.vector(t, "range", p, 6, positive=True),
            noise_std=self.vector(t, "noise_std", p, 6, nonneg=True),
            quantization=self.vector(t, "quantization", p, 6, nonneg=True, default=[0.0] * 6),
            rate_hz=self.number(t, "rate_hz", p, positive=True),
            bias=self.vector(t, "bias", p, 6, default=[0.0] * 6),
            drift_per_s=self.vector(t, "drift_per_s", p, 6, default=[0.0] * 6),
            accuracy=accuracy,
            mount=self.choice(t, "mount", p, SENSOR_MOUNTS) if "mount" in t else "base",  # type: ignore[arg-type]
        )

    def world(self, t: dict, joints: tuple[str, ...]) -> WorldSpec:
        p, n = "world.", len(joints)
        self.unknown_keys(t, {"model", "inertials", "friction_coulomb", "friction_viscous", "friction_stribeck",
                              "stribeck_velocity", "torque_constant", "sensor_offset_m", "sensor_rotation_rad",
                              "sensor_gain", "coloured_noise_std", "coloured_noise_tau_s", "temperature_drift",
                              "temperature_rise_K", "temperature_tau_s", "shell_offset_m",
                              "vendor_shell", "vendor_shell_shift_m", *_JOINT_SENSING_KEYS}, p)
        model_path = self.model_file(t, p) if "model" in t else None

        def joint_vector(key: str, **kw) -> Any:
            return self.vector(t, key, p, n, **kw) if key in t else None

        shell = self.number(t, "shell_offset_m", p, default=0.0)
        if not 0.0 <= shell <= 0.05:
            raise self.fail(p + "shell_offset_m", f"expected 0 to 0.05 m, got {shell}")
        return WorldSpec(
            model_path=model_path, inertials=self.inertials(self.get(t, "inertials", p, dict, {})),
            friction_coulomb=joint_vector("friction_coulomb", nonneg=True),
            friction_viscous=joint_vector("friction_viscous", nonneg=True),
            friction_stribeck=joint_vector("friction_stribeck", nonneg=True),
            stribeck_velocity=self.number(t, "stribeck_velocity", p, positive=True, default=0.02),
            torque_constant=joint_vector("torque_constant", positive=True),
            sensor_offset=self.vector(t, "sensor_offset_m", p, 3, default=[0.0] * 3),
            sensor_rotation=self.vector(t, "sensor_rotation_rad", p, 3, default=[0.0] * 3),
            sensor_gain=self.matrix6(t, "sensor_gain", p),
            coloured_noise_std=self.vector(t, "coloured_noise_std", p, 6, nonneg=True, default=[0.0] * 6),
            coloured_noise_tau_s=self.number(t, "coloured_noise_tau_s", p, positive=True, default=1.0),
            temperature_drift=self.vector(t, "temperature_drift", p, 6, default=[0.0] * 6),
            temperature_rise_K=self.number(t, "temperature_rise_K", p, default=0.0),
            temperature_tau_s=self.number(t, "temperature_tau_s", p, positive=True, default=600.0),
            shell_offset=shell, vendor_shell=self.vendor_shell(t, p),
            vendor_shell_shift=self.shifts(self.get(t, "vendor_shell_shift_m", p, dict, {}),
                                           p + "vendor_shell_shift_m."),
            **self.joint_sensing(t, p, joint_vector))

    def joint_sensing(self, t: dict, p: str, joint_vector) -> dict[str, Any]:
        """``[world]``'s joint sensing keys (docs/reality.md): motor ripple and cogging, temperature
        coefficients, the windings' thermal model, joint torque sensors' offsets and drift."""
        out = {"gear_ratio": joint_vector("gear_ratio", positive=True),
               "motor_angle_offset": joint_vector("motor_angle_offset"),
               "current_ripple": joint_vector("current_ripple", nonneg=True),
               "cogging_torque": joint_vector("cogging_torque", nonneg=True),
               "winding_start_K": joint_vector("winding_start_K"),
               "joint_torque_offset": joint_vector("joint_torque_offset"),
               "joint_torque_drift_per_K": joint_vector("joint_torque_drift_per_K")}
        if out["current_ripple"] is not None and np.any(out["current_ripple"] >= 0.5):
            raise self.fail(p + "current_ripple", "expected amplitudes below 0.5 (a fraction of the torque)")
        for key, limit in (("torque_constant_per_K", 0.01), ("friction_per_K", 0.05)):
            out[key] = self.number(t, key, p, default=0.0)
            if abs(out[key]) > limit:
                raise self.fail(p + key, f"expected -{limit} to {limit} per K, got {out[key]}")
        out["winding_heating_K_per_A2"] = self.number(t, "winding_heating_K_per_A2", p, default=0.0)
        if out["winding_heating_K_per_A2"] < 0:
            raise self.fail(p + "winding_heating_K_per_A2", "expected a number >= 0")
        out["winding_tau_s"] = self.number(t, "winding_tau_s", p, positive=True, default=900.0)
        return out

    def shifts(self, table: dict, p: str) -> Any:
        """``vendor_shell_shift_m``: per body, where its real shell lies off the vendor's meshes (m, body frame)."""
        out = {body: self.vector(table, body, p, 3) for body in table}
        for body, v in out.items():
            if np.any(np.abs(v) > 0.05):
                raise self.fail(p + body, f"expected each axis within 0.05 m, got {v.tolist()}")
        return out

    def inertials(self, table: dict) -> Any:
        out = {}
        for body, item in table.items():
            q = f"world.inertials.{body}."
            if not isinstance(item, dict):
                raise self.fail(q[:-1], f"expected a table, got {type(item).__name__}")
            self.unknown_keys(item, {"mass_scale", "com_offset_m", "inertia_scale"}, q)
            out[body] = InertialError(self.number(item, "mass_scale", q, positive=True, default=1.0),
                                      self.vector(item, "com_offset_m", q, 3, default=[0.0] * 3),
                                      self.number(item, "inertia_scale", q, positive=True, default=1.0))
        return out

    def matrix6(self, t: dict, key: str, prefix: str) -> Any:
        if key not in t:
            return _frozen(np.eye(6))
        rows = self.get(t, key, prefix, list)
        if len(rows) != 6:
            raise self.fail(prefix + key, f"expected 6 rows of 6 numbers, got {len(rows)} rows")
        out = np.array([self.vector({f"{key}[{i}]": r}, f"{key}[{i}]", prefix, 6) for i, r in enumerate(rows)])
        if abs(np.linalg.det(out)) < 1e-6:
            raise self.fail(prefix + key, "the gain matrix is singular: no sensor reads like that")
        return _frozen(out)

    def touchable(self, items: Any) -> tuple[TouchableLink, ...]:
        if items is None:
            raise self.fail("touchable", "missing: expected at least one [[touchable]] table")
        if not isinstance(items, list) or not all(isinstance(i, dict) for i in items) or not items:
            raise self.fail("touchable", "expected an array of tables ([[touchable]])")
        out = []
        for i, item in enumerate(items):
            p = f"touchable[{i}]."
            self.unknown_keys(item, {"link", "pulls"}, p)
            out.append(TouchableLink(link=self.get(item, "link", p, str),
                                     pulls=self.get(item, "pulls", p, bool, False)))
        names = [t.link for t in out]
        if len(set(names)) != len(names):
            raise self.fail("touchable", "a link is listed twice")
        return tuple(out)

    def devices(self, items: Any) -> tuple[DeviceSpec, ...]:
        if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
            raise self.fail("devices", "expected an array of tables ([[devices]])")
        out = []
        for i, item in enumerate(items):
            p = f"devices[{i}]."
            self.unknown_keys(item, {"name", "kind", "transport", "address", "params"}, p)
            params = self.get(item, "params", p, dict, {})
            spec = DeviceSpec(name=self.get(item, "name", p, str), kind=self.get(item, "kind", p, str),
                              transport=self.get(item, "transport", p, str),
                              address=self.get(item, "address", p, str, None), params=dict(params))
            out.append(self.checked_device(spec, p))
        names = [d.name for d in out]
        if len(set(names)) != len(names):
            raise self.fail("devices", "device names must be unique")
        return tuple(out)

    def checked_device(self, spec: DeviceSpec, prefix: str) -> DeviceSpec:
        """The device's kind, transport and params against the kind's schema (:mod:`.device_params`)."""
        try:
            check_transport(device_kind(spec.kind).kind, spec.transport)
            check_params(spec.kind, spec.params)
        except ParamError as exc:
            key = exc.key if exc.key in ("kind", "transport") else f"params.{exc.key}"
            raise self.fail(prefix + key, f"device {spec.name!r}: {exc.problem}") from None
        return spec


def _as_tuple(kind: type | tuple[type, ...]) -> tuple[type, ...]:
    return kind if isinstance(kind, tuple) else (kind,)


def _kind_name(kind: type | tuple[type, ...]) -> str:
    names = {int: "an integer", float: "a number", str: "a string", bool: "true or false", list: "a list",
             dict: "a table"}
    kinds = _as_tuple(kind)
    if set(kinds) == {int, float}:
        return "a number"
    return " or ".join(names.get(k, k.__name__) for k in kinds)
