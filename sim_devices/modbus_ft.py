"""Emulator of a Modbus F/T sensor (scene kind ``modbus-ft``; the FT 300 in :mod:`ftc_hw.sim_devices.ft300`
is one) over Modbus RTU on a pty or Modbus TCP on loopback.

The register map is data (``params.map``: a built-in name or a table, see
:mod:`ftc_hw.codecs.registers`); each read answers the newest world sample. Identity registers
hold ``params.identity`` (``{name: value}``). Transport: the device's ``transport``
(``modbus-rtu`` | ``modbus-tcp``) unless ``options["transport"]``; TCP binds ``options["host"]`` or
the device's ``address`` (default 127.0.0.1) and ``options["port"]`` (default 0: a free port, reported).
RTU answers after the wire time of request and response at the device's baud rate
(``options["wire_time"]``, default true): a poll costs what it costs on a real RS-485 line. A request
with a wrong CRC, or for another unit, gets no answer; a whole frame (CRC good) of a function the
device has not gets exception 01 (Modbus Application Protocol V1.1b3), FC05 and FC43 included.

Faults on RTU: all (a ``corrupt`` response fails its CRC; in stream mode they hit stream frames).
On TCP, whose bytes cannot be corrupted in flight: ``drop`` (no answer), ``delay``, ``duplicate``,
``truncate`` (part of the answer, then the connection is reset), ``stall_s``, ``disconnect_at_s``.
"""
from __future__ import annotations

import contextlib
import select
import selectors
import socket
import time
from typing import Any

from ftc_hw.codecs.checksums import crc16_modbus
from ftc_hw.codecs.errors import CodecError, FrameFormatError
from ftc_hw.codecs.modbus_frames import mbap_decode, mbap_encode, rtu_decode_request, rtu_encode
from ftc_hw.codecs.registers import RegisterMap, encode_identity, register_map
from ftc_hw.codecs.stream import StreamFormat
from ftc_hw.scene import DeviceSpec, Scene

from .emulator import FTEmulator, Pacer, PtyLink, default_pty_path, serve_with
from .link import LinkInfo
from .loopback import check_loopback
from .modbus_slave import ModbusSlave

TCP_FAULTS = frozenset(("drop", "delay", "duplicate", "truncate", "stall_s", "disconnect_at_s"))
JAM_BYTES = 10  # consecutive 0xFF bytes that stop the FT 300 stream (Robotiq's driver sends 50)
SILENCE_S = 0.05  # a request older than this is stale: start a new frame (RTU inter-frame silence)


class ModbusFTEmulator(FTEmulator):
    default_map: str | None = None
    default_identity: dict[str, str] = {}
    stream_format: StreamFormat | None = None  # a stream mode started through the map's stream_register

    def __init__(self, device: DeviceSpec, scene: Scene, link: LinkInfo, options: dict[str, Any]) -> None:
        self.transport = str((options or {}).get("transport", device.transport))
        if self.transport not in ("modbus-rtu", "modbus-tcp"):
            raise ValueError(f"transport {self.transport!r}: expected modbus-rtu or modbus-tcp")
        if self.transport == "modbus-tcp":
            self.SUPPORTED_FAULTS = TCP_FAULTS
        super().__init__(device, scene, link, options)
        p = device.params
        spec = p.get("map", self.default_map)
        if spec is None:
            raise ValueError("params.map: a built-in register map name or a map table is required")
        self.map: RegisterMap = register_map(spec)
        self.device_id = int(p.get("device_id", 1))
        self.baudrate = int(p.get("baudrate", 19200))
        self.wire_time = bool(self.options.get("wire_time", True))
        registers: dict[int, int] = dict.fromkeys(range(self.map.block()[0], sum(self.map.block())), 0)
        registers.update(self.map.encode((0.0,) * 6))
        identity = {**self.default_identity, **dict(p.get("identity", {}))}
        for f in self.map.identity:
            regs = encode_identity(f.decoder, str(identity.get(f.name, "")), f.count)
            registers.update({f.address + i: r for i, r in enumerate(regs)})
        writable: set[int] = set()
        if self.map.stream_register is not None:
            registers[self.map.stream_register] = 0
            writable.add(self.map.stream_register)
        self.slave = ModbusSlave(self.device_id, registers, writable, self._on_write)
        self.streaming = False
        self._start_stream = False
        self.stream_pacer: Pacer | None = None
        self.jam = 0
        self.rx = bytearray()
        self.rx_time = 0.0
        self.last = None
        self.pty: PtyLink | None = None
        self.listener: socket.socket | None = None
        self.sel: selectors.BaseSelector | None = None
        self.host = check_loopback(str(self.options.get("host") or device.address or "127.0.0.1"))
        self.port = int(self.options.get("port", p.get("port", 0)))
        self.path = str(self.options.get("path") or default_pty_path(scene, device))
        self.extra_stats.update(responses=0, bad_requests=0, stream_starts=0, stream_stops=0)

    # -- registers -------------------------------------------------------------------------------------
    def refresh(self) -> None:
        recs = self.new_samples()
        if recs:
            self.last = recs[-1]
        elif self.last is None:
            self.last = self.reader.latest()  # the world's state when the device powered up
        if self.last is not None:
            self.slave.registers.update(self.map.encode(self.last[1:7], self.saturation_bits(self.last)))

    def _on_write(self, address: int, values: list[int]) -> None:
        m = self.map
        if (self.stream_format is not None and self.transport == "modbus-rtu" and address == m.stream_register
                and values and values[0] == m.stream_value):
            self._start_stream = True

    # -- endpoints -------------------------------------------------------------------------------------
    def bind(self) -> dict[str, Any]:
        if self.transport == "modbus-rtu":
            self.pty = PtyLink(self.path)
            return {**self.endpoint_base("modbus-rtu", self.path), "baudrate": self.baudrate,
                    "device_id": self.device_id, "map": self.map.name}
        self._listen()
        return {**self.endpoint_base("modbus-tcp", f"{self.host}:{self.port}"), "host": self.host, "port": self.port,
                "device_id": self.device_id, "map": self.map.name}

    def _listen(self) -> None:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind((self.host, self.port))
        s.listen(8)
        s.setblocking(False)
        self.port = s.getsockname()[1]
        self.listener = s
        self.sel = selectors.DefaultSelector()
        self.sel.register(s, selectors.EVENT_READ, None)

    def close(self) -> None:
        if self.pty is not None:
            self.pty.close()
        self._close_sockets()

    def _close_sockets(self) -> None:
        if self.sel is not None:
            for key in list(self.sel.get_map().values()):
                with contextlib.suppress(OSError):
                    key.fileobj.close()  # type: ignore[union-attr]
            self.sel.close()
            self.sel = None
        self.listener = None

    def loop(self) -> None:
        if self.transport == "modbus-rtu":
            self._loop_rtu()
        else:
            self._loop_tcp()

    # -- RTU -------------------------------------------------------------------------------------------
    def _loop_rtu(self) -> None:
        assert self.pty is not None
        while True:
            timeout = 0.02 if self.stream_pacer is None else max(0.0, min(0.02, self.stream_pacer.remaining()))
            if select.select([self.pty.fileno()], [], [], timeout)[0]:
                self._receive_rtu(self.pty.read())
            if self.stream_pacer is not None and self.stream_pacer.due():
                self.stream_pacer.tick()
                self._send_stream_frame()
            if self.faults.disconnect_due():
                self.pty.close()
                time.sleep(self.faults.config.reconnect_after_s)
                self.new_samples()
                self.rx.clear()
                self.pty.open()
            self.extra_stats.update(overflows=self.pty.overflows, cut=self.pty.cut)
            self.heartbeat()

    def _receive_rtu(self, data: bytes) -> None:
        if self.streaming:
            for b in data:  # the stream ignores everything but a run of 0xFF (the stop "jam signal")
                self.jam = self.jam + 1 if b == 0xFF else 0
            if self.jam >= JAM_BYTES:
                self.streaming, self.stream_pacer, self.jam = False, None, 0
                self.extra_stats["stream_stops"] += 1
                self.rx.clear()
            return
        now = time.monotonic()
        if now - self.rx_time > SILENCE_S:
            self.rx.clear()
        self.rx_time = now
        self.rx += data
        while self.rx:
            try:
                n, req = rtu_decode_request(self.rx)
            except FrameFormatError as exc:
                if self._unknown_function(bytes(self.rx)):
                    continue
                del self.rx[:exc.consumed]
                self.extra_stats["bad_requests"] += 1
                continue
            except CodecError as exc:
                del self.rx[:exc.consumed]
                self.extra_stats["bad_requests"] += 1
                continue
            if n == 0 or req is None:
                break
            del self.rx[:n]
            self._answer_rtu(n, *req)

    def _unknown_function(self, frame: bytes) -> bool:
        """A whole frame of a function code the codec cannot size (RTU frames end by silence; a request
        arrives in one write): when its CRC holds, answer it (exception 01, illegal function, from the
        slave) and take it off the buffer."""
        if len(frame) < 4 or crc16_modbus(frame[:-2]) != int.from_bytes(frame[-2:], "little"):
            return False
        self.rx.clear()
        self._answer_rtu(len(frame), frame[0], frame[1:-2])
        return True

    def _answer_rtu(self, request_len: int, unit: int, pdu: bytes) -> None:
        self._start_stream = False
        self.refresh()
        resp = self.slave.handle(unit, pdu)
        if resp is None:
            return
        frame = rtu_encode(unit, resp)
        if self.wire_time:
            time.sleep((request_len + len(frame)) * 10.0 / self.baudrate)
        if self.faults.stalled():
            self.faults.counts["stalled"] += 1
            return
        fault = self.faults.next_fault("response")
        if fault == "delay":
            time.sleep(self.faults.delay_s)
        assert self.pty is not None
        for chunk in self.faults.apply(fault, frame, protect=2):
            self.pty.write(chunk)
        self.extra_stats["responses"] += 1
        if self._start_stream:
            self.streaming = True
            self.stream_pacer = Pacer(1.0 / (self.stream_format.rate_hz or 100.0))  # type: ignore[union-attr]
            self.extra_stats["stream_starts"] += 1

    def _send_stream_frame(self) -> None:
        """One stream frame with the newest world sample: the device's own 100 Hz clock decimates the world."""
        self.refresh()
        if self.last is None or not self.count_sample():
            return
        if self.faults.stalled():
            self.faults.counts["stalled"] += 1
            return
        assert self.stream_format is not None and self.pty is not None
        frame = self.stream_format.encode(self.last[1:7])
        fault = self.faults.next_fault("stream")
        if fault == "delay":
            time.sleep(self.faults.delay_s)
        for chunk in self.faults.apply(fault, frame, protect=len(self.stream_format.header)):
            self.pty.write(chunk)

    # -- TCP -------------------------------------------------------------------------------------------
    def _loop_tcp(self) -> None:
        while True:
            assert self.sel is not None
            for key, _ in self.sel.select(timeout=0.02):
                if key.fileobj is self.listener:
                    with contextlib.suppress(OSError):
                        conn, _addr = self.listener.accept()  # type: ignore[union-attr]
                        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                        self.sel.register(conn, selectors.EVENT_READ, bytearray())
                    continue
                self._serve_conn(key.fileobj, key.data)  # type: ignore[arg-type]
                if self.sel is None:
                    break
            if self.faults.disconnect_due():
                self._close_sockets()
                time.sleep(self.faults.config.reconnect_after_s)
                self._listen()
            self.heartbeat()

    def _drop_conn(self, conn: socket.socket) -> None:
        if self.sel is not None:
            with contextlib.suppress(KeyError, ValueError):
                self.sel.unregister(conn)
        with contextlib.suppress(OSError):
            conn.close()

    def _serve_conn(self, conn: socket.socket, buf: bytearray) -> None:
        try:
            data = conn.recv(4096)
        except OSError:
            data = b""
        if not data:
            self._drop_conn(conn)
            return
        buf += data
        while buf:
            try:
                n, req = mbap_decode(buf)
            except CodecError:
                self.extra_stats["bad_requests"] += 1
                self._drop_conn(conn)
                return
            if n == 0 or req is None:
                return
            del buf[:n]
            tid, unit, pdu = req
            self.refresh()
            resp = self.slave.handle(unit, pdu)
            if resp is None:
                continue
            if self.faults.stalled():
                self.faults.counts["stalled"] += 1
                continue
            frame = mbap_encode(tid, unit, resp)
            fault = self.faults.next_fault("response")
            if fault == "delay":
                time.sleep(self.faults.delay_s)
            try:
                if fault == "truncate":
                    conn.sendall(frame[:self.faults.rng.randrange(1, len(frame))])
                    self._drop_conn(conn)
                    return
                for chunk in self.faults.apply(fault, frame):
                    conn.sendall(chunk)
            except OSError:
                self._drop_conn(conn)
                return
            self.extra_stats["responses"] += 1


def serve(device: DeviceSpec, scene: Scene, link: LinkInfo, ready, options: dict) -> None:
    serve_with(ModbusFTEmulator, device, scene, link, ready, options)

