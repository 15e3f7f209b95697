"""Starting a rig: devices picked from the adapter registry, on one bus, opened and waited for.

One way to do it for every caller: the monitor session, the calibration wizard's session and the
device benches. By default a scene's rig is its first F/T sensor and its first arm device (the role
of each kind is in :data:`ftc_hw.devices.registry.ADAPTERS`; an arm that reads its own F/T sensor, a
UR's flange sensor, fills both roles with one adapter: :func:`~ftc_hw.devices.registry.roles_of`); a
caller may name its own device specs (one adapter per device name).
With a simulated world, ``endpoints`` (:attr:`ftc_hw.sim_devices.host.WorldHost.endpoints`) says
where each emulated device listens; without, each device's ``address`` in the scene does (or its
kind's locator param, ``channel`` for CAN), as the scene file, a rig file or ``--device`` options
(:func:`ftc_hw.scene.load_rig_scene`) set it. Devices that say nowhere are named in one RigError.
"""
from __future__ import annotations

import contextlib
import time
from collections.abc import Iterable, Mapping
from typing import Any

from ftc_hw.bus import Bus
from ftc_hw.devices.base import Adapter, DeviceError
from ftc_hw.devices.registry import Role, kinds, make_adapter, roles_of
from ftc_hw.scene import DeviceSpec, Scene
from ftc_hw.scene.device_params import KINDS, located, locator_key


class RigError(RuntimeError):
    """A device could not be picked, built or reached (the message says which)."""


def pick_device(scene: Scene, role: Role) -> DeviceSpec | None:
    """The scene's first device of ``role`` (``ft`` or ``arm``), or None."""
    return next((d for d in scene.devices if role in roles_of(d, scene)), None)


def require_device(scene: Scene, role: Role) -> DeviceSpec:
    device = pick_device(scene, role)
    if device is None:
        what = {"ft": "F/T sensor", "arm": "arm"}[role]
        raise RigError(f"scene {scene.name!r} declares no {what} device (kinds: {', '.join(kinds(role))})")
    return device


def check_located(specs: Iterable[DeviceSpec], endpoints: Mapping[str, Any] | None = None) -> None:
    """RigError naming every device with neither an emulator's endpoint nor an address (or locator)."""
    endpoints = endpoints or {}
    unique = {s.name: s for s in specs}  # a device filling two roles is named once
    unlocated = [s for s in unique.values() if not endpoints.get(s.name) and s.kind in KINDS
                 and not located(s.kind, s.address, s.params)]
    if unlocated:
        raise RigError(missing_address(unlocated))


def missing_address(specs: Iterable[DeviceSpec]) -> str:
    """What to say when devices have neither an emulator's endpoint nor an address: which, what their
    address is, and how to give one."""
    specs = list(specs)
    what = " and ".join(f"{s.name!r} ({s.kind}: {KINDS[s.kind].address}, e.g. {KINDS[s.kind].example})"
                        for s in specs)
    options = " ".join(f"--device {s.name}.{locator_key(s.kind)}={KINDS[s.kind].example}" for s in specs)
    return (f"no address for device {what}: give {'it' if len(specs) == 1 else 'each one'} with {options}, or "
            "in a rig file (--rig FILE.toml, a table per device name; docs/hardware.md); "
            "or run the scene's emulated devices with --sim")


class Rig:
    """Adapters on one bus: ``open()``, ``wait(timeout)``, ``close()`` (idempotent; a context manager
    opens and waits with ``timeout``)."""

    def __init__(self, bus: Bus, adapters: Iterable[Adapter] = (), timeout: float = 20.0) -> None:
        self.bus = bus
        self.adapters: list[Adapter] = list(adapters)
        self.timeout = timeout

    def add(self, adapter: Adapter) -> Adapter:
        self.adapters.append(adapter)
        return adapter

    def adapter(self, name: str) -> Adapter:
        for a in self.adapters:
            if a.name == name:
                return a
        raise KeyError(f"no device {name!r} in the rig ({', '.join(a.name for a in self.adapters)})")

    def first(self, role: Role) -> Adapter | None:
        return next((a for a in self.adapters if role in a.roles), None)

    @property
    def ft(self) -> Adapter | None:
        return self.first("ft")

    @property
    def arm(self) -> Adapter | None:
        return self.first("arm")

    def open(self) -> Rig:
        for a in self.adapters:
            a.open()
        return self

    def wait(self, timeout: float | None = None, *, data: bool = False) -> None:
        """Until every adapter is connected (and, with ``data``, has published a frame); RigError names
        the first that is not, with its counters."""
        timeout = self.timeout if timeout is None else timeout
        end = time.monotonic() + timeout
        for a in self.adapters:
            if not a.wait_connected(max(0.0, end - time.monotonic())):
                raise RigError(f"{a.name} ({a.kind}) did not connect within {timeout:g} s: {dict(a.counters)}")
        def quiet(a: Adapter) -> bool:
            return any(self.bus.latest(topic) is None for topic in a.topics)

        while data and time.monotonic() < end and any(quiet(a) for a in self.adapters):
            time.sleep(0.02)
        silent = [a.name for a in self.adapters if data and quiet(a)]
        if silent:
            raise RigError(f"connected, but no data arrives from {', '.join(silent)} within {timeout:g} s")

    def close(self) -> None:
        for a in self.adapters:
            with contextlib.suppress(Exception):  # closing every other device matters more
                a.close()

    def __enter__(self) -> Rig:
        try:
            self.open().wait()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def build_rig(scene: Scene, *, bus: Bus | None = None, devices: Iterable[DeviceSpec] | None = None,
              endpoints: Mapping[str, Any] | None = None, roles: Iterable[Role] = ("ft", "arm"),
              overrides: Mapping[str, Mapping[str, Any]] | None = None, timeout: float = 20.0) -> Rig:
    """The rig of ``devices`` (default: the scene's first device of each of ``roles``, each required),
    not opened. ``endpoints``: by device name, where an emulated device listens. ``overrides``: by
    device name, keyword arguments for its adapter class."""
    specs = list(devices) if devices is not None else [require_device(scene, r) for r in roles]
    unique: dict[str, DeviceSpec] = {}
    for spec in specs:  # a device that fills two roles gets one adapter
        unique.setdefault(spec.name, spec)
    specs = list(unique.values())
    endpoints = endpoints or {}
    check_located(specs, endpoints)
    overrides = overrides or {}
    bus = bus if bus is not None else Bus()
    rig = Rig(bus, timeout=timeout)
    try:
        for spec in specs:
            rig.add(make_adapter(spec, bus, endpoints.get(spec.name), scene=scene, **overrides.get(spec.name, {})))
    except DeviceError as exc:
        raise RigError(str(exc)) from None
    return rig
