"""Universal Robots arm adapter: ur_rtde's receive interface for joint state, the dashboard for stop/pause.

Publishes a ``JointFrame`` on ``joints/<name>`` for every RTDE packet (500 Hz e-Series, 125 Hz CB3:
the device's ``frequency``): ``t_device_ns`` is the controller's ``timestamp``, ``seq`` counts
controller periods (``round(timestamp * frequency)``, so a packet the poller missed is a sequence
gap, flagged ``SEQ_GAP``), ``tau = torque_constant * current`` when torque constants are known
(device ``torque_constant`` or the scene's ``[robot] torque_constant``), else None.

The e-Series' built-in flange F/T sensor (``ft``; default: on when the scene's pipeline uses a flange
sensor, ``[sensor] mount = "flange"``, and the scene declares no F/T device of its own): the same RTDE
recipe also asks ``ft_raw_wrench`` (UR: the raw wrench of the sensor in the tool flange frame, not
compensated for the payload; sim_devices/SOURCES.md, "UR F/T"), and every packet publishes a
``WrenchFrame`` on ``wrench/<name>`` too: the sensor frame (the scene's sensor site, which must be the
flange frame), SI, the same ``t_device_ns``, ``seq`` and gap / clock flags as the packet's JointFrame,
``SATURATED`` when an axis reaches the sensor's range (``ft_range``, else the scene's ``[sensor]
range``), as for the F/T adapters without status bits. The device then fills the rig's F/T role as well
as its arm role (``roles``). A wrench that is not finite is counted (``ft_bad``) and not published.
``actual_TCP_force`` (the controller's wrench at the TCP, base axes) is not read: nothing consumes it.

ur_rtde keeps serving the last values when the controller goes away and only ``isConnected()``
says so; this adapter polls the timestamp and checks ``isConnected()`` itself: no new packet for
``stale_after`` s (default max(50 ms, 10 periods)) publishes ``stale``, the next one ``recovered``;
a closed connection, or ``dead_after`` s without data (a hung controller), is a broken link,
reopened with backoff by the base class.

Measured with ur_rtde 1.6.5 (see tests): ``reconnect()`` and the dashboard client's ``connect()``
block forever against a controller that accepts TCP but never answers, and ``disconnect()`` then
takes ~3 s; the constructor holds the GIL during its handshake. So before any ur_rtde call that
connects, a plain socket with a timeout checks that the controller answers the RTDE version request;
a hung interface is retired to a background thread (its ``disconnect()`` runs there) and replaced by
a new one; and the dashboard, the stop path, is a plain socket with timeouts, not ur_rtde's client.

``prepare_servo()``, ``servo(q)``, ``end_servo()``: a stream of joint setpoints (the retreat reflex) written
with ur_rtde's ``RTDEIOInterface`` to the input registers of the control-loop program
(``ftc_hw.codecs.ur_control_loop``; docs/arms.md, "Streamed setpoints"), Nagle's algorithm turned off on
its socket (``no_delay_to``).

``stop()``, the monitor's reflex: dashboard ``stop`` (the program stops, the arm brakes to a halt
on its path); ``pause()``: dashboard ``pause``. A reply "Failed to execute: stop" is accepted when
the program is already stopped. Replies are read as UR documents them for the e-Series dashboard
server (``sim_devices/SOURCES.md``, "UR dashboard"): ``programState`` as ``<STOPPED|PLAYING|PAUSED>
<program>``; anything else (``could not understand: ...``, a reply of another command) raises
``DashboardReplyError``.
"""
from __future__ import annotations

import contextlib
import os
import socket
import struct
import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import rtde_io
import rtde_receive

from ftc_hw.bus import Bus, JointFlag, JointFrame, WrenchFlag, WrenchFrame, joints_topic, wrench_topic
from ftc_hw.codecs.ur_control_loop import CONTROL_LOOP
from ftc_hw.scene import DeviceSpec, Scene

from .arm_base import ArmAdapter
from .base import DeviceError, DeviceIOError
from .ft_base import at_range

RTDE_PORT = 30004
VARIABLES = ["timestamp", "actual_q", "actual_qd", "actual_current", "robot_mode", "safety_mode", "runtime_state"]
FT_VARIABLES = ["ft_raw_wrench"]  # e-Series, from PolyScope 5.9 (UR's RTDE guide)
DASHBOARD_WELCOME = "Connected: Universal Robots Dashboard Server"
PROGRAM_STATES = ("STOPPED", "PLAYING", "PAUSED")


class DashboardReplyError(DeviceError):
    """The dashboard server answered, but not with a documented reply to the command sent."""

    def __init__(self, command: str, reply: str) -> None:
        super().__init__(f"dashboard {command!r}: unexpected reply {reply!r}")
        self.command, self.reply = command, reply


def parse_program_state(reply: str) -> tuple[str, str]:
    """``programState``'s reply, ``<STOPPED|PLAYING|PAUSED> <program>``, as (state, program)."""
    state, _, program = reply.partition(" ")
    if state not in PROGRAM_STATES or not program:
        raise DashboardReplyError("programState", reply)
    return state, program


def probe_rtde(host: str, timeout: float = 0.3, port: int = RTDE_PORT) -> None:
    """Raise DeviceIOError unless the controller at ``host`` answers an RTDE v2 version request in time."""
    try:
        with socket.create_connection((host, port), timeout=timeout) as s:
            s.settimeout(timeout)
            s.sendall(struct.pack(">HBH", 5, ord("V"), 2))
            reply = b""
            while len(reply) < 4:
                chunk = s.recv(4 - len(reply))
                if not chunk:
                    raise DeviceIOError(f"{host}:{port} closed the connection")
                reply += chunk
    except OSError as exc:
        raise DeviceIOError(f"RTDE at {host}:{port} does not answer: {exc}") from exc
    size, cmd, accepted = struct.unpack(">HBB", reply)
    if cmd != ord("V") or not accepted:
        raise DeviceIOError(f"RTDE at {host}:{port} refused protocol version 2")


class DashboardLink:
    """A dashboard server connection (port 29999) with timeouts; one command at a time."""

    def __init__(self, host: str, port: int = 29999, timeout: float = 0.5) -> None:
        self.host, self.port, self.timeout = host, port, timeout
        self._sock: socket.socket | None = None
        self._buf = b""
        self._lock = threading.Lock()

    def _open(self) -> None:
        self.close()
        self._sock = socket.create_connection((self.host, self.port), timeout=self.timeout)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._buf = b""
        welcome = self._line()
        if welcome != DASHBOARD_WELCOME:
            raise DeviceIOError(f"{self.host}:{self.port} is no dashboard server ({welcome!r})")

    def _line(self) -> str:
        assert self._sock is not None
        while b"\n" not in self._buf:
            chunk = self._sock.recv(1024)
            if not chunk:
                raise ConnectionError("dashboard server closed the connection")
            self._buf += chunk
        line, self._buf = self._buf.split(b"\n", 1)
        return line.decode(errors="replace").strip()

    def command(self, text: str) -> str:
        """Send one command, return its reply line; reconnects once if the connection broke."""
        with self._lock:
            for attempt in (0, 1):
                try:
                    if self._sock is None:
                        self._open()
                    assert self._sock is not None
                    self._sock.sendall(text.encode() + b"\n")
                    return self._line()
                except (OSError, ConnectionError) as exc:
                    self.close()
                    if attempt:
                        raise DeviceIOError(f"dashboard {self.host}:{self.port}: {exc}") from exc
            raise AssertionError("unreachable")

    def close(self) -> None:
        if self._sock is not None:
            with contextlib.suppress(OSError):
                self._sock.close()
            self._sock = None


def no_delay_to(host: str, port: int = RTDE_PORT) -> int:
    """Turn Nagle's algorithm off on this process's TCP connections to ``host:port``; how many it changed.

    ur_rtde's IO interface leaves it on (measured, ur_rtde 1.6.5 against the emulator: a setpoint after a
    pause waited 42 ms, a controller's delayed ACK, for the packet before it), so a stream of small input
    packages would go out in bursts. The interface does not expose its socket: it is found among the
    process's open descriptors by its peer (Linux's /proc; elsewhere nothing is changed)."""
    changed = 0
    fd_dir = "/proc/self/fd"
    if not os.path.isdir(fd_dir):
        return 0
    try:
        peers = {(host, port)} | {(a[4][0], port) for a in socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)}
    except OSError:
        peers = {(host, port)}
    for name in os.listdir(fd_dir):
        try:
            with socket.socket(fileno=os.dup(int(name))) as s:
                if s.type != socket.SOCK_STREAM or s.family not in (socket.AF_INET, socket.AF_INET6):
                    continue
                if s.getpeername()[:2] not in peers or s.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY):
                    continue
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                changed += 1
        except OSError:  # not a socket, not connected, or gone meanwhile
            continue
    return changed


def _retire(rtde: Any) -> None:
    """Disconnect an interface in the background (ur_rtde's disconnect sleeps 0.5-3 s)."""
    def run() -> None:
        with contextlib.suppress(Exception):  # it is being thrown away
            rtde.disconnect()

    threading.Thread(target=run, name="ur-rtde-retire", daemon=True).start()


def reads_flange_ft(device: DeviceSpec, scene: Scene | None, other_ft_device: bool) -> bool:
    """Whether a ``ur-rtde`` device reads its flange F/T sensor: its ``ft`` param, else whether the scene's
    pipeline uses a flange sensor and no other device of the scene (``other_ft_device``) reads it."""
    if "ft" in device.params:
        return bool(device.params["ft"])
    return scene is not None and scene.sensing.ft == "flange" and not other_ft_device


class URArm(ArmAdapter):
    kind = "ur-rtde"

    def __init__(self, name: str, bus: Bus, host: str, *, frequency: float = 500.0,
                 torque_constant: Sequence[float] | None = None, stale_after: float | None = None,
                 dead_after: float = 0.5, dashboard_port: int = 29999, probe_timeout: float = 0.3,
                 reconnect_backoff: tuple[float, float] = (0.05, 0.5), ft: bool = False,
                 ft_range: Sequence[float] | None = None) -> None:
        super().__init__(name, bus, reconnect_backoff=reconnect_backoff)
        self.host = host
        self.ft = bool(ft)
        self.ft_topic = wrench_topic(name) if self.ft else None
        self.ft_range = None if ft_range is None else np.asarray(ft_range, dtype=float)
        self.variables = VARIABLES + (FT_VARIABLES if self.ft else [])
        self.rate = float(frequency)
        self.period = 1.0 / self.rate
        self.torque_constant = None if torque_constant is None else np.asarray(torque_constant, dtype=float)
        self.stale_after = stale_after if stale_after is not None else max(0.05, 10.0 * self.period)
        self.dead_after = dead_after
        self.probe_timeout = probe_timeout
        self.topic = joints_topic(name)
        self.dashboard = DashboardLink(host, dashboard_port)
        self.robot_mode: int | None = None
        self.safety_mode: int | None = None
        self.runtime_state: int | None = None
        self._rtde: Any = None
        self._io: Any = None  # ur_rtde's IO interface, which writes the streamed setpoints' registers
        self._flag = 0  # the last setpoint's flag (1, 2, ...: never 0, which ends the stream)
        self._last_ts: float | None = None
        self._last_seq: int | None = None
        self._last_new = 0.0

    @classmethod
    def from_spec(cls, spec: Any, bus: Bus, endpoint: dict | str | None = None, *, scene: Any = None,
                  **overrides: Any) -> URArm:
        """From a scene's ``[[devices]]`` entry; ``endpoint``: ``ftc sim``'s endpoint dict or an address."""
        p = dict(spec.params)
        host = endpoint.get("address", endpoint.get("endpoint")) if isinstance(endpoint, dict) else endpoint
        host = host or spec.address
        if not host:
            raise DeviceError(f"device {spec.name!r}: no controller address")
        kwargs: dict[str, Any] = {k: p[k] for k in ("frequency", "torque_constant", "stale_after", "dead_after",
                                                    "dashboard_port", "ft", "ft_range") if k in p}
        if "torque_constant" not in kwargs and scene is not None:
            kwargs["torque_constant"] = list(scene.robot.torque_constant)
        if "ft_range" not in kwargs and scene is not None and scene.sensor is not None \
                and scene.sensor.mount == "flange":  # a base sensor's range is not the flange sensor's
            kwargs["ft_range"] = list(scene.sensor.range)
        if isinstance(endpoint, dict) and "dashboard_port" in endpoint:
            kwargs.setdefault("dashboard_port", endpoint["dashboard_port"])
        kwargs.update(overrides)
        return cls(spec.name, bus, host, **kwargs)

    def describe(self) -> str:
        return f"{self.kind} {self.host} at {self.rate:g} Hz" + (" with its flange F/T sensor" if self.ft else "")

    @property
    def roles(self) -> frozenset[str]:
        return frozenset({"arm", "ft"}) if self.ft else frozenset({"arm"})

    @property
    def topics(self) -> tuple[str, ...]:
        return (self.topic,) if self.ft_topic is None else (self.topic, self.ft_topic)

    # -- link -------------------------------------------------------------------------------------------
    def _connect(self) -> None:
        probe_rtde(self.host, self.probe_timeout)
        rtde = self._rtde
        try:
            if rtde is not None and not rtde.isConnected():
                rtde.reconnect()
            else:
                if rtde is not None:  # connected but silent: a hung controller
                    _retire(rtde)
                self._rtde = rtde = None
                rtde = rtde_receive.RTDEReceiveInterface(self.host, self.rate, self.variables)
                self._rtde = rtde
        except RuntimeError as exc:
            raise DeviceIOError(f"ur_rtde: {exc}") from exc
        if not rtde.isConnected():
            raise DeviceIOError("ur_rtde connected but reports no connection")
        self._last_new = time.monotonic()
        try:  # open the stop path now, not when the monitor needs it
            self.dashboard.command("robotmode")
        except DeviceIOError as exc:
            self.counters["dashboard_failures"] += 1
            self.event("error", f"dashboard unavailable: {exc} (stop() will retry)")

    def _disconnect(self) -> None:
        self.dashboard.close()  # ur_rtde's interface is kept for reconnect() (or retired if hung)

    def close(self) -> None:
        super().close()
        if self._io is not None:
            io, self._io = self._io, None
            _retire(io)
        if self._rtde is not None:
            rtde, self._rtde = self._rtde, None
            if rtde.isConnected() and self._stale:
                _retire(rtde)  # hung: its disconnect takes seconds
            # else dropped here: ur_rtde's destructor disconnects (sleeping 0.5 s inside); disconnect() before
            # it would sleep that 0.5 s twice

    # -- the reader loop ----------------------------------------------------------------------------------
    def _read_once(self) -> None:
        self._stale_on_failure(self._poll)

    def _poll(self) -> None:
        rtde = self._rtde
        deadline = time.monotonic() + self.poll_timeout
        while not self._stop.is_set():
            ts = rtde.getTimestamp()
            if ts != self._last_ts:
                self._publish(rtde, ts)
                return
            now = time.monotonic()
            if not rtde.isConnected():
                raise DeviceIOError("RTDE connection closed")
            silent = now - self._last_new
            if silent > self.stale_after:
                self._mark_stale(f"no RTDE packet for {silent:.3f} s")
            if silent > self.dead_after:
                raise DeviceIOError(f"no RTDE packet for {silent:.3f} s: controller hung")
            if now > deadline:
                return
            # after a packet, one sleep to 0.7 of a period (not two of half a period: a wake-up each, and
            # in a monitor's process each takes the interpreter from the pipeline), then poll finely
            near = 0.7 * self.period
            time.sleep(0.0002 if silent > near else near - silent)

    def _publish(self, rtde: Any, ts: float) -> None:
        for _ in range(3):  # the getters are separate calls: make sure they saw the same packet
            q, qd, cur = rtde.getActualQ(), rtde.getActualQd(), rtde.getActualCurrent()
            wrench = rtde.getFtRawWrench() if self.ft else None
            ts2 = rtde.getTimestamp()
            if ts2 == ts:
                break
            ts = ts2
        t_host = time.monotonic_ns()
        self.robot_mode, self.safety_mode = rtde.getRobotMode(), rtde.getSafetyMode()
        self.runtime_state = rtde.getRuntimeState()
        seq = round(ts * self.rate)
        flags = JointFlag.NONE
        if self._last_seq is not None:
            if seq - self._last_seq > 1:
                flags |= JointFlag.SEQ_GAP
                self.counters["missed_packets"] += seq - self._last_seq - 1
            elif seq <= self._last_seq:  # controller clock went back (restart)
                flags |= JointFlag.CLOCK_SUSPECT
                seq = self._last_seq + 1
        cur = np.asarray(cur, dtype=float)
        tau = None if self.torque_constant is None else self.torque_constant * cur
        frame = JointFrame.make(t_host, q, qd, cur, tau, source=self.name, seq=seq, t_device_ns=round(ts * 1e9),
                                flags=flags)
        self._last_ts, self._last_seq, self._last_new = ts, seq, time.monotonic()
        self.counters["frames"] += 1
        self.bus.publish(self.topic, frame)
        if wrench is not None:
            self._publish_wrench(frame, wrench)
        self._mark_fresh("RTDE packets again")

    def _publish_wrench(self, joints: JointFrame, wrench: Sequence[float]) -> None:
        """The flange sensor's reading of the packet ``joints`` came in, as a WrenchFrame of its times."""
        w = np.asarray(wrench, dtype=float)
        if w.shape != (6,) or not np.all(np.isfinite(w)):
            self.counters["ft_bad"] += 1
            return
        flags = WrenchFlag(int(joints.flags) & int(WrenchFlag.SEQ_GAP | WrenchFlag.CLOCK_SUSPECT))
        if self.ft_range is not None and at_range(w, self.ft_range):
            flags |= WrenchFlag.SATURATED
            self.counters["saturated"] += 1
        self.bus.publish(self.ft_topic, WrenchFrame.make(joints.t_host_ns, w, source=self.name, seq=joints.seq,
                                                         t_device_ns=joints.t_device_ns, flags=flags))
        self.counters["ft_frames"] += 1

    # -- commands ----------------------------------------------------------------------------------------
    def _dashboard(self, command: str, ok: str, already: str) -> None:
        """Send ``command``; its documented success reply is ``ok``, and ``Failed to execute: <command>``
        is accepted when the program is ``already`` in that state (or stopped)."""
        reply = self.dashboard.command(command)
        if reply == ok:
            return
        if reply == f"Failed to execute: {command}":
            state, _ = parse_program_state(self.dashboard.command("programState"))
            if state in (already, "STOPPED"):
                return
        raise DashboardReplyError(command, reply)

    # -- streamed joint setpoints: the control-loop program's registers (ftc_hw.codecs.ur_control_loop) --------
    @property
    def servo_period_s(self) -> float:  # type: ignore[override]
        return self.period  # one setpoint per controller cycle

    def prepare_servo(self) -> None:
        """Open ur_rtde's IO interface, which writes the registers (before a reflex needs it: a handshake)."""
        if self._io is not None:
            return
        probe_rtde(self.host, self.probe_timeout)
        try:
            self._io = rtde_io.RTDEIOInterface(self.host)
        except RuntimeError as exc:
            raise DeviceIOError(f"ur_rtde IO interface: {exc}") from exc
        if not no_delay_to(self.host):
            self.counters["nagle_left_on"] += 1

    def servo(self, q: Sequence[float]) -> None:
        """The next setpoint: the joint registers, then the flag (1, 2, ...), which hands them over."""
        doubles, ints = CONTROL_LOOP.encode(q)
        io = self._io
        if io is None:
            raise DeviceError(f"{self.name}: prepare_servo() first")
        self._flag = self._flag % 1_000_000 + 1
        ok = all(io.setInputDoubleRegister(r, v) for r, v in doubles.items())
        ok = ok and all(io.setInputIntRegister(r, v) for r, v in ints.items())
        if not (ok and io.setInputIntRegister(CONTROL_LOOP.flag_int, self._flag)):
            raise DeviceIOError(f"{self.name}: the controller did not take the setpoint registers")
        self.counters["setpoints"] += 1

    def end_servo(self) -> None:
        """Flag 0: the program stops following; the arm stays where the last setpoint took it."""
        if self._io is not None and not self._io.setInputIntRegister(CONTROL_LOOP.flag_int, 0):
            raise DeviceIOError(f"{self.name}: the controller did not take the end of the stream")

    def stop(self) -> None:
        """The monitor's reflex: stop the program (dashboard ``stop``); the arm halts."""
        self._dashboard("stop", "Stopped", "STOPPED")
        self.counters["stops"] += 1

    def pause(self) -> None:
        self._dashboard("pause", "Pausing program", "PAUSED")
        self.counters["pauses"] += 1
