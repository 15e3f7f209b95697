"""Emulator of the CAN F/T sensor (scene kind ``ft-can``: ATI Net F/T over CAN, frames from the DBC)
on python-can's ``serial`` interface over a pty (no kernel CAN here).

Requests on the base ID: opcode 1 answers the newest sample once; 2 streams every world sample (four
frames each, at the world's sensor rate); 3 stops; 4 (init/bias, what a public driver sends when it
starts: issue 36) biases the sensor: what it sends from then on is less the newest reading, until a
power cycle (counted ``biases``); any other opcode is ignored and counted in ``bad_requests``, as a
frame that does not decode is. The sample counter is the world sample index (plus
``options["counter_offset"]``). A restarted emulator (power cycle) starts idle and unbiased.

Faults act on CAN frames as a CAN controller would deliver them: ``corrupt`` = the frame failed its
CRC and the host's controller reports an error frame instead; ``truncate`` = a frame with a shortened
DLC; ``garbage`` = a frame from another node (unknown ID, random data) before the sensor's;
``drop``, ``duplicate`` (a retransmission), ``delay``, ``stall_s`` and ``disconnect_at_s`` as usual.
"""
from __future__ import annotations

import math
import select
import time
from typing import Any

import numpy as np

from ftc_hw.codecs import serial_can
from ftc_hw.codecs.errors import CodecError
from ftc_hw.codecs.netft_can import OP_BIAS, OP_READ, OP_START, OP_STOP, NetFTCodec
from ftc_hw.scene import DeviceSpec, Scene

from .emulator import FTEmulator, Pacer, PtyLink, default_pty_path, serve_with
from .link import LinkInfo

_DESTROYS = ("drop", "corrupt", "truncate")


class CanFTEmulator(FTEmulator):
    def __init__(self, device: DeviceSpec, scene: Scene, link: LinkInfo, options: dict[str, Any]) -> None:
        super().__init__(device, scene, link, options)
        p = device.params
        self.base_id = int(p.get("base_id", 8))
        self.dbc = str(p.get("dbc", "ati_netft_can.dbc"))
        self.codec = NetFTCodec(self.dbc, self.base_id)
        self.bitrate = int(p.get("bitrate", 1_000_000))
        self.counter_offset = int(self.options.get("counter_offset", 0))
        self.path = str(self.options.get("path") or default_pty_path(scene, device))
        self.pty: PtyLink | None = None
        self.streaming = False
        self.rx = bytearray()
        self.last = None
        self.bias: np.ndarray | None = None  # the reading at the last bias request (opcode 4), SI
        self.extra_stats.update(requests=0, bad_requests=0, biases=0, frames=0)

    def bind(self) -> dict[str, Any]:
        self.pty = PtyLink(self.path)
        return {**self.endpoint_base("can-serial", self.path), "interface": "serial", "channel": self.path,
                "bitrate": self.bitrate, "base_id": self.base_id, "dbc": self.dbc, "rate_hz": self.rate_hz}

    def close(self) -> None:
        if self.pty is not None:
            self.pty.close()

    def loop(self) -> None:
        pacer = Pacer(1.0 / self.rate_hz)
        assert self.pty is not None
        while True:
            timeout = max(0.0, pacer.remaining())
            if select.select([self.pty.fileno()], [], [], timeout)[0]:
                self.receive(self.pty.read())
            if not pacer.due():
                continue
            pacer.tick()
            if self.faults.disconnect_due():
                self.unplug()
            recs = self.new_samples()
            if recs:
                self.last = recs[-1]
            if self.streaming:
                for rec in recs:
                    self.send_sample(rec)
            self.extra_stats.update(overflows=self.pty.overflows, cut=self.pty.cut)
            self.heartbeat()

    def receive(self, data: bytes) -> None:
        self.rx += data
        while self.rx:
            try:
                n, frame = serial_can.decode(self.rx)
            except CodecError as exc:
                del self.rx[:exc.consumed]
                self.extra_stats["bad_requests"] += 1
                continue
            if n == 0:
                break
            del self.rx[:n]
            if frame is None:
                continue
            arb_id, payload, _ = frame
            part = self.codec.decode(arb_id, payload) if arb_id == self.base_id else None
            if part is None:
                continue
            op = part.value[0]
            if op not in (OP_READ, OP_START, OP_STOP, OP_BIAS):
                self.extra_stats["bad_requests"] += 1
                continue
            self.extra_stats["requests"] += 1
            if op in (OP_READ, OP_BIAS) and self.last is None:  # asked before the pacing loop took a sample
                recs = self.new_samples()
                self.last = recs[-1] if len(recs) else None
            if op in (OP_START, OP_STOP):
                self.streaming = op == OP_START
                self._last_n = None  # samples outside a stream are not missing
            elif op == OP_READ and self.last is not None:
                self.send_sample(self.last, count=False)
            elif op == OP_BIAS and self.last is not None:
                self.bias = np.asarray(self.last[1:7], dtype=float).copy()
                self.extra_stats["biases"] += 1

    def send_sample(self, rec, count: bool = True) -> None:
        n = self.sample_number(float(rec[0])) + self.counter_offset
        if count and not self.count_sample():
            return
        if count:
            self.check_continuity(n)
        faults = self.faults
        if faults.stalled():
            faults.counts["stalled"] += 1
            faults.damaged.append(n)
            return
        t_ms = math.floor(float(rec[0]) * 1000)
        out: list[bytes] = []
        destroyed = False
        written = True
        wrench = rec[1:7] if self.bias is None else np.asarray(rec[1:7], dtype=float) - self.bias
        for arb_id, data in self.codec.encode_sample(wrench, n, self.saturation_bits(rec)):
            fault = faults.next_fault()
            destroyed |= fault in _DESTROYS
            if fault == "delay":
                written &= self._write(out)
                out = []
                time.sleep(faults.delay_s)
            self.extra_stats["frames"] += 1
            out += self._apply(fault, arb_id, data, t_ms)
        written &= self._write(out)
        if destroyed:
            faults.damaged.append(n)
        else:
            self.delivered(n, None, written)

    def _apply(self, fault: str | None, arb_id: int, data: bytes, t_ms: int) -> list[bytes]:
        frame = serial_can.encode(arb_id, data, t_ms)
        rng = self.faults.rng
        if fault == "drop":
            return []
        if fault == "duplicate":
            return [frame, frame]
        if fault == "corrupt":
            return [serial_can.encode(0x0, bytes(8), t_ms, error_frame=True)]
        if fault == "truncate":
            return [serial_can.encode(arb_id, data[:rng.randrange(len(data))], t_ms)]
        if fault == "garbage":
            foreign = rng.choice([i for i in range(0x100, 0x7FF) if i not in self.codec.ids])
            return [serial_can.encode(foreign, bytes(rng.randrange(256) for _ in range(8)), t_ms), frame]
        return [frame]

    def _write(self, chunks: list[bytes]) -> bool:
        if not chunks or self.pty is None:
            return True
        return self.pty.write(b"".join(chunks))

    def unplug(self) -> None:
        assert self.pty is not None
        self.pty.close()
        time.sleep(self.faults.config.reconnect_after_s)
        for rec in self.new_samples():
            if self.streaming:
                n = self.sample_number(float(rec[0])) + self.counter_offset
                self.check_continuity(n)
                self.faults.counts["unplugged"] += 1
                self.faults.damaged.append(n)
        self.rx.clear()
        self.pty.open()


def serve(device: DeviceSpec, scene: Scene, link: LinkInfo, ready, options: dict) -> None:
    serve_with(CanFTEmulator, device, scene, link, ready, options)
