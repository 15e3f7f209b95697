"""Emulator of the Robotiq FT 300 (scene kind ``ft300``): Modbus RTU on a pty (or Modbus TCP), registers
180-185 and the identity at 500/510/514 as Robotiq's driver reads them, and the 100 Hz data stream.

Writing 0x0200 to register 410 (FC16, as ``rq_com_start_stream`` does) switches the RTU device to
streaming ``20 4E`` frames at 100 Hz with the newest world sample; a run of 0xFF bytes (the driver's
50-byte "jam signal") switches it back to Modbus. Identity defaults: firmware ``FTS-3.0.1``, serial
``FTS-0042``, year 2019 (``params.identity`` overrides them).
"""
from __future__ import annotations

from ftc_hw.codecs.stream import FT300_STREAM
from ftc_hw.scene import DeviceSpec, Scene

from .emulator import serve_with
from .link import LinkInfo
from .modbus_ft import ModbusFTEmulator


class FT300Emulator(ModbusFTEmulator):
    default_map = "ft300"
    default_identity = {"firmware": "FTS-3.0.1", "serial": "FTS-0042", "year": "2019"}
    stream_format = FT300_STREAM

    def __init__(self, device: DeviceSpec, scene: Scene, link: LinkInfo, options: dict) -> None:
        params = {"device_id": 9, "baudrate": 19200, **device.params}
        super().__init__(DeviceSpec(device.name, device.kind, device.transport, device.address, params),
                         scene, link, options)
        self.device = device


def serve(device: DeviceSpec, scene: Scene, link: LinkInfo, ready, options: dict) -> None:
    serve_with(FT300Emulator, device, scene, link, ready, options)
