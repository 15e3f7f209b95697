"""Arm adapters by device kind, for ``ftc_hw.devices.registry.make_adapter``.

Each factory is ``(device_spec, bus, endpoint=None, *, scene=None, **overrides) -> Adapter``, like
``ftc_hw.devices.registry.make_adapter``: ``endpoint`` is the dict ``ftc sim`` prints for the device (or a
port path / address string; None: the spec's ``address``), ``scene`` gives the UR joints' torque
constants, ``overrides`` are keyword arguments of the adapter class.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .base import Adapter, DeviceError
from .dynamixel import DynamixelArm
from .ur import URArm

ARM_ADAPTERS: dict[str, Callable[..., Adapter]] = {
    "dynamixel": DynamixelArm.from_spec,
    "ur-rtde": URArm.from_spec,
}


def make_arm_adapter(device_spec: Any, bus: Any, endpoint: Any = None, *, scene: Any = None,
                     **overrides: Any) -> Adapter:
    factory = ARM_ADAPTERS.get(device_spec.kind)
    if factory is None:
        raise DeviceError(f"no arm adapter for device kind {device_spec.kind!r} (known: {', '.join(ARM_ADAPTERS)})")
    return factory(device_spec, bus, endpoint, scene=scene, **overrides)
