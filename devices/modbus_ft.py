"""Generic Modbus F/T sensors (scene kind ``modbus-ft``) over RTU or TCP through pymodbus (3.16.1:
``device_id=``, keyword-only ``count=``): one engine, any register map (:mod:`ftc_hw.codecs.registers`).

Each poll reads the map's block in one request and publishes one frame (no device sequence or
clock: ``seq`` is the adapter's own count). A failed poll is counted as ``timeouts`` (no answer),
``checksum_errors`` (an answer of the right length whose CRC is wrong, RTU) or ``format_errors``
(a short or malformed answer); ``max_failures`` failed polls in a row reconnect. On RTU, an answer still
waiting when the next request goes out is counted ``late_answers``: one that came after its request had timed
out (a stalled host or device), or a repeated one; pymodbus discards it before sending.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from typing import Any

from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

from ftc_hw.bus import Bus
from ftc_hw.codecs.checksums import crc16_modbus
from ftc_hw.codecs.errors import FrameFormatError
from ftc_hw.codecs.registers import RegisterMap, register_map

from .base import DeviceError, DeviceIOError
from .ft_base import FTAdapter

# pymodbus logs every failed connect on stderr ("Connection ... refused", "Repeating...."): the
# adapter already turns each into a counted bus event, and the stray lines would tear the live view
logging.getLogger("pymodbus.logging").setLevel(logging.CRITICAL)


class PollFailed(Exception):
    """One request got no usable answer (counted; the link may still be fine)."""


class ModbusFTAdapter(FTAdapter):
    """``transport``: ``modbus-rtu`` (``port`` = serial path) or ``modbus-tcp`` (``host``, ``tcp_port``).
    ``poll_hz``: polls per second (None or 0: as fast as the link answers). ``timeout``: per request."""

    kind = "modbus-ft"

    def __init__(self, name: str, bus: Bus, register_map_: str | Mapping[str, Any] | RegisterMap, *,
                 transport: str = "modbus-rtu", port: str | None = None, host: str = "127.0.0.1",
                 tcp_port: int = 502, device_id: int = 1, baudrate: int = 19200, poll_hz: float | None = None,
                 timeout: float = 0.1, max_failures: int = 3, **kwargs: Any) -> None:
        self.map = register_map_ if isinstance(register_map_, RegisterMap) else register_map(register_map_)
        if transport not in ("modbus-rtu", "modbus-tcp"):
            raise DeviceError(f"transport {transport!r}: expected modbus-rtu or modbus-tcp")
        if transport == "modbus-rtu" and not port:
            raise DeviceError("modbus-rtu needs a serial port path")
        kwargs.setdefault("range", self.map.range)
        kwargs.setdefault("stale_after", 0.1 if transport == "modbus-rtu" else 0.05)
        super().__init__(name, bus, **kwargs)
        self.transport = transport
        self.port, self.host, self.tcp_port = port, host, tcp_port
        self.device_id = device_id
        self.baudrate = baudrate
        self.poll_period = 1.0 / poll_hz if poll_hz else 0.0
        self.timeout = timeout
        self.max_failures = max_failures
        self.client: ModbusSerialClient | ModbusTcpClient | None = None
        self._rx = b""
        self._fails = 0
        self._next_poll = 0.0

    def describe(self) -> str:
        where = self.port if self.transport == "modbus-rtu" else f"{self.host}:{self.tcp_port}"
        ident = ", ".join(f"{k} {v}" for k, v in self.identity.items())
        return f"{self.kind} ({self.map.name}) over {self.transport} at {where}, id {self.device_id}" + (
            f" [{ident}]" if ident else "")

    # -- pymodbus ------------------------------------------------------------------------------------
    def _trace(self, sending: bool, data: bytes) -> bytes:
        if not sending:
            self._rx = bytes(data)  # pymodbus passes everything received so far for this request
        elif isinstance(self.client, ModbusSerialClient) and self.client.socket is not None \
                and self.client.socket.in_waiting:
            self.counters["late_answers"] += 1
        return data

    def _open_client(self) -> ModbusSerialClient | ModbusTcpClient:
        if self.transport == "modbus-rtu":
            client: ModbusSerialClient | ModbusTcpClient = ModbusSerialClient(
                self.port or "", baudrate=self.baudrate, timeout=self.timeout, retries=0, trace_packet=self._trace)
        else:
            client = ModbusTcpClient(self.host, port=self.tcp_port, timeout=self.timeout, retries=0,
                                     trace_packet=self._trace)
        if not client.connect():
            client.close()
            raise DeviceIOError(f"cannot open {self.port if self.transport == 'modbus-rtu' else self.host}")
        self.client = client
        return client

    def read_registers(self, address: int, count: int, function: int | None = None) -> list[int]:
        """One read request; raises PollFailed (counted) or DeviceIOError (link broken)."""
        client = self.client
        if client is None:
            raise DeviceIOError("not connected")
        fc = self.map.function if function is None else function
        read = client.read_holding_registers if fc == 3 else client.read_input_registers
        self._rx = b""
        try:
            r = read(address, count=count, device_id=self.device_id)
        except (ConnectionException, OSError) as exc:
            raise DeviceIOError(f"connection lost: {exc!r}") from exc
        except ModbusIOException as exc:
            self._count_failure(5 + 2 * count)
            raise PollFailed(str(exc)) from exc
        except ModbusException as exc:
            self.counters["format_errors"] += 1
            raise PollFailed(str(exc)) from exc
        if r.isError():
            self.counters["exceptions"] += 1
            raise PollFailed(f"exception response {r}")
        if len(r.registers) != count:
            self.counters["format_errors"] += 1
            raise PollFailed(f"{len(r.registers)} registers, expected {count}")
        return list(r.registers)

    def _count_failure(self, expected_len: int) -> None:
        rx = self._rx
        c = self.counters
        if not rx:
            c["timeouts"] += 1
        elif self.transport == "modbus-rtu" and len(rx) >= expected_len and \
                crc16_modbus(rx[:expected_len - 2]) != int.from_bytes(rx[expected_len - 2:expected_len], "little"):
            c["checksum_errors"] += 1
        else:
            c["format_errors"] += 1

    def read_identity(self) -> dict[str, str]:
        out = {}
        for f in self.map.identity:
            out[f.name] = self.map.decode_identity(f, self.read_registers(f.address, f.count, 3))
        return out

    def _with_retries(self, fn, attempts: int = 3):
        for i in range(attempts):
            try:
                return fn()
            except PollFailed:
                if i == attempts - 1:
                    raise
        return None

    # -- Adapter ---------------------------------------------------------------------------------------
    def _connect(self) -> None:
        self._open_client()
        try:
            self.identity = self._with_retries(self.read_identity) or {}
        except PollFailed as exc:
            raise DeviceIOError(f"no answer to the identity read: {exc}") from exc
        self._fails = 0
        self._next_poll = time.monotonic()

    def _read_once(self) -> None:
        if self.poll_period:
            wait = self._next_poll - time.monotonic()
            if wait > 0:
                time.sleep(min(wait, self.poll_timeout))
                if wait > self.poll_timeout:
                    return
            self._next_poll = max(self._next_poll + self.poll_period, time.monotonic() - self.poll_period)
        start, count = self.map.block()
        try:
            regs = self.read_registers(start, count)
            wrench, status = self.map.decode(regs, start)
        except (PollFailed, FrameFormatError) as exc:
            if isinstance(exc, FrameFormatError):
                self.counters["format_errors"] += 1
            self._fails += 1
            if self._fails >= self.max_failures:
                raise DeviceIOError(f"{self._fails} polls failed in a row (last: {exc})") from exc
            return
        self._fails = 0
        self.counters["polls"] += 1
        self.publish_sample(wrench, t_host_ns=time.monotonic_ns(), status=status)

    def _disconnect(self) -> None:
        client, self.client = self.client, None
        if client is not None:
            client.close()
