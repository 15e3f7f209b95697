"""Emulator of a streaming serial F/T sensor (scene kind ``ft-serial-stream``) over a pty.

Every world sample becomes one frame of the device's format (``params.format``, default ``ftc-1k``)
with its sequence number (the world sample index plus an offset) and its device time (the world time
plus an offset); frames leave at absolute deadlines of the world's sensor period. The offsets are 0,
or set so that the first frame sent carries ``options["seq_start"]`` and ``options["t_device_start_s"]``
(tests use it to make the counters wrap); the stats report them. Byte-level faults: all of
:mod:`ftc_hw.sim_devices.faults`.
"""
from __future__ import annotations

import time
from typing import Any

from ftc_hw.codecs.stream import stream_format
from ftc_hw.scene import DeviceSpec, Scene

from .emulator import FTEmulator, Pacer, PtyLink, default_pty_path, serve_with
from .link import LinkInfo

_DESTROYS = ("drop", "corrupt", "truncate")


class SerialStreamEmulator(FTEmulator):
    def __init__(self, device: DeviceSpec, scene: Scene, link: LinkInfo, options: dict[str, Any]) -> None:
        super().__init__(device, scene, link, options)
        self.fmt = stream_format(device.params.get("format", "ftc-1k"))
        self.baudrate = int(device.params.get("baudrate", 1_000_000))
        self.seq_start = self.options.get("seq_start")
        self.t_start = self.options.get("t_device_start_s")
        self.seq_offset = self.t_offset_ns = 0
        self.extra_stats.update(seq_offset=0, t_offset_ns=0)
        self.path = str(self.options.get("path") or default_pty_path(scene, device))
        self.pty: PtyLink | None = None

    def bind(self) -> dict[str, Any]:
        self.pty = PtyLink(self.path)
        return {**self.endpoint_base("serial", self.path), "baudrate": self.baudrate, "format": self.fmt.name,
                "rate_hz": self.rate_hz}

    def close(self) -> None:
        if self.pty is not None:
            self.pty.close()

    def loop(self) -> None:
        pacer = Pacer(1.0 / self.rate_hz)
        assert self.pty is not None
        while True:
            pacer.sleep()
            pacer.tick()
            self.pty.read()  # the device ignores what the host sends
            if self.faults.disconnect_due():
                self.unplug()
            for rec in self.new_samples():
                self.send(rec)
            self.extra_stats.update(overflows=self.pty.overflows, cut=self.pty.cut)
            self.heartbeat()

    def send(self, rec) -> None:
        if self.samples == 0:
            if self.seq_start is not None:
                self.seq_offset = int(self.seq_start) - self.sample_number(float(rec[0]))
            if self.t_start is not None:
                self.t_offset_ns = round(float(self.t_start) * 1e9) - round(float(rec[0]) * 1e9)
            self.extra_stats.update(seq_offset=self.seq_offset, t_offset_ns=self.t_offset_ns)
        n = self.sample_number(float(rec[0])) + self.seq_offset
        if not self.count_sample():
            return
        self.check_continuity(n)
        self.extra_stats.setdefault("first_seq", n)
        self.extra_stats["last_seq"] = n
        faults = self.faults
        if faults.stalled():
            faults.counts["stalled"] += 1
            faults.damaged.append(n)
            return
        frame = self.fmt.encode(rec[1:7], seq=n, t_device_ns=round(float(rec[0]) * 1e9) + self.t_offset_ns,
                                status=self.saturation_bits(rec))
        fault = faults.next_fault(sample=n)
        if fault in _DESTROYS:
            faults.damaged.append(n)
        if fault == "delay":
            time.sleep(faults.delay_s)
        assert self.pty is not None
        written = False
        for chunk in faults.apply(fault, frame, protect=len(self.fmt.header)):
            ok = self.pty.write(chunk)
            written |= ok and chunk == frame
        self.delivered(n, fault, written)

    def unplug(self) -> None:
        """The cable is pulled for ``reconnect_after_s``: samples of that time are never sent."""
        assert self.pty is not None
        self.pty.close()
        time.sleep(self.faults.config.reconnect_after_s)
        for rec in self.new_samples():
            n = self.sample_number(float(rec[0])) + self.seq_offset
            self.check_continuity(n)
            self.faults.counts["unplugged"] += 1
            self.faults.damaged.append(n)
        self.pty.open()


def serve(device: DeviceSpec, scene: Scene, link: LinkInfo, ready, options: dict) -> None:
    serve_with(SerialStreamEmulator, device, scene, link, ready, options)
