"""Every adapter by scene device kind, with its role (``ft``: an F/T sensor, ``arm``: joint state):
``make_adapter(device, bus, endpoint)`` builds the adapter of a scene's ``[[devices]]`` entry,
connected to the endpoint ``ftc sim`` printed for it (its first stdout line,
``{"scene", "devices": [endpoint, ...]}``) or, without one, to the device's ``address`` (hardware).

F/T device params read here (all optional): ``stale_after_s``, ``range`` (else the device model's or
the scene sensor's), and per kind: ``ft300``: ``mode`` (stream | poll), ``device_id``, ``baudrate``,
``poll_hz``; ``modbus-ft``: ``map``, ``device_id``, ``baudrate``, ``poll_hz``, ``port``;
``ft-serial-stream``: ``format``, ``baudrate``; ``ft-can``: ``channel`` (else the address), ``dbc``,
``base_id``, ``mode``, ``poll_hz``, ``interface``; ``ft-rdt``: ``port``, ``http_port``, ``mode``,
``rate_hz``, ``buffer``, ``counts_per_force``, ``counts_per_torque``, ``read_calibration``. Arm adapters
read theirs in their ``from_spec``.
Every kind's params, with types, ranges and defaults: :data:`ftc_hw.scene.device_params.KINDS`
(the scene loader checks them).

Kinds whose adapters live above this layer (:data:`PLUGINS`: the ROS inputs, which import rclpy, allowed
only in ``ftc_hw.app.ros``) are loaded on the first adapter asked of one, as python-can loads an
interface's backend when a bus of it is made: importing their module registers them
(:func:`register_kind`); their roles are known without it.

Roles: a device fills its kind's role, and an arm that reads its own F/T sensor fills the ``ft`` role
too (:func:`roles_of`): a UR e-Series reading its flange sensor (``ur-rtde``'s ``ft`` param, by default
on when the scene's pipeline uses a flange sensor and no device of an F/T kind is declared).
"""
from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from ftc_hw.bus import Bus
from ftc_hw.scene import DeviceSpec, Scene

from .base import Adapter, DeviceError
from .can_ft import CanFTAdapter
from .dynamixel import DynamixelArm
from .franka import FrankaArm
from .ft300 import FT300Adapter
from .ft_base import FTAdapter
from .modbus_ft import ModbusFTAdapter
from .netft_rdt import RdtFTAdapter
from .serial_stream import SerialStreamFTAdapter
from .ur import URArm, reads_flange_ft


def _where(device: DeviceSpec, ep: Mapping[str, Any]) -> str:
    where = ep.get("endpoint") or device.address
    if not where:
        raise DeviceError(f"device {device.name!r}: no endpoint and no address")
    return str(where)


def _host_port(device: DeviceSpec, ep: Mapping[str, Any], default_port: int = 502) -> tuple[str, int]:
    if "host" in ep and "port" in ep:
        return str(ep["host"]), int(ep["port"])
    host, _, port = _where(device, ep).partition(":")
    return host or "127.0.0.1", int(port or device.params.get("port", default_port))


def _common(device: DeviceSpec, scene: Scene | None) -> dict[str, Any]:
    p = device.params
    out: dict[str, Any] = {}
    if "stale_after_s" in p:
        out["stale_after"] = float(p["stale_after_s"])
    if "range" in p:
        out["range"] = tuple(float(x) for x in p["range"])
    elif scene is not None:
        out["scene_range"] = tuple(float(x) for x in scene.sensor.range)
    return out


def _range_default(kw: dict[str, Any], has_own: bool) -> dict[str, Any]:
    scene_range = kw.pop("scene_range", None)
    if scene_range is not None and not has_own and "range" not in kw:
        kw["range"] = scene_range
    return kw


def _ft300(device: DeviceSpec, bus: Bus, ep: Mapping[str, Any], kw: dict[str, Any]) -> FTAdapter:
    p = device.params
    transport = str(ep.get("transport", device.transport))
    kw = _range_default(kw, has_own=True)
    common = dict(device_id=int(ep.get("device_id", p.get("device_id", 9))), transport=transport,
                  mode=str(p.get("mode", "stream")) if transport == "modbus-rtu" else "poll", **kw)
    if "poll_hz" in p:
        common["poll_hz"] = float(p["poll_hz"])
    if transport == "modbus-tcp":
        host, port = _host_port(device, ep)
        return FT300Adapter(device.name, bus, host=host, tcp_port=port, **common)
    baudrate = int(ep.get("baudrate", p.get("baudrate", 19200)))
    return FT300Adapter(device.name, bus, _where(device, ep), baudrate=baudrate, **common)


def _modbus_ft(device: DeviceSpec, bus: Bus, ep: Mapping[str, Any], kw: dict[str, Any]) -> FTAdapter:
    p = device.params
    if "map" not in p:
        raise DeviceError(f"device {device.name!r}: params.map (a register map name or table) is required")
    transport = str(ep.get("transport", device.transport))
    kw = _range_default(kw, has_own=False)
    common = dict(transport=transport, device_id=int(ep.get("device_id", p.get("device_id", 1))),
                  poll_hz=float(p["poll_hz"]) if "poll_hz" in p else 500.0, **kw)
    if transport == "modbus-tcp":
        host, port = _host_port(device, ep)
        return ModbusFTAdapter(device.name, bus, p["map"], host=host, tcp_port=port, **common)
    return ModbusFTAdapter(device.name, bus, p["map"], port=_where(device, ep),
                           baudrate=int(ep.get("baudrate", p.get("baudrate", 19200))), **common)


def _serial_stream(device: DeviceSpec, bus: Bus, ep: Mapping[str, Any], kw: dict[str, Any]) -> FTAdapter:
    p = device.params
    kw = _range_default(kw, has_own=False)
    return SerialStreamFTAdapter(device.name, bus, _where(device, ep), p.get("format", "ftc-1k"),
                                 baudrate=int(ep.get("baudrate", p.get("baudrate", 1_000_000))), **kw)


def _can(device: DeviceSpec, bus: Bus, ep: Mapping[str, Any], kw: dict[str, Any]) -> FTAdapter:
    p = device.params
    kw.pop("scene_range", None)  # saturation comes in the status frame
    kw.pop("range", None)
    return CanFTAdapter(device.name, bus, str(ep.get("channel") or p.get("channel") or _where(device, ep)),
                        interface=str(ep.get("interface", p.get("interface", "serial"))),
                        dbc=str(ep.get("dbc", p.get("dbc", "ati_netft_can.dbc"))),
                        base_id=int(ep.get("base_id", p.get("base_id", 8))),
                        rate_hz=float(ep.get("rate_hz", p.get("rate_hz", 1000.0))),
                        mode=str(p.get("mode", "stream")), poll_hz=float(p.get("poll_hz", 100.0)), **kw)


def _rdt(device: DeviceSpec, bus: Bus, ep: Mapping[str, Any], kw: dict[str, Any]) -> FTAdapter:
    p = device.params
    kw.pop("scene_range", None)  # saturation comes in the status word
    kw.pop("range", None)
    host = str(ep.get("host") or device.address or "")
    if not host:
        raise DeviceError(f"device {device.name!r}: no endpoint and no address (the Net F/T box's IP address)")
    cpf, cpt, buffer = p.get("counts_per_force"), p.get("counts_per_torque"), p.get("buffer")
    return RdtFTAdapter(device.name, bus, host, port=int(ep.get("port", p.get("port", 49152))),
                        http_port=int(ep.get("http_port", p.get("http_port", 80))),
                        tcp_port=int(ep.get("tcp_port") or p.get("tcp_port", 49151)),
                        mode=str(p.get("mode", "realtime")),
                        rate_hz=None if "rate_hz" not in p else float(p["rate_hz"]),
                        buffer=None if buffer is None else int(buffer),
                        counts_per_force=None if cpf is None else float(cpf),
                        counts_per_torque=None if cpt is None else float(cpt),
                        read_calibration=bool(p.get("read_calibration", True)), **kw)


Role = Literal["ft", "arm"]
Build = Callable[[DeviceSpec, Bus, Any, "Scene | None", dict[str, Any]], Adapter]


ReadsFT = Callable[[DeviceSpec, "Scene | None", bool], bool]


@dataclass(frozen=True)
class AdapterKind:
    role: Role
    build: Build  # (device, bus, endpoint, scene, overrides) -> the adapter, not opened
    moves_on_goals: bool = False  # an arm whose protocol takes goal positions (the wizard and ftc identify move it)
    # an arm that can read its own F/T sensor: (device, scene, another F/T device declared) -> it does
    reads_ft: ReadsFT | None = None


def _ft(build: Callable[[DeviceSpec, Bus, Mapping[str, Any], dict[str, Any]], FTAdapter]) -> AdapterKind:
    def make(device: DeviceSpec, bus: Bus, endpoint: Any, scene: Scene | None, overrides: dict[str, Any]) -> Adapter:
        return build(device, bus, dict(endpoint or {}), {**_common(device, scene), **overrides})

    return AdapterKind("ft", make)


def _arm(cls: type[DynamixelArm] | type[URArm] | type[FrankaArm], reads_ft: ReadsFT | None = None) -> AdapterKind:
    def make(device: DeviceSpec, bus: Bus, endpoint: Any, scene: Scene | None, overrides: dict[str, Any]) -> Adapter:
        if reads_ft is not None:
            overrides = {"ft": "ft" in roles_of(device, scene), **overrides}
        return cls.from_spec(device, bus, endpoint, scene=scene, **overrides)

    return AdapterKind("arm", make, cls.moves_on_goals, reads_ft)


ADAPTERS: dict[str, AdapterKind] = {
    "ft300": _ft(_ft300),
    "modbus-ft": _ft(_modbus_ft),
    "ft-serial-stream": _ft(_serial_stream),
    "ft-can": _ft(_can),
    "ft-rdt": _ft(_rdt),
    "dynamixel": _arm(DynamixelArm),
    "ur-rtde": _arm(URArm, reads_flange_ft),
    "franka": _arm(FrankaArm),
}


@dataclass(frozen=True)
class PluginKind:
    role: Role
    module: str  # importing it registers the kind (register_kind); it may raise why it cannot (a missing extra)


PLUGINS: dict[str, PluginKind] = {
    "ros-joint-state": PluginKind("arm", "ftc_hw.app.ros.inputs"),
    "ros-wrench": PluginKind("ft", "ftc_hw.app.ros.inputs"),
}
_registered: dict[str, AdapterKind] = {}


def register_kind(kind: str, entry: AdapterKind) -> None:
    """Called by a plugin kind's module when imported: its adapters from now on."""
    plugin = PLUGINS.get(kind)
    if plugin is None or plugin.role != entry.role:
        raise ValueError(f"{kind!r} is no plugin kind of role {entry.role!r} (PLUGINS)")
    _registered[kind] = entry


def _entry(kind: str) -> AdapterKind | None:
    """The kind's adapter entry; a plugin kind's module imported first (whatever it raises propagates)."""
    entry = ADAPTERS.get(kind) or _registered.get(kind)
    if entry is None and kind in PLUGINS:
        importlib.import_module(PLUGINS[kind].module)
        entry = _registered.get(kind)
    return entry


def kinds(role: Role) -> tuple[str, ...]:
    """The device kinds of a role, in the registry's order (plugin kinds last)."""
    return (*(k for k, a in ADAPTERS.items() if a.role == role), *(k for k, p in PLUGINS.items() if p.role == role))


def moves_on_goals(kind: str) -> bool:
    """True for an arm kind whose protocol takes goal positions."""
    entry = ADAPTERS.get(kind)  # no plugin kind moves the arm
    return entry is not None and entry.moves_on_goals


def role_of(kind: str) -> Role | None:
    """The role of a device kind (an arm kind's device may fill the ``ft`` role too: :func:`roles_of`)."""
    entry = ADAPTERS.get(kind) or PLUGINS.get(kind)
    return entry.role if entry is not None else None


def roles_of(device: DeviceSpec, scene: Scene | None = None) -> frozenset[Role]:
    """The roles ``device`` fills in ``scene``'s rig: its kind's, and ``ft`` for an arm that reads its own
    F/T sensor (a UR's flange sensor; see the module doc)."""
    entry = ADAPTERS.get(device.kind)
    if entry is None:
        role = role_of(device.kind)
        return frozenset() if role is None else frozenset({role})
    if entry.reads_ft is None:
        return frozenset({entry.role})
    other = scene is not None and any(role_of(d.kind) == "ft" for d in scene.devices)
    return frozenset({entry.role, "ft"}) if entry.reads_ft(device, scene, other) else frozenset({entry.role})


def make_adapter(device: DeviceSpec, bus: Bus, endpoint: Mapping[str, Any] | str | None = None, *,
                 scene: Scene | None = None, **overrides: Any) -> Adapter:
    """The adapter of ``device`` (not opened). ``endpoint``: the device's entry of the ``ftc sim``
    line (None: use ``device.address``). ``scene``: gives the sensor range when neither the device
    model nor ``params.range`` does, and the UR joints' torque constants. ``overrides``: keyword
    arguments for the adapter class. A plugin kind whose module cannot load raises what it raises
    (the ROS kinds: ``RosUnavailable`` without the ``ros`` extra)."""
    entry = _entry(device.kind)
    if entry is None:
        raise DeviceError(f"no adapter for device kind {device.kind!r} (known: {', '.join([*ADAPTERS, *PLUGINS])})")
    return entry.build(device, bus, endpoint, scene, overrides)
