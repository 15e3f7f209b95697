"""The bus across processes and machines, on Eclipse Zenoh.

Each bus topic of a rig is a Zenoh key expression, ``ftc/<rig>/<topic>``: ``ftc/cell1/wrench/ft``,
``ftc/cell1/joints/arm``, ``ftc/cell1/events/contact``, ``ftc/cell1/events/device``; the payload is one
frame in the binary format of :mod:`ftc_hw.bus.wire`.

- :class:`RemotePublisher` forwards a local :class:`~ftc_hw.bus.Bus`'s topics to Zenoh (a device's
  process publishes its reader's frames; the monitor publishes its contact events back).
- :class:`RemoteSubscriber` publishes what arrives into a local bus: the frames keep their
  timestamps, sequence numbers and sources, so ``latest``, ``window``, ``sample_at``, ``stats`` and a
  :class:`~ftc_hw.bus.Watchdog` work on remote topics as on local ones. A payload on our key
  expressions that is not a frame of ours (another program's, a corrupt one, another major version
  of the format) is counted and dropped, never raised into Zenoh's thread.

Where a session listens: :func:`session_config` gives a peer that listens only on the endpoints it
is given (none: it only connects) with multicast scouting off unless asked; callers keep listening
endpoints on loopback unless the user names others (``ftc serve --listen``). Zenoh's own TLS and
access control are set in a Zenoh configuration file (``config_file``): docs/bus.md.
"""
from __future__ import annotations

import contextlib
import json
import socket
import threading
import time
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from itertools import groupby
from operator import itemgetter
from pathlib import Path
from typing import Any

import zenoh

from .bus import Bus, frame_topic
from .wire import WireError, WireForeignError, WireVersionError, decode_all, encode, encode_batch

KEY_ROOT = "ftc"
DEFAULT_PREFIXES = ("wrench/", "joints/", "events/")
_from_remote = threading.local()  # set while a RemoteSubscriber publishes into a bus (same thread)


class RemoteError(RuntimeError):
    """A Zenoh session could not be opened or a key expression is not ours."""


def key_expr(rig: str, topic: str) -> str:
    """The Zenoh key expression of a rig's bus topic."""
    if not rig or "/" in rig or any(c in rig for c in "*$?#"):
        raise RemoteError(f"rig name {rig!r}: one non-empty key chunk without / * $ ? #")
    return f"{KEY_ROOT}/{rig}/{topic}"


def stop_key(rig: str, arm: str) -> str:
    """Where a remote monitor commands an arm's reader to stop: the onset ContactEvent is the payload."""
    return key_expr(rig, f"command/{arm}/stop")


def topic_of(key: str) -> tuple[str, str] | None:
    """``(rig, topic)`` of one of our key expressions, or None for another key."""
    parts = key.split("/", 2)
    if len(parts) != 3 or parts[0] != KEY_ROOT or not parts[2]:
        return None
    return parts[1], parts[2]


def topic_for(frame: Any) -> str:
    """The bus topic a frame belongs on; TypeError for anything that is not a bus frame."""
    topic = frame_topic(frame)
    if topic is None:
        raise TypeError(f"not a bus frame: {type(frame).__name__}")
    return topic


def session_config(listen: Sequence[str] = (), connect: Sequence[str] = (), *, mode: str = "peer",
                   multicast: bool = False, config_file: Path | None = None) -> zenoh.Config:
    """A session's configuration: ``mode`` peer, client (everything through the router it connects
    to) or router (``ftc serve``); it listens on ``listen`` only (none: it only connects), connects
    to ``connect``, scouts by multicast only if asked; ``config_file`` (Zenoh's JSON5: TLS, access
    control) is the base the rest is set on."""
    if mode not in ("peer", "client", "router"):
        raise RemoteError(f"Zenoh mode {mode!r}: peer, client or router")
    try:
        cfg = zenoh.Config.from_file(str(config_file)) if config_file is not None else zenoh.Config()
        cfg.insert_json5("mode", json.dumps(mode))
        cfg.insert_json5("scouting/multicast/enabled", json.dumps(bool(multicast)))
        cfg.insert_json5("listen/endpoints", json.dumps(list(listen)))
        cfg.insert_json5("connect/endpoints", json.dumps(list(connect)))
    except (zenoh.ZError, OSError, ValueError) as exc:
        raise RemoteError(f"Zenoh configuration: {exc}") from None
    return cfg


def open_session(listen: Sequence[str] = (), connect: Sequence[str] = (), *, mode: str = "peer",
                 multicast: bool = False, config_file: Path | None = None) -> zenoh.Session:
    """A Zenoh session (see :func:`session_config`); :class:`RemoteError` if it cannot be opened
    (an endpoint in use or unreachable to listen on, a bad configuration file)."""
    cfg = session_config(listen, connect, mode=mode, multicast=multicast, config_file=config_file)
    try:
        return zenoh.open(cfg)
    except zenoh.ZError as exc:
        raise RemoteError(f"cannot open a Zenoh session (listen {list(listen)}, connect {list(connect)}): "
                          f"{exc}") from None


def free_loopback_endpoint() -> str:
    """A TCP endpoint on 127.0.0.1 at a port free now (a private router: a monitor's own readers, a bench)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


def connect_session(endpoint: str, timeout: float, *, config_file: Path | None = None) -> zenoh.Session:
    """A client session to the router at ``endpoint``, tried again every 0.5 s for ``timeout`` seconds
    (the server may be starting); then :class:`RemoteError`."""
    end = time.monotonic() + timeout
    while True:
        try:
            return open_session(connect=[endpoint], mode="client", config_file=config_file)
        except RemoteError:
            if time.monotonic() >= end:
                raise
            time.sleep(0.5)


class RemotePublisher:
    """Forwards a local bus's topics under ``prefixes`` to Zenoh as ``ftc/<rig>/<topic>``.

    Frames go out reliably, blocking when a link is congested (Zenoh's ``BLOCK``: a slow network
    delays them, never loses them silently). The publishing thread (a device's reader) puts a frame on
    Zenoh itself when nothing is waiting: no other thread has to wake up for it. While a put is under
    way, or frames wait, it hands the frame to a sender thread, which sends what piled up together,
    one batch message per topic (``wire.encode_batch``). A put that blocks for more than
    ``SLOW_PUT_S`` (the link is congested) sends everything through the sender thread for the next
    ``CONGESTED_HOLD_S``: a slow network delays that thread, and the reader for at most that one put.
    ``sent`` counts the frames put.
    """

    SLOW_PUT_S = 0.002
    CONGESTED_HOLD_S = 1.0

    def __init__(self, session: zenoh.Session, bus: Bus, rig: str,
                 prefixes: Iterable[str] = DEFAULT_PREFIXES, max_batch: int = 256) -> None:
        key_expr(rig, "x")  # validates the rig name
        self.session, self.bus, self.rig, self.max_batch = session, bus, rig, max_batch
        self.sent = 0
        self._pubs: dict[str, Any] = {}
        self._queue: deque[tuple[str, bytes]] = deque()
        self._wake = threading.Condition()
        self._closed = False
        self._busy = False  # a put is under way (in the publishing thread or the sender)
        self._dead = False  # the session closed under us: nothing more can be sent
        self._handover_until = 0.0  # monotonic s: until then every frame goes through the sender
        self._thread = threading.Thread(target=self._send_loop, name=f"ftc-zenoh-pub-{rig}", daemon=True)
        self._thread.start()
        self._subs = [bus.subscribe(p, self._forward) for p in prefixes]

    def _forward(self, frame: Any) -> None:
        if getattr(_from_remote, "active", False):
            return  # it came from Zenoh: whoever sent it published it there
        item = (topic_for(frame), encode(frame))
        with self._wake:
            if self._closed or self._dead:
                return
            if self._busy or self._queue or time.monotonic() < self._handover_until:
                self._queue.append(item)
                if len(self._queue) == 1:
                    self._wake.notify()
                return
            self._busy = True
        t0 = time.monotonic()
        try:
            self._put(item[0], [item[1]])
        finally:
            done = time.monotonic()
            with self._wake:
                self._busy = False
                if done - t0 > self.SLOW_PUT_S:
                    self._handover_until = done + self.CONGESTED_HOLD_S
                if self._queue:
                    self._wake.notify()

    def _send_loop(self) -> None:
        while True:
            with self._wake:
                while (self._busy or not self._queue) and not self._closed:
                    self._wake.wait()
                while self._busy:  # closing: the publishing thread's last put first
                    self._wake.wait(0.01)
                if not self._queue or self._dead:
                    return  # closed and flushed
                items = [self._queue.popleft() for _ in range(min(len(self._queue), self.max_batch))]
                self._busy = True
            try:
                for topic, group in _runs(items):
                    self._put(topic, group)
            finally:
                with self._wake:
                    self._busy = False

    def _put(self, topic: str, group: list[bytes]) -> None:
        if self._dead:
            return
        try:
            self._publisher(topic).put(group[0] if len(group) == 1 else encode_batch(group))
        except zenoh.ZError:
            self._dead = True  # the session closed under us
            return
        self.sent += len(group)

    def _publisher(self, topic: str) -> Any:
        pub = self._pubs.get(topic)
        if pub is None:
            pub = self._pubs[topic] = self.session.declare_publisher(
                key_expr(self.rig, topic), congestion_control=zenoh.CongestionControl.BLOCK,
                reliability=zenoh.Reliability.RELIABLE)
        return pub

    def close(self, timeout: float = 2.0) -> None:
        """Stop forwarding; what was handed over is sent first (idempotent)."""
        for s in self._subs:
            s.close()
        with self._wake:
            self._closed = True
            self._wake.notify()
        self._thread.join(timeout)
        for p in list(self._pubs.values()):
            with contextlib.suppress(zenoh.ZError):  # the session closed first: nothing to undeclare
                p.undeclare()
        self._pubs = {}

    def __enter__(self) -> RemotePublisher:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _runs(items: list[tuple[str, bytes]]) -> list[tuple[str, list[bytes]]]:
    """Consecutive messages of one topic grouped, in order."""
    return [(topic, [data for _, data in run]) for topic, run in groupby(items, key=itemgetter(0))]


@dataclass
class RemoteCounts:
    """What a :class:`RemoteSubscriber` took and dropped."""

    received: int = 0
    foreign: int = 0  # on our key expressions, not a frame of ours (or on the wrong topic)
    corrupt: int = 0  # magic right, body wrong (truncated, bad value)
    version: int = 0  # another major version of the format
    by_topic: dict[str, int] = field(default_factory=dict)

    def summary(self) -> dict[str, int]:
        """What a run's summary says: taken, and dropped by why."""
        return {"received": self.received, "foreign": self.foreign, "corrupt": self.corrupt, "version": self.version}


class RemoteSubscriber:
    """Publishes the frames of ``ftc/<rig>/**`` (``rig="*"``: every rig's) into a local bus."""

    def __init__(self, session: zenoh.Session, bus: Bus, rig: str = "*") -> None:
        self.bus, self.rig = bus, rig
        self.counts = RemoteCounts()
        self._lock = threading.Lock()
        key = f"{KEY_ROOT}/{rig}/**" if rig == "*" else key_expr(rig, "**")
        # other sessions' frames only: this process's own are on its bus already
        self._sub = session.declare_subscriber(key, self._on_sample, allowed_origin=zenoh.Locality.REMOTE)

    def _on_sample(self, sample: Any) -> None:
        where = topic_of(str(sample.key_expr))
        if where is not None and where[1].startswith("command/"):
            return  # a command to a reader (stop_key), not a bus topic
        try:
            frames = decode_all(sample.payload.to_bytes())
            ok = where is not None and all(topic_for(f) == where[1] for f in frames)
        except WireVersionError:
            self._count("version")
            return
        except WireForeignError:
            self._count("foreign")
            return
        except WireError:
            self._count("corrupt")
            return
        if not ok:
            self._count("foreign")
            return
        with self._lock:
            self.counts.received += len(frames)
            self.counts.by_topic[where[1]] = self.counts.by_topic.get(where[1], 0) + len(frames)
        _from_remote.active = True  # a RemotePublisher on this bus does not send it back out
        try:
            for frame in frames:
                self.bus.publish(where[1], frame)
        finally:
            _from_remote.active = False

    def _count(self, what: str) -> None:
        with self._lock:
            setattr(self.counts, what, getattr(self.counts, what) + 1)

    def close(self) -> None:
        """Stop taking frames (idempotent)."""
        with contextlib.suppress(zenoh.ZError):  # already undeclared, or the session closed
            self._sub.undeclare()

    def __enter__(self) -> RemoteSubscriber:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
