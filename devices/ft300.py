"""Robotiq FT 300 (scene kind ``ft300``): Modbus RTU through pymodbus, polling registers 180-185 or the
100 Hz data stream, as Robotiq's own driver (``rq_sensor_com.c``) drives it:

1. listen for a running stream; if there is one, send the 50-byte 0xFF "jam signal" until the line
   is quiet (the manual's way of stopping the stream). A sensor left streaming by another program
   answers no Modbus until then; this runs on every RTU connect, in poll mode too;
2. identity: FC03 at 500 (firmware, must start with ``F``), 510 (serial), 514 (production year);
3. stream mode: FC16 writes 0x0200 to register 410, then ``20 4E`` frames arrive on the same port
   (:data:`ftc_hw.codecs.stream.FT300_STREAM`); closing sends the jam signal again.

The stream carries neither sequence numbers nor timestamps: frames get the adapter's own ``seq`` and
their receive time. Saturation: an axis at the FT 300's range (300 N, 30 N m).
"""
from __future__ import annotations

import time
from typing import Any

import serial

from ftc_hw.bus import Bus
from ftc_hw.codecs.registers import FT300_MAP
from ftc_hw.codecs.stream import FT300_STREAM

from .base import DeviceError, DeviceIOError
from .modbus_ft import ModbusFTAdapter, PollFailed
from .serial_stream import StreamReader

JAM = b"\xff" * 50  # RQ_COM_JAM_SIGNAL_LENGTH
QUIET_S = 0.08  # rq_com: 80 ms without a byte means the stream stopped
LISTEN_S = 0.03  # a streaming sensor sends a frame every 10 ms


class FT300Adapter(ModbusFTAdapter):
    """``mode``: ``stream`` (100 Hz, RTU only) or ``poll`` (registers 180-185 at ``poll_hz``).
    ``restart_after``: seconds without a valid stream frame before the link is reset and the stream
    restarted."""

    kind = "ft300"

    def __init__(self, name: str, bus: Bus, port: str | None = None, *, mode: str = "stream", device_id: int = 9,
                 baudrate: int = 19200, transport: str = "modbus-rtu", restart_after: float = 0.5,
                 poll_hz: float | None = 100.0, **kwargs: Any) -> None:
        if mode not in ("stream", "poll"):
            raise DeviceError(f"mode {mode!r}: expected stream or poll")
        if mode == "stream" and transport != "modbus-rtu":
            raise DeviceError("the FT 300 data stream exists on its RS-485 (Modbus RTU) link only")
        if mode == "stream":
            kwargs.setdefault("stale_after", 0.05)
        super().__init__(name, bus, FT300_MAP, transport=transport, port=port, device_id=device_id,
                         baudrate=baudrate, poll_hz=poll_hz, **kwargs)
        self.mode = mode
        self.restart_after = restart_after
        self.reader = StreamReader(self, FT300_STREAM)
        self._streaming = False

    def describe(self) -> str:
        return f"{super().describe()}, {self.mode} mode"

    def _open_client(self) -> Any:
        """The Modbus client, on RTU with a stream left running by another program stopped first."""
        client = super()._open_client()
        if self.transport == "modbus-rtu":
            try:
                self._stop_stream(client.socket)  # type: ignore[arg-type]
            except (serial.SerialException, OSError) as exc:
                client.close()
                raise DeviceIOError(str(exc)) from exc
            except BaseException:
                client.close()
                raise
        return client

    def _connect(self) -> None:
        if self.mode == "poll":
            super()._connect()
            return
        client = self._open_client()
        try:
            self.identity = self._with_retries(self.read_identity) or {}
            if not self.identity.get("firmware", "").startswith("F"):
                raise DeviceIOError(f"not an FT 300 (firmware {self.identity.get('firmware')!r})")
            r = client.write_registers(FT300_MAP.stream_register, [FT300_MAP.stream_value], device_id=self.device_id)
            if r.isError():
                raise DeviceIOError(f"register {FT300_MAP.stream_register} refused: {r}")
        except PollFailed as exc:
            raise DeviceIOError(f"FT 300 did not answer: {exc}") from exc
        except (serial.SerialException, OSError) as exc:
            raise DeviceIOError(str(exc)) from exc
        self._streaming = True
        self.reader.reset()
        self.counters["stream_starts"] += 1

    def identify(self) -> dict[str, str]:
        """Once, without the reader thread (``ftc devices probe``): stop a running stream, read the
        identity, close the port. DeviceIOError when nothing answers or what answers is no FT 300."""
        self._open_client()
        try:
            identity = self._with_retries(self.read_identity) or {}
        except PollFailed as exc:
            raise DeviceIOError(f"no answer to the identity read ({exc})") from exc
        except (serial.SerialException, OSError) as exc:
            raise DeviceIOError(str(exc)) from exc
        finally:
            self._disconnect()
        if not identity.get("firmware", "").startswith("F"):
            raise DeviceIOError(f"not an FT 300 (firmware {identity.get('firmware')!r})")
        return identity

    def _stop_stream(self, ser: serial.Serial) -> None:
        """Robotiq's ``rq_com_stop_stream_after_boot``: jam until nothing arrives for 80 ms."""
        ser.reset_input_buffer()
        time.sleep(LISTEN_S)
        for _ in range(5):
            if not ser.in_waiting:
                return
            self.counters["jams"] += 1
            ser.write(JAM)
            ser.flush()
            quiet_since = time.monotonic()
            deadline = quiet_since + 1.0
            while time.monotonic() < deadline:
                if ser.in_waiting:
                    ser.reset_input_buffer()
                    quiet_since = time.monotonic()
                elif time.monotonic() - quiet_since > QUIET_S:
                    return
                time.sleep(0.005)
        raise DeviceIOError("the FT 300 stream does not stop")

    def _read_once(self) -> None:
        if self.mode == "poll":
            super()._read_once()
            return
        client = self.client
        if client is None or client.socket is None:
            raise DeviceIOError("port closed")
        self.reader.read(client.socket, self.restart_after)  # type: ignore[arg-type]

    def _disconnect(self) -> None:
        client = self.client
        if self._streaming and client is not None and client.socket is not None:
            try:
                client.socket.write(JAM)  # leave the sensor in Modbus mode, as the manual asks
                client.socket.flush()
            except (serial.SerialException, OSError):
                pass
        self._streaming = False
        super()._disconnect()
