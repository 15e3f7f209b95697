"""What answers where (``ftc devices probe``), through the same client libraries as the adapters:
an FT 300 on a serial port (Modbus RTU, its identity registers), DYNAMIXEL servos on a serial port
(broadcast ping at each baud rate: ids and models), a Net F/T on a CAN channel (one sample request
on its base id) or at an IP address (its calibration page, then one RDT record), a UR controller at an
IP address (RTDE version request, dashboard identity).

Every probe is bounded: ``timeout`` per request (an FT 300 gets 3 tries of its identity read), and a
DYNAMIXEL broadcast ping waits its fixed ~0.8 s per baud rate. Each returns a :class:`Finding` or
None, and a line saying what was tried and what came back.
"""
from __future__ import annotations

import socket
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import can
import dynamixel_sdk as sdk
import serial
from serial.tools import list_ports

from ftc_hw.bus import Bus
from ftc_hw.codecs.dxl_table import MODELS
from ftc_hw.codecs.errors import CodecError
from ftc_hw.codecs.netft_can import OP_READ, NetFTCodec
from ftc_hw.codecs.netft_rdt import CMD_START_REALTIME, DEFAULT_PORT, decode_packet, encode_request

from .base import DeviceError, DeviceIOError
from .ft300 import FT300Adapter
from .netft_rdt import RdtFTAdapter
from .ur import DashboardLink, probe_rtde

DXL_BAUDS = (57600, 1_000_000)  # the X series' factory setting, and OpenMANIPULATOR-X's
UR_IDENTITY = (("version", "PolyscopeVersion"), ("serial", "get serial number"), ("model", "get robot model"))
_MODEL_NAMES = {m.model_number: name for name, m in MODELS.items()}


@dataclass
class Finding:
    """A device that answered: ``what`` (FT 300, DYNAMIXEL, Net F/T, UR controller), ``where`` (port,
    channel or address), and what it said about itself."""

    what: str
    where: str
    identity: dict[str, Any] = field(default_factory=dict)


Probe = tuple[Finding | None, str]  # (what answered, what was tried and what came back)


def serial_ports() -> list[str]:
    """The system's serial ports (USB adapters and built-in), as pyserial lists them."""
    return sorted(p.device for p in list_ports.comports())


def probe_ft300(port: str, *, baudrate: int = 19200, device_id: int = 9, timeout: float = 0.3) -> Probe:
    tried = f"FT 300 on {port} at {baudrate} bit/s, Modbus id {device_id}"
    adapter = FT300Adapter("probe", Bus(), port, baudrate=baudrate, device_id=device_id, timeout=timeout)
    try:
        identity = adapter.identify()
    except (DeviceError, OSError) as exc:
        return None, f"{tried}: {exc}"
    return Finding("FT 300", port, {"baudrate": baudrate, "device_id": device_id, **identity}), f"{tried}: answered"


def probe_dynamixel(port: str, bauds: Iterable[int] = DXL_BAUDS) -> tuple[list[Finding], list[str]]:
    """A broadcast ping (protocol 2.0) at each baud rate: one finding per baud rate that answered."""
    found, notes = [], []
    handler = sdk.PortHandler(port)
    try:
        if not handler.openPort():
            return [], [f"DYNAMIXEL on {port}: cannot open the port"]
    except (OSError, serial.SerialException) as exc:
        return [], [f"DYNAMIXEL on {port}: cannot open the port ({exc})"]
    packets = sdk.PacketHandler(2.0)
    try:
        for baud in bauds:
            tried = f"DYNAMIXEL broadcast ping on {port} at {baud} bit/s"
            if not handler.setBaudRate(baud):
                notes.append(f"{tried}: the port refuses that baud rate")
                continue
            servos, result = packets.broadcastPing(handler)
            if result != sdk.COMM_SUCCESS or not servos:
                notes.append(f"{tried}: no servo answered")
                continue
            ids = sorted(servos)
            models = {i: _MODEL_NAMES.get(servos[i][0], f"model number {servos[i][0]}") for i in ids}
            found.append(Finding("DYNAMIXEL", port, {"baudrate": baud, "ids": ids, "models": models}))
            notes.append(f"{tried}: ids {', '.join(map(str, ids))}")
    except (OSError, serial.SerialException) as exc:
        notes.append(f"DYNAMIXEL on {port}: the port failed ({exc})")
    finally:
        handler.closePort()
    return found, notes


def probe_netft(channel: str, *, interface: str = "serial", base_id: int = 8, dbc: str = "ati_netft_can.dbc",
                timeout: float = 0.3) -> Probe:
    """One sample request (opcode 1) on the base id; the sensor's status frame is the answer."""
    tried = f"Net F/T on {interface}:{channel}, base id {base_id}"
    codec = NetFTCodec(dbc, base_id)
    kwargs: dict[str, Any] = {"baudrate": 115200, "timeout": timeout} if interface == "serial" else {}
    try:
        bus = can.Bus(interface=interface, channel=channel, **kwargs)
    except Exception as exc:  # noqa: BLE001 - python-can raises per interface; the reason is shown
        return None, f"{tried}: cannot open ({exc})"
    try:
        arb_id, data = codec.encode_request(OP_READ)
        bus.send(can.Message(arbitration_id=arb_id, data=data, is_extended_id=False))
        status = _status_answer(bus, codec, timeout)
    except (can.CanError, OSError, ValueError) as exc:
        return None, f"{tried}: {exc}"
    finally:
        bus.shutdown()
    if status is None:
        return None, f"{tried}: no answer within {timeout:g} s"
    identity = {"interface": interface, "base_id": base_id, "status": f"0x{status[0]:08x}", "counter": status[1]}
    return Finding("Net F/T", channel, identity), f"{tried}: answered"


def _status_answer(bus: can.BusABC, codec: NetFTCodec, timeout: float) -> tuple[int, int] | None:
    attempts = 64  # a few samples' frames at most; recv's own timeout bounds each wait
    while attempts:
        attempts -= 1
        msg = bus.recv(timeout=timeout)
        if msg is None:
            return None
        try:
            part = codec.decode(msg.arbitration_id, bytes(msg.data))
        except CodecError:
            continue
        if part is not None and part.role == "status":
            return part.value[0], part.value[1]
    return None


def probe_netft_rdt(address: str, *, port: int = DEFAULT_PORT, http_port: int = 80, timeout: float = 0.3) -> Probe:
    """The box's pages on its web server (HTTP: the configuration, the calibration), then one real-time
    record (RDT: start, count 1). The identity says where the counts per unit came from and any software
    bias another program left in the box."""
    tried = f"Net F/T (RDT) at {address}:{port}, calibration on port {http_port}"
    adapter = RdtFTAdapter("probe", Bus(), address, port=port, http_port=http_port)
    try:
        box = adapter.fetch_box()
    except (DeviceError, CodecError) as exc:
        return None, f"{tried}: {exc}"
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.settimeout(timeout)
        try:
            s.sendto(encode_request(CMD_START_REALTIME, 1), (address, port))
            records = decode_packet(s.recv(2048), 1)
        except (OSError, CodecError) as exc:
            return None, f"{tried}: calibration read, no RDT record ({exc or 'timed out'})"
    cal = box.calibration
    identity = {"port": port, "counts_per_force": f"{cal.counts_per_force:g}/{cal.force_unit}",
                "counts_per_torque": f"{cal.counts_per_torque:g}/{cal.torque_unit}", "counts_from": box.source,
                "rdt_rate_hz": cal.rdt_rate_hz, "status": f"0x{records[0].status:08x}",
                "ft_sequence": records[0].ft_sequence, **({"software_bias": list(box.bias)} if any(box.bias) else {})}
    return Finding("Net F/T (RDT)", address, identity), f"{tried}: answered"


def probe_ur(address: str, *, timeout: float = 0.3, dashboard_port: int = 29999) -> Probe:
    """The RTDE version request (port 30004), then the dashboard's version, serial number and model."""
    tried = f"UR controller at {address}"
    try:
        probe_rtde(address, timeout)
    except DeviceIOError as exc:
        return None, f"{tried}: {exc}"
    identity: dict[str, Any] = {"rtde": "protocol 2"}
    link = DashboardLink(address, dashboard_port, timeout)
    try:
        for key, command in UR_IDENTITY:
            identity[key] = link.command(command)
    except (DeviceIOError, OSError) as exc:
        identity["dashboard"] = f"no answer ({exc})"
    finally:
        link.close()
    return Finding("UR controller", address, identity), f"{tried}: answered"
