"""Streaming serial F/T sensors (scene kind ``ft-serial-stream``) through pyserial, for any frame format
of :mod:`ftc_hw.codecs.stream` (``ftc-1k``, ``ft300``, or a format table from the scene)."""
from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import serial

from ftc_hw.bus import Bus
from ftc_hw.codecs.stream import StreamFormat, StreamParser, stream_format

from .base import DeviceIOError
from .ft_base import FTAdapter


class StreamReader:
    """Reads a byte stream from a pyserial port into an adapter: parse, count, publish."""

    def __init__(self, adapter: FTAdapter, fmt: StreamFormat) -> None:
        self.adapter = adapter
        self.parser = StreamParser(fmt)
        self.last_frame = time.monotonic()
        self._silent = False

    def reset(self) -> None:
        self.parser.reset()
        self.last_frame = time.monotonic()
        self._silent = False

    def read(self, ser: serial.Serial, silence_s: float | None = None) -> None:
        """One read (at most the port's timeout); raises DeviceIOError when the port broke, or when
        nothing valid arrived for ``silence_s`` s."""
        try:
            data = ser.read(max(1, ser.in_waiting))
        except (serial.SerialException, OSError, TypeError) as exc:  # pyserial raises TypeError on a closed fd
            raise DeviceIOError(f"read failed: {exc}") from exc
        t_host = time.monotonic_ns()
        a = self.adapter
        samples = self.parser.feed(data) if data else []
        p = self.parser
        c = a.counters
        c["decoded"], c["checksum_errors"], c["format_errors"] = p.frames, p.checksum_errors, p.format_errors
        c["resyncs"], c["bytes_discarded"] = p.resyncs, p.bytes_discarded
        for s in samples:
            a.publish_sample(s.wrench, t_host_ns=t_host, seq=s.seq, t_device_ns=s.t_device_ns, status=s.status)
        now = time.monotonic()
        if samples:
            self.last_frame = now
            self._silent = False
            return
        quiet = now - self.last_frame
        if not self._silent and quiet > a.stale_after:
            self._silent = True
            c["timeouts"] += 1
        if silence_s is not None and quiet > silence_s:
            raise DeviceIOError(f"no valid frame for {quiet:.2f} s")


class SerialStreamFTAdapter(FTAdapter):
    """``port``: a serial device path (or a pty symlink from ``ftc sim``). ``fmt``: a built-in format
    name or a :class:`StreamFormat`. ``silence_s``: reopen the port after this long without a frame."""

    kind = "ft-serial-stream"

    def __init__(self, name: str, bus: Bus, port: str, fmt: str | Mapping[str, Any] | StreamFormat = "ftc-1k", *,
                 baudrate: int = 1_000_000, silence_s: float | None = 2.0, **kwargs: Any) -> None:
        self.fmt = fmt if isinstance(fmt, StreamFormat) else stream_format(fmt)
        kwargs.setdefault("range", self.fmt.range)
        if self.fmt.rate_hz:
            kwargs.setdefault("stale_after", max(0.05, 5.0 / self.fmt.rate_hz))
        super().__init__(name, bus, seq_modulus=self.fmt.seq_modulus,
                         t_device_modulus_ns=self.fmt.t_device_modulus_ns, **kwargs)
        self.port = port
        self.baudrate = baudrate
        self.silence_s = silence_s
        self.reader = StreamReader(self, self.fmt)
        self._ser: serial.Serial | None = None

    def describe(self) -> str:
        return f"{self.kind} {self.fmt.name} on {self.port} at {self.baudrate} Bd"

    def _connect(self) -> None:
        self._ser = serial.Serial(self.port, self.baudrate, timeout=self.poll_timeout)
        self._ser.reset_input_buffer()  # bytes queued while nobody listened carry no usable receive time
        self.reader.reset()

    def _read_once(self) -> None:
        assert self._ser is not None
        self.reader.read(self._ser, self.silence_s)

    def _disconnect(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            ser.close()
