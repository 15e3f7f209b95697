"""The link between the physics world's process and the protocol emulators' processes.

The world process owns a :class:`WorldLink`: shared-memory rings that it appends every F/T sample
(when the scene has an F/T sensor) and every joint sample to, and a command socket. Each emulator
process attaches to the rings by name (:class:`EmulatorSide`), reads what is new with a
:class:`RingReader` (never misses a sample unless it falls a whole ring behind, which it counts), and
sends commands (:class:`Command`) back: goal positions, stop, torque on/off.

Commands travel as JSON datagrams on a Unix socket in a private (0700) directory: any number of
senders, one message per datagram, sent from the emulator's own thread (no feeder thread, unlike a
``multiprocessing.Queue``), and a file descriptor the world can wait on, so that it applies a
command as soon as it arrives instead of at its next paced step (the stop reflex's latency).

Ring slots: ``[seq, t, payload...]``. The writer fills the payload, then writes ``seq`` last; a
reader copies the slot and accepts it only if ``seq`` is the one it expects before and after the
copy (a seqlock: no locks shared across processes).
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import multiprocessing as mp
import os
import select
import shutil
import socket
import tempfile
import time
from dataclasses import dataclass, field
from multiprocessing import resource_tracker, shared_memory
from typing import Any

import numpy as np

from .played import PlayedInfo, PlayedRing

RING_SLOTS = 4096  # about 4 s of 1 kHz samples


@dataclass(frozen=True)
class Command:
    """A device's request to the world. ``kind``: ``goal`` (q rad, the joints' order), ``stop``
    (hold where the arm is), ``torque`` (on: bool), ``resume`` (continue the trajectory a stop interrupted)."""

    source: str
    kind: str
    q: tuple[float, ...] | None = None
    on: bool | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    t_sent_ns: int = 0  # time.monotonic_ns() when the emulator sent it (set by EmulatorSide.send)

    def encode(self) -> bytes:
        return json.dumps({"source": self.source, "kind": self.kind, "q": self.q, "on": self.on, "extra": self.extra,
                           "t_sent_ns": self.t_sent_ns}).encode()

    @classmethod
    def decode(cls, data: bytes) -> Command:
        """Raises ValueError (or a subclass) for anything that is not an encoded Command."""
        d = json.loads(data)
        if not isinstance(d, dict) or not isinstance(d.get("source"), str) or not isinstance(d.get("kind"), str):
            raise ValueError("not a command")
        q = d.get("q")
        return cls(d["source"], d["kind"], None if q is None else tuple(float(x) for x in q), d.get("on"),
                   dict(d.get("extra") or {}), int(d.get("t_sent_ns", 0)))


class NoFTRingError(LookupError):
    """An F/T ring was asked of a world whose scene has no F/T sensor."""


class CommandLinkError(ConnectionError):
    """A command could not be handed to the world (its process is gone or not draining)."""


class Ring:
    """A single-writer, many-reader ring of fixed-width float64 records in shared memory."""

    def __init__(self, width: int, slots: int = RING_SLOTS, name: str | None = None, create: bool = True) -> None:
        self.width = width
        self.slots = slots
        nbytes = (slots * (width + 2) + 1) * 8
        if create:
            self.shm = shared_memory.SharedMemory(name=name, create=True, size=nbytes)
        else:
            # Python < 3.13 registers attached segments with the resource tracker, which would unlink
            # the world's rings when this process exits: only the creator owns them. Not registering
            # (rather than unregistering afterwards) matters when the tracker is shared with the world's
            # process (spawned children share it): an unregister would drop the world's own entry.
            register = resource_tracker.register
            resource_tracker.register = lambda *args, **kwargs: None
            try:
                self.shm = shared_memory.SharedMemory(name=name, create=False, size=nbytes)
            finally:
                resource_tracker.register = register
        self.owner = create
        buf = np.ndarray((slots * (width + 2) + 1,), dtype=np.float64, buffer=self.shm.buf)
        self._head = buf[:1]  # number of records written so far
        self._data = buf[1:].reshape(slots, width + 2)
        self._slots: list[np.ndarray] = []  # the writer's views of its slots (made once: ~0.3 us each)
        if create:
            self._head[0] = 0.0
            self._data[:, 0] = -1.0
            self._slots = list(self._data)
        self._count = 0  # the writer's count of records written (its own copy of the head)

    @property
    def name(self) -> str:
        return self.shm.name

    @property
    def written(self) -> int:
        return int(self._head[0])

    def append(self, t: float, payload: np.ndarray) -> None:
        self.append_parts(t, (payload,))

    def append_parts(self, t: float, parts: tuple[np.ndarray, ...]) -> None:
        """Append one record whose payload is ``parts`` one after the other (only the creator writes)."""
        k = self._count
        slot = self._slots[k % self.slots]
        slot[0] = -1.0  # invalid while being written
        slot[1] = t
        i = 2
        for part in parts:
            j = i + len(part)
            slot[i:j] = part
            i = j
        if i != len(slot):
            raise ValueError(f"record of {i - 2} values for a ring of width {self.width}")
        slot[0] = float(k)
        self._count = k + 1
        self._head[0] = float(k + 1)

    def read(self, k: int) -> np.ndarray | None:
        """Record k (t, payload...) or None when it was overwritten or is not written yet."""
        slot = self._data[k % self.slots]
        if slot[0] != k:
            return None
        copy = slot[1:].copy()
        return copy if slot[0] == k else None

    def close(self) -> None:
        self._head = self._data = None  # type: ignore[assignment]
        self.shm.close()
        if self.owner:
            self.shm.unlink()


class RingReader:
    """Reads a ring (or a stored run's :class:`PlayedRing`) in order from where it attaches; counts records
    lost by falling behind."""

    def __init__(self, ring: Ring | PlayedRing, from_start: bool = False) -> None:
        self.ring = ring
        self.next = 0 if from_start else ring.written
        self.lost = 0

    def new(self, limit: int = 1 << 30) -> list[np.ndarray]:
        out = []
        written = self.ring.written
        if written - self.next > self.ring.slots:  # fell a whole ring behind
            skip = written - self.ring.slots - self.next
            self.lost += skip
            self.next += skip
        while self.next < written and len(out) < limit:
            rec = self.ring.read(self.next)
            if rec is None:  # overwritten while we read: count it and move on
                self.lost += 1
            else:
                out.append(rec)
            self.next += 1
        return out

    def latest(self) -> np.ndarray | None:
        written = self.ring.written
        return None if written == 0 else self.ring.read(written - 1)


@dataclass(frozen=True)
class LinkInfo:
    """What an emulator process needs to attach: ring names and widths, the command socket's path."""

    ft_ring: str | None  # None: the scene has no F/T sensor (no F/T ring)
    joint_ring: str
    n_joints: int
    commands: str  # the world's command socket (AF_UNIX, SOCK_DGRAM)
    played: PlayedInfo | None = None  # a run computed ahead: its stored streams replace the rings (played.py)


FT_WIDTH = 12  # wrench (6, sensor frame, scene convention, as the device reports it), saturated (6, 0/1)


@dataclass(frozen=True, slots=True)
class JointRecord:
    """One sample of the world's joint ring, by name. The one place that says its layout: a record
    (what a :class:`RingReader` returns) is ``[t, q (n), qd (n), qdd (n), current (n), tau (n),
    tau_j (n)]`` -- the world's time (s), then for each of the ``n`` joints, in the scene's order, its
    angle (rad), velocity (rad/s), acceleration (rad/s^2), motor current (A, as the motor's sensor reads
    it), motor torque (N m) and the joint torque sensor's reading (N m: the torque the joint transmits
    on the link side of its gear, i.e. the motor torque less the joint's friction, with the sensor's
    offset and noise; zeros where the scene has no joint torque sensors). The world writes it
    (:meth:`WorldLink.publish_joints`); ``from_row`` reads it, its arrays views of the row."""

    t: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    current: np.ndarray
    tau: np.ndarray
    tau_j: np.ndarray

    FIELDS = 6  # arrays of n per record

    @staticmethod
    def width(n: int) -> int:
        """The ring's payload width for ``n`` joints (the record without its time)."""
        return JointRecord.FIELDS * n

    @classmethod
    def from_row(cls, row: np.ndarray, n: int) -> JointRecord:
        return cls(float(row[0]), *(row[1 + k * n:1 + (k + 1) * n] for k in range(JointRecord.FIELDS)))


MAX_COMMAND_BYTES = 65536
SEND_TIMEOUT_S = 1.0  # a world that drains nothing for this long is hung


class WorldLink:
    """Created in the world's process. ``info`` goes to each emulator process (picklable)."""

    def __init__(self, n_joints: int, ctx: mp.context.BaseContext | None = None, *, ft: bool = True) -> None:
        """``ft``: the scene has an F/T sensor (else no F/T ring: :attr:`ft` is None)."""
        # ctx: accepted for compatibility; nothing here needs a multiprocessing context any more
        self.n_joints = n_joints
        self.ft = Ring(FT_WIDTH) if ft else None
        self.joints = Ring(JointRecord.width(n_joints))
        self._dir = tempfile.mkdtemp(prefix="ftc-link-")  # 0700: only this user's processes can send
        self.command_path = os.path.join(self._dir, "commands")
        self._commands = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self._commands.bind(self.command_path)
        self._commands.setblocking(False)
        self._ready = select.poll()
        self._ready.register(self._commands, select.POLLIN)
        self.bad_commands = 0  # datagrams that were no Command (counted, dropped)
        self.info = LinkInfo(None if self.ft is None else self.ft.name, self.joints.name, n_joints,
                             self.command_path)

    def publish_ft(self, t: float, wrench: np.ndarray, saturated: np.ndarray) -> None:
        self.ft.append_parts(t, (wrench, saturated))  # bools stored as 0.0 / 1.0

    def publish_joints(self, t: float, q, qd, qdd, current, tau, tau_j) -> None:
        """Append one :class:`JointRecord` (its fields in its order)."""
        self.joints.append_parts(t, (q, qd, qdd, current, tau, tau_j))

    def drain_commands(self, limit: int = 100) -> list[Command]:
        if not self._ready.poll(0):  # the common case, every step: a poll is cheaper than a failed recv
            return []
        out = []
        for _ in range(limit):
            try:
                data = self._commands.recv(MAX_COMMAND_BYTES)
            except BlockingIOError:
                break
            try:
                out.append(Command.decode(data))
            except (ValueError, TypeError):
                self.bad_commands += 1
        return out

    def fileno(self) -> int:
        """The command socket's descriptor (readable when a command waits)."""
        return self._commands.fileno()

    def wait_commands(self, timeout: float) -> bool:
        """Block up to ``timeout`` s; True as soon as a command is waiting."""
        ready, _, _ = select.select([self._commands], [], [], max(0.0, timeout))
        return bool(ready)

    def close(self) -> None:
        if self.ft is not None:
            self.ft.close()
        self.joints.close()
        self._commands.close()
        shutil.rmtree(self._dir, ignore_errors=True)


class EmulatorSide:
    """Created in an emulator process from ``LinkInfo``: readers of the rings and a command sender."""

    def __init__(self, info: LinkInfo) -> None:
        self.info = info
        self.ft: Ring | PlayedRing | None
        self.joints: Ring | PlayedRing
        if info.played is not None:  # the run computed ahead, played on the wall clock
            self.ft = None if info.played.ft is None else PlayedRing(info.played, ft=True)
            self.joints = PlayedRing(info.played, ft=False)
        else:
            self.ft = None if info.ft_ring is None else Ring(FT_WIDTH, name=info.ft_ring, create=False)
            self.joints = Ring(JointRecord.width(info.n_joints), name=info.joint_ring, create=False)
        self._commands = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self._commands.settimeout(SEND_TIMEOUT_S)

    def ft_reader(self) -> RingReader:
        """The F/T ring's reader; a :class:`NoFTRingError` when the world has no F/T sensor."""
        if self.ft is None:
            raise NoFTRingError("the world has no F/T sensor (its scene has no [sensor]): no F/T ring to read")
        return RingReader(self.ft)

    def joint_reader(self) -> RingReader:
        return RingReader(self.joints)

    def joint_state(self) -> JointRecord | None:
        """The newest joint sample (None before the first)."""
        rec = RingReader(self.joints).latest()
        return None if rec is None else JointRecord.from_row(rec, self.info.n_joints)

    def send(self, command: Command) -> None:
        """Hand ``command`` to the world; raises CommandLinkError when the world cannot take it."""
        data = dataclasses.replace(command, t_sent_ns=time.monotonic_ns()).encode()  # ~10 us
        try:
            self._commands.sendto(data, self.info.commands)
        except OSError as exc:
            raise CommandLinkError(f"world command socket {self.info.commands}: {exc}") from exc

    def close(self) -> None:
        if self.ft is not None:
            self.ft.close()
        self.joints.close()
        with contextlib.suppress(OSError):
            self._commands.close()
