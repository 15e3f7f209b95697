"""The scene's device-parameter schema (``ftc_hw.scene.device_params``) against what the adapters are:
the same kinds as the registry, the DYNAMIXEL choices of the control table, the adapters' defaults."""
from __future__ import annotations

import pytest

from ftc_hw.bus import Bus
from ftc_hw.codecs.dxl_table import BAUD_CODES, MODELS
from ftc_hw.devices.registry import ADAPTERS, PLUGINS, make_adapter
from ftc_hw.scene import DeviceSpec
from ftc_hw.scene.device_params import KINDS

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core


def test_the_schema_has_exactly_the_registry_kinds():
    assert list(KINDS) == [*ADAPTERS, *PLUGINS]


def test_dynamixel_choices_are_the_control_table_s():
    kind = KINDS["dynamixel"]
    assert set(kind.param("baudrate").choices) == set(BAUD_CODES)
    assert set(kind.param("model").choices) == set(MODELS)


def _default(kind: str, name: str):
    return KINDS[kind].param(name).default


@pytest.mark.parametrize(("kind", "transport", "params", "attrs"), [
    ("ft300", "modbus-rtu", {}, {"baudrate": "baudrate", "device_id": "device_id", "mode": "mode"}),
    ("modbus-ft", "modbus-rtu", {"map": "ft300"}, {"baudrate": "baudrate", "device_id": "device_id"}),
    ("ft-serial-stream", "serial", {}, {"baudrate": "baudrate"}),
    ("ft-can", "can-serial", {}, {"interface": "interface", "mode": "mode"}),
    ("dynamixel", "serial", {"ids": [1, 2]}, {"baudrate": "baudrate"}),
])
def test_schema_defaults_are_the_adapters(kind, transport, params, attrs):
    adapter = make_adapter(DeviceSpec("d", kind, transport, "/dev/ttyFTC0", params), Bus())
    for param, attr in attrs.items():
        assert getattr(adapter, attr) == _default(kind, param), (kind, param)


def test_rate_defaults_are_the_adapters():
    dxl = make_adapter(DeviceSpec("d", "dynamixel", "serial", "/dev/ttyFTC0", {"ids": [1]}), Bus())
    assert dxl.period == pytest.approx(1.0 / _default("dynamixel", "rate_hz"))
    ur = make_adapter(DeviceSpec("d", "ur-rtde", "tcp", "192.0.2.1"), Bus())
    assert ur.rate == _default("ur-rtde", "frequency")
    can = make_adapter(DeviceSpec("d", "ft-can", "can-serial", None, {"channel": "/dev/ttyFTC1"}), Bus())
    assert can.channel == "/dev/ttyFTC1" and can.codec.base_id == _default("ft-can", "base_id")
