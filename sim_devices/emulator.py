"""What every emulator process shares (:class:`Emulator`: the world link, the endpoint's lifecycle, a
stats file, fault injection, an exit with the world's process and a clean one on SIGTERM), what every
F/T emulator adds (:class:`FTEmulator`: the world's F/T samples, their numbering and accounting), and
their helpers: a pty endpoint with a stable path, absolute deadline pacing. The arm emulators
(``dynamixel``, ``ur``) are emulators of the first kind.

Endpoint of a pty device: the emulator owns the pty master; clients open ``path``
(``/tmp/ftc-<scene>-<device>-<runner pid>.tty`` unless ``options["path"]``), a symlink replaced
atomically whenever the pty is re-created (after a simulated unplug, or when the emulator is
restarted), so a client reopens the same path. The emulator keeps a slave descriptor of its own open,
so that the pty survives clients coming and going (what it writes while nobody listens is discarded
by the client's input flush on open), and the symlink points at that descriptor,
``/proc/<emulator pid>/fd/<n>``, not at ``/dev/pts/<n>``: when the emulator dies the path stops
resolving, where a ``/dev/pts`` name would soon be reused by another process's pty.

Options every emulator understands: ``faults`` (those its transport supports, none for the arms),
``seed`` (see :mod:`ftc_hw.sim_devices.faults`), ``stats_path`` (JSON file with the emulator's
counters, rewritten at most every 0.1 s and at exit); every F/T emulator: ``max_frames`` (stop sending
after this many samples; the stats then say ``"done": true``).
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import select
import signal
import time
import tty
from pathlib import Path
from typing import Any

import numpy as np

from ftc_hw.scene import DeviceSpec, Scene

from .faults import ALL_FAULTS, FaultConfig, FaultInjector
from .link import EmulatorSide, LinkInfo


def sample_number(t: float, rate_hz: float) -> int:
    """The index of the world sample at time ``t``. The world samples at ``(k + 1/2) / rate`` after its
    first step (and ``k / rate`` in tests): flooring keeps both apart where rounding half to even would
    merge neighbours."""
    return math.floor(t * rate_hz + 1e-6)


def default_pty_path(scene: Scene, device: DeviceSpec) -> str:
    return f"/tmp/ftc-{scene.name}-{device.name}-{os.getppid()}.tty"


class PtyLink:
    """The device side of a serial line: a pty master, and a symlink clients open."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.master = self.slave = -1
        self.slave_name = self.target = ""
        self.overflows = self.cut = 0
        self.open()

    def open(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self.master, self.slave = master, slave
        self.slave_name = os.ttyname(slave)
        proc_fd = f"/proc/{os.getpid()}/fd/{slave}"
        self.target = proc_fd if os.path.exists(proc_fd) else self.slave_name
        tmp = f"{self.path}.{os.getpid()}.tmp"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        os.symlink(self.target, tmp)
        os.replace(tmp, self.path)

    def close(self) -> None:
        """Unplug: the symlink disappears and clients reading the old pty get EIO."""
        with contextlib.suppress(OSError):
            if os.readlink(self.path) == self.target:
                os.unlink(self.path)
        for fd in (self.master, self.slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self.master = self.slave = -1

    def fileno(self) -> int:
        return self.master

    def write(self, data: bytes) -> bool:
        """Write one frame; False when the client's buffer is full (nobody reading, or a client stalled
        for longer than the ~20 kB pty buffer lasts): the frame is dropped whole, as a device with no
        listener loses it. A frame that fitted in part is finished (waiting up to 1 s) so that the
        client never sees a frame cut by the buffer."""
        if not data or self.master < 0:
            return False
        try:
            n = os.write(self.master, data)
        except BlockingIOError:
            n = 0
        if n == 0:
            self.overflows += 1
            return False
        rest = data[n:]
        deadline = time.monotonic() + 1.0
        while rest and time.monotonic() < deadline:
            select.select([], [self.master], [], 0.01)
            with contextlib.suppress(BlockingIOError):
                rest = rest[os.write(self.master, rest):]
        if rest:
            self.cut += 1
        return True

    def read(self, n: int = 4096) -> bytes:
        try:
            return os.read(self.master, n)
        except (BlockingIOError, OSError):
            return b""


class Pacer:
    """Absolute deadlines every ``period`` s; a late caller is not made to catch up bursts after a stall."""

    def __init__(self, period: float, start_in: float | None = None) -> None:
        self.period = period
        self.next = time.monotonic() + (period if start_in is None else start_in)

    def remaining(self) -> float:
        return self.next - time.monotonic()

    def due(self) -> bool:
        return self.remaining() <= 0.0

    def tick(self) -> None:
        self.next += self.period
        now = time.monotonic()
        if now - self.next > 5 * self.period:
            self.next = now + self.period

    def sleep(self) -> None:
        r = self.remaining()
        if r > 0:
            time.sleep(r)


class StatsFile:
    def __init__(self, path: str | None) -> None:
        self.path = Path(path) if path else None
        self._last = 0.0

    def write(self, data: dict[str, Any], force: bool = False) -> None:
        if self.path is None:
            return
        now = time.monotonic()
        if not force and now - self._last < 0.1:
            return
        self._last = now
        tmp = self.path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps(data))
        os.replace(tmp, self.path)


def _raise_exit(signum: int, frame: object) -> None:
    """The first SIGTERM ends the serving loop; any later one is ignored: raised again while the process
    runs its exit handlers it would print a traceback there (and on the monitor's stderr)."""
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise SystemExit(0)


class Emulator:
    """Base of every emulator process: ``bind()`` returns the endpoint dict, ``loop()`` serves until the
    process ends (``heartbeat()`` in it), ``close()`` releases the endpoint; ``run()`` does the three."""

    SUPPORTED_FAULTS: frozenset[str] = frozenset()  # none unless the transport says

    def __init__(self, device: DeviceSpec, scene: Scene, link: LinkInfo, options: dict[str, Any]) -> None:
        self.device = device
        self.scene = scene
        self.options = dict(options or {})
        self.faults = FaultInjector(FaultConfig.from_options(self.options, self.SUPPORTED_FAULTS))
        self.side = EmulatorSide(link)
        self.stats_file = StatsFile(self.options.get("stats_path"))
        self._ppid = os.getppid()
        self.extra_stats: dict[str, Any] = {}

    # -- stats -----------------------------------------------------------------------------------------
    def stats(self) -> dict[str, Any]:
        return {"name": self.device.name, **self.faults.snapshot(), **self.extra_stats}

    def write_stats(self, force: bool = False) -> None:
        self.stats_file.write(self.stats(), force)

    def parent_gone(self) -> bool:
        """The process that started this one (the world's) is gone."""
        return os.getppid() != self._ppid

    def heartbeat(self) -> None:
        """Called by the serving loops: stats to disk, and an exit once the parent (the runner) is gone,
        so that a runner killed without its cleanup leaves no emulator behind."""
        if self.parent_gone():
            raise SystemExit(0)
        self.write_stats()

    # -- process ---------------------------------------------------------------------------------------
    def bind(self) -> dict[str, Any]:
        raise NotImplementedError

    def loop(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        """Release the endpoint (remove a pty symlink); must not raise."""

    def endpoint_base(self, transport: str, endpoint: str) -> dict[str, Any]:
        return {"name": self.device.name, "kind": self.device.kind, "transport": transport, "endpoint": endpoint}

    def run(self, ready) -> None:
        signal.signal(signal.SIGTERM, _raise_exit)
        try:
            endpoint = self.bind()
        except Exception as exc:  # noqa: BLE001 - reported to the parent, which raises
            self.close()
            ready.put({"error": f"{type(exc).__name__}: {exc}"})
            return
        self.faults.start()
        endpoint["ready_ns"] = time.monotonic_ns()  # CLOCK_MONOTONIC is shared by the host's processes
        ready.put(endpoint)
        try:
            self.loop()
        finally:
            self.close()
            with contextlib.suppress(Exception):
                self.write_stats(force=True)


class FTEmulator(Emulator):
    """Base of the F/T emulators: the world's F/T samples, their numbers at the sensor's rate, what was
    sent and what was not."""

    SUPPORTED_FAULTS: frozenset[str] = ALL_FAULTS - {"reorder"}  # a byte stream keeps its order

    def __init__(self, device: DeviceSpec, scene: Scene, link: LinkInfo, options: dict[str, Any]) -> None:
        super().__init__(device, scene, link, options)
        sensor = scene.require_ft(f"the F/T emulator of device {device.name!r}")
        self.reader = self.side.ft_reader()
        mf = self.options.get("max_frames")
        self.max_frames = None if mf is None else int(mf)
        self.rate_hz = float(sensor.rate_hz)
        self.samples = 0  # samples sent (or attempted: faults included)
        self._last_n: int | None = None
        self.done = False

    # -- world -----------------------------------------------------------------------------------------
    def new_samples(self) -> list[np.ndarray]:
        """Records ``[t, wrench(6), saturated(6)]`` the world produced since the last call."""
        return self.reader.new()

    def sample_number(self, t: float) -> int:
        return sample_number(t, self.rate_hz)

    def check_continuity(self, n: int) -> None:
        """Record as undelivered the world samples skipped before sample ``n`` (the emulator fell a whole
        ring behind the world, or was unplugged): ``damaged`` lists every sample not delivered."""
        last = self._last_n
        if last is not None and n > last + 1:
            self.faults.counts["skipped"] += n - last - 1
            self.faults.damaged.extend(range(last + 1, n))
        self._last_n = n if last is None else max(n, last)

    def delivered(self, n: int, fault: str | None, written: bool) -> None:
        """Account a frame the faults did not destroy but the client's full buffer did."""
        if not written and fault not in ("drop", "corrupt", "truncate"):
            self.faults.counts["overflow"] += 1
            self.faults.damaged.append(n)

    @staticmethod
    def saturation_bits(rec: np.ndarray) -> int:
        flags = rec[7:13].tolist()
        if not any(flags):  # the common case: nothing saturated
            return 0
        return sum(1 << i for i, v in enumerate(flags) if v > 0.5)

    def count_sample(self) -> bool:
        """Account one sample to send; False once ``max_frames`` were sent (then nothing more is)."""
        if self.max_frames is not None and self.samples >= self.max_frames:
            self.done = True
            return False
        self.samples += 1
        return True

    def stats(self) -> dict[str, Any]:
        return {"name": self.device.name, "samples": self.samples, "done": self.done,
                "ring_lost": self.reader.lost, **self.faults.snapshot(), **self.extra_stats}


def serve_with(cls: type[Emulator], device: DeviceSpec, scene: Scene, link: LinkInfo, ready, options: dict) -> None:
    """The registry's ``serve`` for an emulator class: configuration errors go back on ``ready``."""
    try:
        emulator = cls(device, scene, link, options)
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which raises
        ready.put({"error": f"{type(exc).__name__}: {exc}"})
        return
    emulator.run(ready)
