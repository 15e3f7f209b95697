"""Point a scene at one's own devices: overrides of its ``[[devices]]`` by device name, from the command
line (``--device NAME.KEY=VALUE``, repeatable) and from a small local rig file (``--rig FILE.toml``: a
table per device name with the same keys). KEY is ``address``, ``transport`` or a param of the
device's kind (:data:`.device_params.KINDS`); values are typed and checked by that schema. The rig
file applies first, then the ``--device`` options, in order.

A rig file may also change a device's ``kind`` (a cell whose arm is read from its ROS driver's topic:
``kind = "ros-joint-state"``): the device then starts afresh as that kind (its transport the kind's first,
no address, none of the scene's params, which were the other kind's) and takes the table's other keys.

```toml
# rig.toml
[ft]
channel = "/dev/ttyACM0"
base_id = 8
[arm]
address = "192.168.1.10"
```
"""
from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from .device_params import (
    DEVICE_KEYS,
    ParamError,
    check_params,
    check_transport,
    check_value,
    close_match,
    device_kind,
    parse_value,
)
from .errors import SceneError
from .loader import load_scene
from .schema import DeviceSpec, Scene

Overrides = dict[str, dict[str, Any]]  # device name -> key -> value
CLI = "--device"


def load_rig_scene(name_or_path: str | Path, device_options: Iterable[str] = (), rig: Path | None = None,
                   sensing: Iterable[str] | None = None) -> Scene:
    """The scene with the rig file's overrides, then the ``--device`` options', applied, using only
    ``sensing`` of what it has (``--sensing``; None: what the scene says). SceneError names the file or
    option, the device and key, and what is accepted."""
    scene = load_scene(name_or_path)
    if sensing is not None:
        scene = scene.with_sensing(sensing)
    if rig is not None:
        scene = apply_overrides(scene, read_rig_file(rig, scene), str(rig))
    overrides: Overrides = {}
    for text in device_options:
        name, key, value = parse_device_option(text, scene)
        overrides.setdefault(name, {})[key] = value
    return apply_overrides(scene, overrides, CLI)


def parse_device_option(text: str, scene: Scene) -> tuple[str, str, Any]:
    """``NAME.KEY=VALUE`` -> (name, key, value typed by the device kind's schema)."""
    target, eq, raw = text.partition("=")
    name, dot, key = target.strip().partition(".")
    if not (eq and dot and name and key):
        raise SceneError(CLI, text, "expected NAME.KEY=VALUE (ft.address=/dev/ttyUSB0, arm.baudrate=57600)")
    spec = _device(scene, name, CLI, target)
    try:
        if key == "kind":
            raise ParamError(key, "a device's kind changes in a rig file (--rig FILE.toml: kind and the new kind's "
                             "keys in the device's table)")
        param = _param(spec, key)
        value = raw if param is None else parse_value(param, raw)
        if key == "transport":
            check_transport(spec.kind, value)
    except ParamError as exc:
        raise SceneError(CLI, f"{name}.{exc.key}", f"device {name!r}: {exc.problem}") from None
    return name, key, value


def read_rig_file(path: Path, scene: Scene) -> Overrides:
    """A rig file: ``[NAME]`` tables of ``KEY = VALUE`` for the scene's devices."""
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise SceneError(path, "", f"cannot read the rig file ({exc.strerror or exc})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SceneError(path, "", f"invalid TOML: {exc}") from None
    for name, table in data.items():
        _device(scene, name, str(path), name)
        if not isinstance(table, dict):
            raise SceneError(path, name, f"expected a table [{name}] of the device's keys, got {table!r}")
    return {name: dict(table) for name, table in data.items()}


def apply_overrides(scene: Scene, overrides: Mapping[str, Mapping[str, Any]], source: str) -> Scene:
    """The scene with each named device's keys replaced, checked against its kind's schema."""
    devices = []
    for spec in scene.devices:
        changes = overrides.get(spec.name)
        devices.append(spec if not changes else _apply(spec, changes, source))
    for name in overrides:
        _device(scene, name, source, name)
    return dataclasses.replace(scene, devices=tuple(devices))


def _apply(spec: DeviceSpec, changes: Mapping[str, Any], source: str) -> DeviceSpec:
    try:
        if "kind" in changes:
            spec, changes = _rekind(spec, changes)
        for key, value in changes.items():
            param = _param(spec, key)
            if param is not None:
                check_value(param, value)
            elif not isinstance(value, str):
                raise ParamError(key, f"expected a string, got {value!r}")
        params = {**spec.params, **{k: v for k, v in changes.items() if k not in DEVICE_KEYS}}
        out = dataclasses.replace(spec, address=changes.get("address", spec.address),
                                  transport=changes.get("transport", spec.transport), params=params)
        check_transport(out.kind, out.transport)
        check_params(out.kind, out.params)
    except ParamError as exc:
        raise SceneError(source, f"{spec.name}.{exc.key}", f"device {spec.name!r}: {exc.problem}") from None
    return out


def _rekind(spec: DeviceSpec, changes: Mapping[str, Any]) -> tuple[DeviceSpec, dict[str, Any]]:
    """The device as a fresh one of ``changes["kind"]`` (unchanged if it is that kind already), and the rest."""
    kind, rest = changes["kind"], {k: v for k, v in changes.items() if k != "kind"}
    if not isinstance(kind, str):
        raise ParamError("kind", f"expected a device kind's name, got {kind!r}")
    if kind == spec.kind:
        return spec, rest
    entry = device_kind(kind)
    return DeviceSpec(spec.name, entry.kind, entry.transports[0]), rest


def _device(scene: Scene, name: str, source: str, key: str) -> DeviceSpec:
    spec = next((d for d in scene.devices if d.name == name), None)
    if spec is None:
        names = [d.name for d in scene.devices]
        raise SceneError(source, key, f"scene {scene.name!r} has no device {name!r} (devices: "
                         f"{', '.join(names) or 'none'}){close_match(name, names)}")
    return spec


def _param(spec: DeviceSpec, key: str) -> Any:
    """The schema param of ``key`` (None for ``address`` and ``transport``); ParamError if unknown."""
    kind = device_kind(spec.kind)
    if key in DEVICE_KEYS:
        return None
    param = kind.param(key)
    if param is None:
        accepted = (*DEVICE_KEYS, *kind.names)
        raise ParamError(key, f"no such key for device kind {spec.kind} (accepted: {', '.join(accepted)})"
                         + close_match(key, accepted))
    return param
