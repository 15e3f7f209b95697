"""Adapters by scene device kind: ``make_adapter(device, bus, endpoint)`` builds the adapter of a scene's
``[[devices]]`` entry, connected to the endpoint ``ftc sim`` printed for it (its first stdout line,
``{"scene", "devices": [endpoint, ...]}``) or, without one, to the device's ``address`` (hardware).

Device params read here (all optional): ``stale_after_s``, ``range`` (else the device model's or the
scene sensor's), and per kind: ``ft300``: ``mode`` (stream | poll), ``device_id``, ``baudrate``,
``poll_hz``; ``modbus-ft``: ``map``, ``device_id``, ``baudrate``, ``poll_hz``, ``port``;
``ft-serial-stream``: ``format``, ``baudrate``; ``ft-can``: ``dbc``, ``base_id``, ``mode``,
``poll_hz``, ``interface``.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from ftc_hw.bus import Bus
from ftc_hw.scene import DeviceSpec, Scene

from .base import DeviceError
from .can_ft import CanFTAdapter
from .ft300 import FT300Adapter
from .ft_base import FTAdapter
from .modbus_ft import ModbusFTAdapter
from .serial_stream import SerialStreamFTAdapter


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
    return CanFTAdapter(device.name, bus, str(ep.get("channel") or _where(device, ep)),
                        interface=str(ep.get("interface", p.get("interface", "serial"))),
                        dbc=str(ep.get("dbc", p.get("dbc", "ati_netft_can.dbc"))),
                        base_id=int(ep.get("base_id", p.get("base_id", 8))),
                        rate_hz=float(ep.get("rate_hz", p.get("rate_hz", 1000.0))),
                        mode=str(p.get("mode", "stream")), poll_hz=float(p.get("poll_hz", 100.0)), **kw)


ADAPTERS: dict[str, Callable[[DeviceSpec, Bus, Mapping[str, Any], dict[str, Any]], FTAdapter]] = {
    "ft300": _ft300,
    "modbus-ft": _modbus_ft,
    "ft-serial-stream": _serial_stream,
    "ft-can": _can,
}


def make_adapter(device: DeviceSpec, bus: Bus, endpoint: Mapping[str, Any] | None = None, *,
                 scene: Scene | None = None, **overrides: Any) -> FTAdapter:
    """The adapter of ``device`` (not opened). ``endpoint``: the device's entry of the ``ftc sim``
    line (None: use ``device.address``). ``scene``: gives the sensor range when neither the device
    model nor ``params.range`` does. ``overrides``: keyword arguments for the adapter class."""
    build = ADAPTERS.get(device.kind)
    if build is None:
        raise DeviceError(f"no adapter for device kind {device.kind!r} (known: {', '.join(ADAPTERS)})")
    kw = {**_common(device, scene), **overrides}
    return build(device, bus, dict(endpoint or {}), kw)
