"""Emulator of the ATI Net F/T box over Ethernet (scene kind ``ft-rdt``): RDT over UDP, its web pages
over HTTP and its TCP interface (port 49151), all on the box's own loopback address. What each behaviour
follows (ATI's manual, ATI's Java demo, public clients): ``sim_devices/SOURCES.md``, section Net F/T.

Address: ``options["host"]`` (``ftc sim --address ft=127.0.0.7``; loopback only), else one of its own,
127.0.0.k (k in 10-99) with UDP 49152, TCP 80 and TCP 49151 free there, as the UR emulator has for RTDE:
every client looks for the box at RDT port 49152, the web server at port 80 and the TCP interface at
49151 of its address. UDP port ``options["port"]`` (an explicit one is bound or fails; 0: a free one),
default the device's ``port`` param (49152), or a free one when that is taken. HTTP
``options["http_port"]`` (explicit: bound or fails), default 80; where 80 cannot be bound (no root nor
CAP_NET_BIND_SERVICE, or taken) a free port, said on stderr and in the endpoint (``http_port``,
``http_port_note``), never silently.

Pages: ``/netftapi2.xml[?index=N]`` (the system's fields and configuration N of 16, the active one, 0,
from the scene: counts per unit from the device's ``counts_per_force`` / ``counts_per_torque`` params,
default 100000 per N and 1000000 per N m, N and Nm, ``comrdtrate`` the world's sensor rate, ``comrdtbsiz``
the ``buffer`` param (10); ``runft`` the newest reading less the bias, ``setbias`` the software bias)
and ``/netftcalapi.xml[?index=0]`` (the calibration: ``calcpf``, ``calcpt`` ...); anything else, an index
out of range or not a number: 404. ``options["calibration_fields"]`` replaces elements of the
configuration page, ``options["calibration_xml"]`` the whole page (tests of bad pages),
``options["calapi_fields"]`` elements of the calibration page, ``options["calapi"] = False`` removes it
(404: a box without it).

TCP interface (:mod:`ftc_hw.sim_devices.netft_tcp`): ``options["tcp_port"]`` (explicit: bound or fails),
default 49151; where that cannot be bound, a free port, said on stderr and in the endpoint (``tcp_port``,
``tcp_port_note``); ``options["tcp"] = False`` removes it (a box without it). READCALINFO answers the
pages' calibration (counts per force and torque, unit codes 2 and 3 for N and Nm), scale factors the
smallest that fit each axis's rated range (``calmr``) in int16; READFT the newest reading less the bias
over those factors, status 0 (its sysCommands bias as 0x0042 does and reset the latch as 0x0041);
WRITETRANSFORM and WRITETHRESHOLD are refused with write status 1 (``tcp_refused``): tool transforms and
monitor conditions are not emulated. Counted: ``tcp_connections``, ``tcp_commands``, ``tcp_bad_commands``,
``tcp_aborted``.

Requests: start real-time (0x0002, one record per packet), loop-driven output (0x0001, one record per
packet: ATI's Java library asks for a single record with count 1) or buffered (0x0003, ``comrdtbsiz``
records per packet) streams every world sample from then on to the requester's address, ``count``
records or until stop (0x0000); set software bias (0x0042) subtracts the newest reading's counts from what
follows (and shows in ``setbias``); reset threshold latch (0x0041) is taken (no thresholds are set: the
latch, ``runmcl``, stays 0) and counted in ``latch_resets``; multi-unit streaming (0x0004) is refused:
no answer, counted in ``refused`` (one box alone has no units to synchronise). A datagram that is not a
request (length, header, an unknown command) is ignored and counted in ``bad_requests``.
ft_sequence is the world sample index since the box booted; rdt_sequence counts the packets of the
current stream from 1.
The box's loop wakes every sample period, or above 3.3 kHz every few (``LATE_S``): at 7 kHz every
third, sending the three records made since, one datagram each, in order (each up to 0.29 ms later
than a box that sends every record the moment it is made; the emulator's CPU: a wake-up costs more
than a record).
``options["status_error_records"]``: ``[[first, count], ...]``: the records sent (from 0, over the
emulator's life) that carry status bit 31 (the box reports an error).

Faults act on datagrams: ``drop``, ``duplicate``, ``reorder`` (sent after the next one),
``truncate`` (cut short), ``delay``, ``stall_s`` (nothing sent; the box's counter runs on) and
``disconnect_at_s``: the box reboots (silent for ``reconnect_after_s``, then idle with its sequences
restarted at 0 and no bias, until a client starts a stream again).
"""
from __future__ import annotations

import contextlib
import dataclasses
import random
import select
import socket
import sys
import threading
import time
from http.server import ThreadingHTTPServer
from typing import Any

from ftc_hw.codecs.errors import CodecError
from ftc_hw.codecs.netft_pages import BoxInfo
from ftc_hw.codecs.netft_rdt import (
    CMD_LOOP,
    CMD_RESET_LATCH,
    CMD_SET_BIAS,
    CMD_START_BUFFERED,
    CMD_START_MULTI_UNIT,
    CMD_START_REALTIME,
    CMD_STOP,
    DEFAULT_PORT,
    STATUS_ERROR,
    Calibration,
    RdtRecord,
    decode_request,
    encode_records,
)
from ftc_hw.codecs.netft_tcp import (
    WRITETHRESHOLD,
    WRITETRANSFORM,
    CalInfo,
    ReadCalInfo,
    ReadFT,
    TcpCommand,
    WriteTransform,
    cal_info,
    encode_cal_info,
    encode_ft_reply,
    encode_write_reply,
    ft_reply,
)
from ftc_hw.scene import DeviceSpec, Scene

from .emulator import FTEmulator, Pacer, serve_with
from .link import LinkInfo
from .loopback import check_loopback
from .netft_tcp import TcpServer, bind_tcp, close_tcp
from .netft_web import BoxPages, bind_web

BOX_ADDRESSES = range(10, 100)  # 127.0.0.k of a box without an address given (UR controllers take 100-249)
LATE_S = 0.3e-3  # how much later than one sample period a record may leave (the box's wake-ups)
UDP_FAULTS = frozenset(("drop", "duplicate", "reorder", "truncate", "delay", "stall_s", "disconnect_at_s"))


class RdtEmulator(FTEmulator):
    SUPPORTED_FAULTS = UDP_FAULTS

    def __init__(self, device: DeviceSpec, scene: Scene, link: LinkInfo, options: dict[str, Any]) -> None:
        super().__init__(device, scene, link, options)
        p = device.params
        host = self.options.get("host")
        self.host: str | None = None if host is None else check_loopback(str(host))
        port = self.options.get("port")
        self.port: int | None = None if port is None else int(port)
        self.default_port = int(p.get("port", DEFAULT_PORT))
        http_port = self.options.get("http_port")
        self.http_port: int | None = None if http_port is None else int(http_port)
        self.http_note = ""
        tcp_port = self.options.get("tcp_port")
        self.tcp_port: int | None = None if tcp_port is None else int(tcp_port)
        self.tcp_note = ""
        self.calibration = Calibration(float(p.get("counts_per_force", 100_000)),
                                       float(p.get("counts_per_torque", 1_000_000)), "N", "Nm",
                                       self.rate_hz, int(p.get("buffer", 10)))
        self.pages = BoxPages.of(self.calibration, BoxInfo(), self.options)
        self.cal_info: CalInfo | None = None  # None: no TCP interface
        try:  # READCALINFO on TCP 49151: the counts per unit of the pages, scale factors from their ranges
            if self.options.get("tcp", True) is not False:
                self.cal_info = cal_info(self.calibration, self.pages.info.max_range)
        except CodecError as exc:
            self.tcp_note = f"no TCP interface (port 49151): {exc}"
        self.error_records = tuple((int(a), int(b)) for a, b in self.options.get("status_error_records") or ())
        self.sock: socket.socket | None = None
        self.http: ThreadingHTTPServer | None = None
        self.tcp: TcpServer | None = None
        self.client: tuple[str, int] | None = None
        self.per_packet = 1
        self.remaining = 0  # records still to send; 0: until stopped
        self.rdt_seq = 0
        self.boot_n: int | None = None  # world sample index at boot: ft_sequence counts from it
        self.bias = (0,) * 6
        self.last_counts = (0,) * 6
        self.pending: list[tuple[int, int, int, tuple[int, ...]]] = []  # (world sample, ft_sequence, status,
        # counts) of the records of the packet being filled
        self.held: tuple[bytes, list[int]] | None = None  # a packet held back by a reorder fault
        self.extra_stats.update(requests=0, bad_requests=0, refused=0, latch_resets=0, pages=0, page_errors=0,
                                packets=0, records=0, send_errors=0, reboots=0)

    # -- endpoint ------------------------------------------------------------------------------------
    def bind(self) -> dict[str, Any]:
        if self.host is None:
            self.sock, self.http, self.tcp = self._bind_own_address()
        else:
            self.sock, self.http = self._bind_udp(self.host), self._bind_http(self.host)
            self.tcp = self._bind_tcp(self.host)
        self.pages = dataclasses.replace(self.pages, info=BoxInfo(address=str(self.host)))  # before the first page
        threading.Thread(target=self.http.serve_forever, name="netft-http", daemon=True).start()
        if self.tcp is not None:
            threading.Thread(target=self.tcp.serve_forever, name="netft-tcp", daemon=True).start()
        port, http_port = self.sock.getsockname()[1], self.http.server_address[1]
        for note in (self.http_note, self.tcp_note):
            if note:
                print(f"{self.device.name}: {note}", file=sys.stderr, flush=True)
        return {**self.endpoint_base("udp", f"{self.host}:{port}"), "host": self.host, "port": port,
                "http_port": http_port, **({"http_port_note": self.http_note} if self.http_note else {}),
                "tcp_port": None if self.tcp is None else self.tcp.server_address[1],
                **({"tcp_port_note": self.tcp_note} if self.tcp_note else {}),
                "rate_hz": self.rate_hz, "buffer": self.calibration.buffer_size}

    def _bind_own_address(self) -> tuple[socket.socket, ThreadingHTTPServer, TcpServer | None]:
        """The first 127.0.0.k (in random order) where the RDT port, the web server's port 80 and the TCP
        interface's 49151 all bind; where port 80 is nowhere ours to bind (no root), the first where the RDT
        port binds, the pages and the TCP interface on free ports where theirs are taken (said)."""
        candidates = list(BOX_ADDRESSES)
        random.shuffle(candidates)
        for fallback in (False, True):
            for k in candidates:
                self.host = f"127.0.0.{k}"
                try:
                    sock = self._bind_udp(self.host, fallback=False)
                except OSError:
                    continue
                try:
                    http = self._bind_http(self.host, fallback=fallback)
                except OSError:
                    sock.close()
                    continue
                try:
                    return sock, http, self._bind_tcp(self.host, fallback=fallback)
                except OSError:
                    sock.close()
                    http.server_close()
        self.host = "127.0.0.1"  # the RDT port taken everywhere: free ports, which the endpoint reports
        return self._bind_udp(self.host), self._bind_http(self.host), self._bind_tcp(self.host)

    def _bind_udp(self, host: str, fallback: bool = True) -> socket.socket:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
        try:
            if self.port is not None:
                sock.bind((host, self.port))
                return sock
            try:
                sock.bind((host, self.default_port))
            except OSError:  # taken (another run): a free port, which the endpoint reports
                if not fallback:
                    raise
                sock.bind((host, 0))
        except OSError:
            sock.close()
            raise
        return sock

    def _bind_http(self, host: str, fallback: bool = True) -> ThreadingHTTPServer:
        server, note = bind_web(host, self.http_port, self.page, self.extra_stats, fallback)
        self.http_note = note
        return server

    def _bind_tcp(self, host: str, fallback: bool = True) -> TcpServer | None:
        if self.cal_info is None:
            return None
        server, note = bind_tcp(host, self.tcp_port, self.tcp_answer, self.extra_stats, fallback)
        self.tcp_note = note
        return server

    def tcp_answer(self, command: TcpCommand) -> bytes:
        """The TCP interface's reply: READCALINFO the calibration the pages show; READFT the newest reading
        less the bias in 16-bit counts (its sysCommands bias, as 0x0042 does, and clear the latch, as
        0x0041); the writes refused (tool transforms and monitor conditions are not emulated): status 1."""
        assert self.cal_info is not None
        if isinstance(command, ReadCalInfo):
            return encode_cal_info(self.cal_info)
        if isinstance(command, ReadFT):
            if command.bias:
                self.bias = self.last_counts
            if command.clear_latch:
                self.extra_stats["latch_resets"] += 1
            reading = tuple(c - b for c, b in zip(self.last_counts, self.bias, strict=True))
            return encode_ft_reply(ft_reply(reading, self.cal_info.scale_factors))
        self.extra_stats["tcp_refused"] += 1
        return encode_write_reply(WRITETRANSFORM if isinstance(command, WriteTransform) else WRITETHRESHOLD, 1)

    def page(self, url: str) -> bytes | None:
        """The web server's page at ``url``, or None (404)."""
        reading = tuple(c - b for c, b in zip(self.last_counts, self.bias, strict=True))
        return self.pages.page(url, reading, self.bias)

    def close(self) -> None:
        if self.http is not None:
            with contextlib.suppress(Exception):
                self.http.shutdown()
                self.http.server_close()
        close_tcp(self.tcp)
        if self.sock is not None:
            self.sock.close()

    # -- the box's loop ------------------------------------------------------------------------------
    def loop(self) -> None:
        # a wake-up every k sample periods, k - 1 of them within LATE_S (at 7 kHz every 3rd: 2333 a second
        # instead of 7000; below 3.3 kHz every one), each sending the records made since, in order, one
        # packet each in real-time mode: a record leaves at most k periods after the world made it (it was
        # one), and a wake-up alone costs ~25-35 us of CPU on this VM
        pacer = Pacer((1 + int(LATE_S * self.rate_hz + 1e-9)) / self.rate_hz)
        assert self.sock is not None
        while True:
            if select.select([self.sock], [], [], max(0.0, pacer.remaining()))[0]:
                self.receive()
            if not pacer.due():
                continue
            pacer.tick()
            if self.faults.disconnect_due():
                self.reboot()
            for rec in self.new_samples():
                self.on_sample(rec)
            self.heartbeat()

    def receive(self) -> None:
        assert self.sock is not None
        try:
            data, addr = self.sock.recvfrom(2048)
        except OSError:
            return
        try:
            req = decode_request(data)
        except CodecError:
            self.extra_stats["bad_requests"] += 1
            return
        if req.command == CMD_START_MULTI_UNIT:
            self.extra_stats["refused"] += 1
            return
        self.extra_stats["requests"] += 1
        if req.command in (CMD_LOOP, CMD_START_REALTIME, CMD_START_BUFFERED):
            self.client = addr
            self.per_packet = int(self.calibration.buffer_size or 1) if req.command == CMD_START_BUFFERED else 1
            self.remaining = req.count
            self.rdt_seq = 0
            self.pending = []
            self._last_n = None  # samples outside a stream are not missing
        elif req.command == CMD_STOP:
            self._stop_stream()
        elif req.command == CMD_SET_BIAS:
            self.bias = self.last_counts
        elif req.command == CMD_RESET_LATCH:
            self.extra_stats["latch_resets"] += 1

    def _stop_stream(self) -> None:
        self._flush_held(overtaken=False)
        self.client = None
        self.pending = []

    def on_sample(self, rec) -> None:
        n = self.sample_number(float(rec[0]))
        if self.boot_n is None:
            self.boot_n = self.extra_stats["boot_sample"] = n  # ft_sequence 0
        counts = self.calibration.to_counts(rec[1:7])
        self.last_counts = counts
        if self.client is None:
            return
        if not self.count_sample():
            self._flush_held(overtaken=False)  # max_frames sent: a packet held back still goes out
            return
        self.check_continuity(n)
        status = self.saturation_bits(rec)
        if self.error_records and self._reports_error(self.samples - 1):
            status |= STATUS_ERROR
        biased = tuple(c - b for c, b in zip(counts, self.bias, strict=True)) if any(self.bias) else counts
        self.pending.append((n, n - self.boot_n, status, biased))
        if len(self.pending) >= self.per_packet:
            self.send_packet()
        if self.remaining:
            self.remaining -= 1
            if self.remaining == 0:
                self._stop_stream()

    def _reports_error(self, record: int) -> bool:
        return any(a <= record < a + n for a, n in self.error_records)

    # -- the wire, with its faults -------------------------------------------------------------------
    def send_packet(self) -> None:
        self.rdt_seq = (self.rdt_seq + 1) & 0xFFFFFFFF
        ns = [p[0] for p in self.pending]
        data = encode_records([RdtRecord(self.rdt_seq, ft_seq, status, counts)  # type: ignore[arg-type]
                               for _, ft_seq, status, counts in self.pending])
        self.pending = []
        faults = self.faults
        if faults.stalled():
            faults.counts["stalled"] += 1
            faults.damaged.extend(ns)
            return
        fault = faults.next_fault(sample=ns[0])
        if fault == "drop":
            faults.damaged.extend(ns)
        elif fault == "truncate":
            self._send(data[:faults.rng.randrange(1, len(data))], ns, whole=False)
        elif fault == "reorder" and self.held is None:
            self.held = (data, ns)
            return
        else:
            if fault == "delay":
                time.sleep(faults.delay_s)
            self._send(data, ns)
            if fault == "duplicate":
                self._send(data, ns, count=False)
        self._flush_held()

    def _flush_held(self, overtaken: bool = True) -> None:
        """Send the packet a reorder held back: after the one that overtook it, or (``overtaken`` False:
        the stream ended first) in order after all, which the fault counts then do not count."""
        held, self.held = self.held, None
        if held is None:
            return
        if not overtaken:
            self.faults.counts["reorder"] -= 1
            self.faults.at["reorder"].remove(held[1][0])
        self._send(*held)

    def _send(self, data: bytes, ns: list[int], whole: bool = True, count: bool = True) -> None:
        assert self.sock is not None
        try:
            if self.client is None:
                raise OSError("no client")
            self.sock.sendto(data, self.client)
        except OSError:
            self.extra_stats["send_errors"] += 1
            if count:
                self.faults.damaged.extend(ns)
            return
        self.extra_stats["packets"] += 1
        if not count:
            return
        if whole:
            self.extra_stats["records"] += len(ns)
        else:
            self.faults.damaged.extend(ns)

    def reboot(self) -> None:
        """A power cycle: silent for ``reconnect_after_s`` (requests unanswered, samples not sent), then
        idle, sequences from 0, no bias."""
        streaming = self.client is not None
        self._stop_stream()
        self.extra_stats["reboots"] += 1
        end = time.monotonic() + self.faults.config.reconnect_after_s
        while time.monotonic() < end:
            if self.sock is not None and select.select([self.sock], [], [], 0.01)[0]:
                with contextlib.suppress(OSError):
                    self.sock.recvfrom(2048)
            for rec in self.new_samples():
                if streaming:
                    n = self.sample_number(float(rec[0]))
                    self.check_continuity(n)
                    self.faults.counts["rebooting"] += 1
                    self.faults.damaged.append(n)
            self.heartbeat()
        self.boot_n = None
        self.rdt_seq = 0
        self.bias = (0,) * 6
        self._last_n = None


def serve(device: DeviceSpec, scene: Scene, link: LinkInfo, ready, options: dict) -> None:
    serve_with(RdtEmulator, device, scene, link, ready, options)
