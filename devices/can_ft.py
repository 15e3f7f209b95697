"""CAN F/T sensors (scene kind ``ft-can``: ATI Net F/T over CAN, frames from a DBC file through cantools)
received with python-can: ``interface="serial"`` on a serial port or an ``ftc sim`` pty (no kernel
CAN here; the port is opened as ``readahead://<port>``, :mod:`ftc_hw.devices.serial_urls`, unless
``read_ahead=False``), ``"virtual"`` in-process, or any python-can interface on real hardware.

``mode="stream"`` asks the sensor to send every sample (opcode 2) and stops it on close (opcode 3);
``mode="poll"`` requests one sample (opcode 1) ``poll_hz`` times per second and publishes each new
one. The sample counter is the sequence number and, at ``rate_hz``, the device clock. Counters:
``checksum_errors`` (error frames: a frame failed its CAN CRC), ``framing_errors`` (bytes the serial
interface could not frame), ``format_errors`` (a sensor frame of the wrong length), ``incomplete``
(samples dropped for a missing part), ``duplicates``, ``foreign`` (other nodes' frames, ignored).
"""
from __future__ import annotations

import struct
import time
from typing import Any

import can
import serial

from ftc_hw.bus import Bus
from ftc_hw.codecs.netft_can import OP_READ, OP_START, OP_STOP, NetFTAssembler, NetFTCodec

from . import serial_urls
from .base import DeviceError, DeviceIOError
from .ft_base import FTAdapter, Silence


class CanFTAdapter(FTAdapter):
    kind = "ft-can"

    def __init__(self, name: str, bus: Bus, channel: str, *, interface: str = "serial",
                 dbc: str = "ati_netft_can.dbc", base_id: int = 8, rate_hz: float = 1000.0, mode: str = "stream",
                 poll_hz: float = 100.0, serial_baudrate: int = 115200, silence_s: float | None = 1.0,
                 can_kwargs: dict[str, Any] | None = None, read_ahead: bool = True, **kwargs: Any) -> None:
        if mode not in ("stream", "poll"):
            raise DeviceError(f"mode {mode!r}: expected stream or poll")
        kwargs.setdefault("stale_after", max(0.05, 5.0 / rate_hz) if mode == "stream" else max(0.05, 5.0 / poll_hz))
        super().__init__(name, bus, seq_modulus=1 << 32, seq_period_ns=round(1e9 / rate_hz), **kwargs)
        self.channel = channel
        self.interface = interface
        self.codec = NetFTCodec(dbc, base_id)
        self.assembler = NetFTAssembler(self.codec)
        self.mode = mode
        self.poll_period = 1.0 / poll_hz
        self.serial_baudrate = serial_baudrate
        self.silence = Silence(self.stale_after, silence_s)
        self.can_kwargs = dict(can_kwargs or {})
        self.read_ahead = read_ahead  # serial interface: the port read through a buffer (serial_urls)
        self.can: can.BusABC | None = None
        self._next_poll = 0.0

    def describe(self) -> str:
        return f"{self.kind} on {self.interface}:{self.channel}, base id {self.codec.base_id}, {self.mode} mode"

    def _send(self, opcode: int) -> None:
        assert self.can is not None
        arb_id, data = self.codec.encode_request(opcode)
        try:
            self.can.send(can.Message(arbitration_id=arb_id, data=data, is_extended_id=False))
        except can.CanError as exc:
            raise DeviceIOError(f"send failed: {exc}") from exc

    def _connect(self) -> None:
        kwargs = dict(self.can_kwargs)
        if self.interface == "serial":
            # frames queued while nobody listened would get a wrong receive time: flush the line first
            with serial.Serial(self.channel, self.serial_baudrate) as s:
                s.reset_input_buffer()
            kwargs.setdefault("baudrate", self.serial_baudrate)
            kwargs.setdefault("timeout", min(self.poll_timeout, self.poll_period / 4) if self.mode == "poll"
                              else self.poll_timeout)
        channel = self.channel
        if self.interface == "serial" and self.read_ahead and "://" not in channel:
            serial_urls.register()
            channel = serial_urls.readahead_url(channel)
        self.can = can.Bus(interface=self.interface, channel=channel, **kwargs)
        self.assembler.reset()
        if self.mode == "stream":
            self._send(OP_START)
        self.silence.heard(time.monotonic())
        self._next_poll = time.monotonic()

    def _read_once(self) -> None:
        if self.mode == "poll" and time.monotonic() >= self._next_poll:
            self._next_poll = max(self._next_poll + self.poll_period, time.monotonic() - self.poll_period)
            self.assembler.expect_answer()
            self._send(OP_READ)
        assert self.can is not None
        c = self.counters
        try:
            msg = self.can.recv(timeout=self._recv_timeout())
        except can.CanOperationError as exc:
            if isinstance(exc.__cause__, serial.SerialException | OSError):
                raise DeviceIOError(f"CAN interface lost: {exc.__cause__}") from exc
            c["framing_errors"] += 1
            return
        except (struct.error, ValueError, TypeError) as exc:  # python-can's serial parser on broken bytes
            c["framing_errors"] += 1
            if "closed" in str(exc):
                raise DeviceIOError(str(exc)) from exc
            return
        t_host = time.monotonic_ns()
        now = time.monotonic()
        if msg is None:
            self.silence.check(now, self.counters)
            return
        if msg.is_error_frame:
            c["checksum_errors"] += 1
            return
        sample = self.assembler.feed(msg.arbitration_id, bytes(msg.data))
        for k, v in self.assembler.counters().items():
            c[k] = v
        if sample is None:
            self.silence.check(now, self.counters)
            return
        self.silence.heard(now)
        self.publish_sample(sample.wrench, t_host_ns=t_host, seq=sample.seq, status=sample.status)

    def _recv_timeout(self) -> float:
        if self.mode == "poll":  # wake up in time for the next request
            return max(0.001, min(self.poll_timeout, self._next_poll - time.monotonic(), self.poll_period / 4))
        return self.poll_timeout

    def _disconnect(self) -> None:
        bus, self.can = self.can, None
        if bus is None:
            return
        try:
            if self.mode == "stream":
                arb_id, data = self.codec.encode_request(OP_STOP)
                bus.send(can.Message(arbitration_id=arb_id, data=data, is_extended_id=False))
        except Exception:  # noqa: BLE001 - the link may already be gone
            pass
        finally:
            bus.shutdown()
