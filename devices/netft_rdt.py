"""ATI Net F/T over Ethernet (scene kind ``ft-rdt``): RDT over UDP, counts per unit from the box's own
web pages (:mod:`ftc_hw.codecs.netft_rdt`, :mod:`ftc_hw.codecs.netft_pages`).

On connect the adapter reads ``http://<box>:<http_port>/netftapi2.xml`` (the active configuration: RDT
rate, buffer size, the software bias, ``cfgcalsel``) and ``/netftcalapi.xml?index=<cfgcalsel>`` (the
calibration: ``calcpf``/``calcpt`` in ``scalfu``/``scaltu``, the names real boxes and the ROS drivers
use; a box without that page (404) is asked READCALINFO on its TCP interface, ``tcp_port`` 49151
(:mod:`ftc_hw.codecs.netft_tcp`: counts per force and torque unit, unit codes; counted in ``calibration_tcp``),
and where that does not answer either (``calinfo_errors``) the configuration's ``cfgcpf``/``cfgcpt`` are
taken, counted in ``calibration_fallback``), unless ``read_calibration=False``, and reconciles them with the scene's
``counts_per_force`` / ``counts_per_torque`` (per N and N m, an override that must agree with the box per SI
unit when both are known), ``rate_hz`` (the box's ``comrdtrate``; None: take the box's) and, in buffered
mode, ``buffer`` (``comrdtbsiz``): a page that is malformed or disagrees fails the connect with a
:class:`~ftc_hw.codecs.netft_rdt.CalibrationError` naming what (a ``reconnecting`` event says it, and the
reader retries). Then it sends start (real-time: one record per packet; buffered: ``buffer`` per packet)
and publishes every record; close sends stop.

A box left biased in software by another program (RDT ``0x0042``: the box subtracts that reading from
every record until it reboots) is not re-biased nor cleared (the other program may rely on it): the
adapter reads the bias (``setbias``, in counts) at each connect, adds it back to every record, so that
what it publishes is the box's unbiased reading, as this project's calibration expects, and says so in
its ``connect`` event (``box_bias``). A bias set while the adapter streams is seen at its next connect.

Sequence numbers: ft_sequence (the box's sample counter) is the frame's seq and, at ``rate_hz``, its
device clock; rdt_sequence (+1 per packet) tells lost packets (``packets_lost``), duplicated ones
(``duplicates``) and late ones (``late``: a packet older than one already received, dropped: its
samples were already counted as a gap). Counters besides the F/T ones: ``packets``, ``records``
(received whole), ``box_packets`` (what the box says it sent: the newest rdt_sequence, summed over
connections; ``box_packets - packets`` were lost on the way or in this host), ``format_errors`` (a
datagram that is not whole records, or not as many as the mode sends), ``kernel_drops`` (datagrams
the host's socket buffer overflowed, where Linux reports it), ``device_errors`` (records whose status
word has error bits: flagged ``DEVICE_ERROR``, with an ``error`` event when they appear and
``recovered`` when they clear). A box silent for ``silence_s`` (rebooted: it forgot the stream) is
reconnected, which starts the stream again.
"""
from __future__ import annotations

import socket
import struct
import time
import urllib.error
import urllib.request
from typing import Any

import numpy as np

from ftc_hw.bus import Bus
from ftc_hw.codecs.errors import CodecError, FrameFormatError
from ftc_hw.codecs.netft_pages import CALIBRATION_PAGE, CONFIG_PAGE, BoxState, page_fields, read_box
from ftc_hw.codecs.netft_rdt import (
    CMD_START_BUFFERED,
    CMD_START_REALTIME,
    CMD_STOP,
    DEFAULT_PORT,
    STATUS_ERROR_MASK,
    Calibration,
    CalibrationError,
    decode_packet,
    encode_request,
    reconcile,
)
from ftc_hw.codecs.netft_tcp import CAL_REPLY_SIZE, TCP_PORT, ReadCalInfo, decode_cal_info, encode_command

from .base import DeviceError, DeviceIOError
from .ft_base import FTAdapter, Silence

SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)  # Linux: a datagram's ancillary data counts the drops
MAX_RATE_HZ = 7000.0  # the box's highest RDT rate
LATE_EPOCH = 50  # this many late packets in a row: the box restarted its packet counter (a new epoch)


class RdtFTAdapter(FTAdapter):
    kind = "ft-rdt"
    status_error_mask = STATUS_ERROR_MASK

    def __init__(self, name: str, bus: Bus, host: str, *, port: int = DEFAULT_PORT, http_port: int = 80,
                 tcp_port: int = TCP_PORT,
                 mode: str = "realtime", rate_hz: float | None = None, buffer: int | None = None,
                 counts_per_force: float | None = None, counts_per_torque: float | None = None,
                 read_calibration: bool = True, silence_s: float | None = 1.0, receive_buffer: int = 4 << 20,
                 **kwargs: Any) -> None:
        if mode not in ("realtime", "buffered"):
            raise DeviceError(f"mode {mode!r}: expected realtime or buffered")
        kwargs.setdefault("stale_after", max(0.05, 5.0 * (buffer or 1) / (rate_hz or MAX_RATE_HZ)))
        super().__init__(name, bus, seq_modulus=1 << 32, seq_period_ns=round(1e9 / (rate_hz or MAX_RATE_HZ)), **kwargs)
        self.host, self.port, self.http_port, self.tcp_port = host, int(port), int(http_port), int(tcp_port)
        self.mode = mode
        self.rate_hz = None if rate_hz is None else float(rate_hz)  # None: the box's comrdtrate
        self.buffer = buffer
        self.overrides = (counts_per_force, counts_per_torque)
        self.read_calibration = read_calibration
        self.silence = Silence(self.stale_after, silence_s)
        self.receive_buffer = receive_buffer
        self.calibration: Calibration | None = None
        self.box: BoxState | None = None  # the box's pages, as last read
        self._bias = np.zeros(6)  # the box's software bias, in counts, added back to every record
        self.sock: socket.socket | None = None
        self._scale = np.ones(6)
        self._per_packet: int | None = None
        self._last_rdt: int | None = None
        self._late_run = 0
        self._rdt_base = 0  # box_packets before this connection

    def describe(self) -> str:
        cal = self.calibration
        units = f", {cal.counts_per_force:g} counts/{cal.force_unit}, {cal.counts_per_torque:g} counts/" \
                f"{cal.torque_unit}" if cal is not None else ""
        bias = f"; the box's software bias (another program's) undone: box_bias {self._bias.astype(int).tolist()} " \
               "counts" if self._bias.any() else ""
        return f"{self.kind} at {self.host}:{self.port}, {self.mode} at {self.rate_hz or 0:g} Hz{units}{bias}"

    # -- connect ---------------------------------------------------------------------------------------
    def fetch_calibration(self) -> Calibration:
        """The box's calibration, from its pages (CalibrationError names what is wrong with them)."""
        return self.fetch_box().calibration

    def fetch_box(self) -> BoxState:
        """The box's configuration page, then its calibration page (``cfgcalsel``'s; a 404 there: READCALINFO
        on its TCP interface, else the configuration's counts, counted in ``calibration_fallback``), read."""
        config = self._get(CONFIG_PAGE)
        index = page_fields(config, CONFIG_PAGE).get("cfgcalsel")
        tcp = None
        try:
            calibration: bytes | None = self._get(CALIBRATION_PAGE + (f"?index={index}" if index else ""))
        except _NotFound:
            calibration = None
            tcp = self.read_cal_info()
            if tcp is None:
                self.counters["calibration_fallback"] += 1
        return read_box(config, calibration, tcp, f"TCP {self.tcp_port} READCALINFO")

    def read_cal_info(self) -> Calibration | None:
        """The calibration as the box's TCP interface answers READCALINFO; None where it does not (nothing
        there, a short or malformed reply: counted in ``calinfo_errors``)."""
        try:
            with socket.create_connection((self.host, self.tcp_port), timeout=1.0) as s:
                s.sendall(encode_command(ReadCalInfo()))
                reply = s.recv(CAL_REPLY_SIZE, socket.MSG_WAITALL)
            cal = decode_cal_info(reply).calibration()
        except (OSError, CodecError):
            self.counters["calinfo_errors"] += 1
            return None
        self.counters["calibration_tcp"] += 1
        return cal

    def _get(self, page: str) -> bytes:
        url = f"http://{self.host}:{self.http_port}{page}"
        try:
            with urllib.request.urlopen(url, timeout=1.0) as answer:
                return answer.read()
        except urllib.error.HTTPError as exc:
            if exc.code == 404:
                raise _NotFound(f"page {url}: 404") from exc
            raise DeviceIOError(f"page {url}: {exc}") from exc
        except (urllib.error.URLError, OSError) as exc:
            raise DeviceIOError(f"page {url}: {exc}") from exc

    def _connect(self) -> None:
        self.box = self.fetch_box() if self.read_calibration else None
        box = self.box.calibration if self.box is not None else None
        self._bias = np.asarray(self.box.bias if self.box is not None else (0,) * 6, dtype=float)
        buffered = self.mode == "buffered"
        cal = reconcile(box, counts_per_force=self.overrides[0], counts_per_torque=self.overrides[1],
                        rate_hz=self.rate_hz, buffer_size=self.buffer if buffered else None)
        self.calibration = cal
        if self.rate_hz is None:
            if cal.rdt_rate_hz is None:
                raise CalibrationError("comrdtrate", "not on the box's page: set the device's rate_hz")
            self.rate_hz = cal.rdt_rate_hz
        self.seq_period_ns = round(1e9 / self.rate_hz)  # the F/T sequence's clock
        self._scale = np.asarray(cal.scale)
        self._per_packet = (self.buffer or cal.buffer_size) if buffered else 1
        if self._per_packet is None:
            raise DeviceError("buffered mode: the box's page gives no comrdtbsiz; set the device's buffer param")
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock = sock
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, self.receive_buffer)
        try:
            sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
        except OSError:
            self.counters["kernel_drops_unknown"] = 1
        sock.connect((self.host, self.port))  # only the box's datagrams reach this socket
        sock.settimeout(self.poll_timeout)
        self._last_rdt = None
        self._late_run = 0
        self._rdt_base = self.counters["box_packets"]
        self._send(CMD_START_BUFFERED if buffered else CMD_START_REALTIME)
        self.silence.heard(time.monotonic())

    def _send(self, command: int) -> None:
        assert self.sock is not None
        try:
            self.sock.send(encode_request(command))
        except OSError as exc:
            raise DeviceIOError(f"request {command:#06x} not sent: {exc}") from exc

    # -- read ------------------------------------------------------------------------------------------
    def _read_once(self) -> None:
        assert self.sock is not None
        try:
            data, ancillary, _, _ = self.sock.recvmsg(65536, socket.CMSG_SPACE(4))
        except TimeoutError:
            self.silence.check(time.monotonic(), self.counters)
            return
        except OSError as exc:  # ICMP port unreachable (nobody at the box's port) and the like
            raise DeviceIOError(f"RDT socket: {exc}") from exc
        t_host = time.monotonic_ns()
        c = self.counters
        c["packets"] += 1
        for level, kind, value in ancillary:
            if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(value) >= 4:
                c["kernel_drops"] = struct.unpack("I", value[:4])[0]
        try:
            records = decode_packet(data, self._per_packet)
        except FrameFormatError:
            c["format_errors"] += 1
            self.silence.check(time.monotonic(), self.counters)
            return
        if not self._in_order(records[0].rdt_sequence):
            return
        self.silence.heard(time.monotonic())
        scale, bias = self._scale, self._bias
        for r in records:
            c["records"] += 1
            self.publish_sample((np.asarray(r.counts, dtype=float) + bias) * scale, t_host_ns=t_host,
                                seq=r.ft_sequence, status=r.status)

    def _in_order(self, rdt: int) -> bool:
        """Whether a packet is new (counting lost, duplicated and late packets); the first of a connection is."""
        last, c = self._last_rdt, self.counters
        if last is not None:
            step = (rdt - last) % (1 << 32)
            if step == 0:
                c["duplicates"] += 1
                return False
            if step >= 1 << 31 and self._late_run < LATE_EPOCH:
                c["late"] += 1
                self._late_run += 1
                return False
            if step < 1 << 31:
                c["packets_lost"] += step - 1
        self._late_run = 0
        self._last_rdt = rdt
        c["box_packets"] = self._rdt_base + rdt
        return True

    def _disconnect(self) -> None:
        sock, self.sock = self.sock, None
        if sock is None:
            return
        try:
            sock.send(encode_request(CMD_STOP))
        except OSError:
            pass
        finally:
            sock.close()


class _NotFound(DeviceIOError):
    """The box answered 404: it has no such page."""
