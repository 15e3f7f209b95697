"""Franka arm controller emulator: libfranka's network protocol (FCI), fed by the world's joint ring.

Binds TCP ``<address>:1337`` (libfranka hard-codes ``kCommandPort``, so every emulator gets its own
loopback address: ``options["address"]``, else the device spec's ``address``, else
``DEFAULT_ADDRESS``; non-loopback addresses are refused) and a UDP socket on the same address.

The device's ``client`` says which controller is emulated: ``panda-py`` a Franka Emika Robot (FER)
system, protocol version 5 (libfranka 0.9.x); ``pylibfranka`` a Franka Research 3 system, version 10
(libfranka 0.21). A Connect of another version is answered ``kIncompatibleLibraryVersion`` with the
emulated version, as a real controller does; libfranka then raises IncompatibleVersionException.

After a Connect the emulator sends one robot state datagram per controller tick (``frequency``, 1 kHz
as Franka's controller) to the client's UDP port (the Connect's, at the TCP peer's address): each
world joint sample whose time crosses a multiple of the period is sent; ``message_id`` is the tick
number (libfranka's ``time`` in ms). The state: ``franka_state.py``. Datagrams from the client
(robot commands: control) are counted and dropped.

Commands (``ftc_hw.codecs.franka``): every command is answered (status 0 unless said). ``StopMove``
halts the arm (``Command("stop")``: it holds where it is; robot_mode idle) -- what a user's stop or
the monitor's reflex does; ``AutomaticErrorRecovery`` continues the scenario a stop halted
(``Command("resume")``; robot_mode move), as a user's program goes on after recovering. While the
scenario plays, robot_mode is ``kMove``. ``Move`` (a client taking control) is refused
``kCommandNotPossibleRejected``: the world's scenario drives the arm. The setters are accepted; SetLoad,
SetEEToK and SetNEToEE show in the state. Version 5: GetCartesianLimit answers an inactive limit,
LoadModelLibrary answers ``kError`` (Franka's compiled model library is not served: libfranka's
``load_model()`` raises ModelException). Version 10: GetRobotModel serves ``franka_urdf.py``'s
description (libfranka's Robot constructor asks for it).

Options: ``address``, ``frequency``, ``client`` (override the device's).
"""
from __future__ import annotations

import contextlib
import math
import socket
import threading
import time
from typing import Any

import numpy as np

from ftc_hw.codecs import franka as F

from .emulator import Emulator, serve_with
from .franka_state import StateBuilder
from .franka_urdf import robot_urdf
from .link import Command, JointRecord
from .listener import Listener, drop_session
from .loopback import check_loopback

DEFAULT_ADDRESS = "127.0.0.4"  # where an emulated controller listens unless told
CLIENT_VERSIONS = {"panda-py": F.V5, "pylibfranka": F.V10}
INCOMPATIBLE_VERSION = 1  # Connect::Status::kIncompatibleLibraryVersion
LOAD_MODEL_ERROR = 1  # LoadModelLibrary::Status::kError
_CARTESIAN_LIMIT = bytes(3 * 8 + 16 * 8 + 1)  # GetCartesianLimit: size, frame, not active


class Controller:
    """The emulated controller's state shared by its sessions and the stream: the robot mode and what
    the setters set; StopMove and error recovery go to the world."""

    def __init__(self, world: Any, source: str) -> None:
        self.world, self.source = world, source
        self.lock = threading.Lock()
        self.robot_mode = F.MODE_MOVE
        self.counts = {"stops": 0, "recoveries": 0, "refused": 0, "bad": 0, "commands_in": 0}

    def stop(self, t_rx_ns: int) -> None:
        with self.lock:
            self.robot_mode = F.MODE_IDLE
            self.counts["stops"] += 1
        self.world.send(Command(self.source, "stop", extra={"t_rx_ns": t_rx_ns}))

    def recover(self) -> None:
        with self.lock:
            resume = self.robot_mode != F.MODE_MOVE
            self.robot_mode = F.MODE_MOVE
            self.counts["recoveries"] += 1
        if resume:
            self.world.send(Command(self.source, "resume"))


class Session:
    """One libfranka client: its TCP connection, then its UDP port once connected."""

    def __init__(self, server: FrankaServer, sock: socket.socket, peer: str) -> None:
        self.server, self.sock, self.peer = server, sock, peer
        self.udp_target: tuple[str, int] | None = None
        self.closed = False

    def _recv(self, n: int) -> bytes:
        data = self.sock.recv(n, socket.MSG_WAITALL) if n else b""
        if len(data) < n:  # MSG_WAITALL returns short only at the peer's close
            raise ConnectionError("peer closed")
        return data

    def run(self) -> None:
        try:
            while True:
                header = F.decode_header(self._recv(F.HEADER_SIZE))
                payload = self._recv(header.size - F.HEADER_SIZE)
                t_rx_ns = time.monotonic_ns()
                reply = self.server.answer(self, header, payload, t_rx_ns)
                if reply is None:
                    return
                self.sock.sendall(reply)
        except (OSError, ConnectionError, F.FrankaProtocolError):
            pass
        finally:
            self.server.drop(self)


class FrankaServer:
    """The command server (TCP) and the state stream's sender (UDP) of one emulated controller."""

    def __init__(self, controller: Controller, proto: F.ProtocolVersion, address: str, urdf: str,
                 extra: dict[str, Any]) -> None:
        self.controller, self.proto, self.urdf = controller, proto, urdf
        self.extra = extra  # what the setters set that the state shows (field -> value)
        self.sessions: list[Session] = []
        self.lock = threading.Lock()
        self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.udp.bind((address, 0))
        self.udp.setblocking(False)
        self.listener = Listener(address, F.COMMAND_PORT, self._client, "franka-accept")

    def _client(self, conn: socket.socket) -> None:
        s = Session(self, conn, conn.getpeername()[0])
        with self.lock:
            self.sessions.append(s)
        threading.Thread(target=s.run, name="franka-session", daemon=True).start()

    def drop(self, s: Session) -> None:
        drop_session(self.lock, self.sessions, s)

    def answer(self, s: Session, header: F.Header, payload: bytes, t_rx_ns: int) -> bytes | None:
        """The reply to one request; None closes the connection (a protocol error)."""
        ctl, proto = self.controller, self.proto
        try:
            name = F.check_request(proto, header)
        except F.FrankaProtocolError:
            ctl.counts["bad"] += 1
            return None
        if name == "Connect":
            version, port = F.decode_connect(payload)
            if version != proto.version:
                return F.encode_connect_response(header, INCOMPATIBLE_VERSION, proto.version)
            s.udp_target = (s.peer, port)
            return F.encode_connect_response(header, F.SUCCESS, proto.version)
        if s.udp_target is None:  # a command before Connect
            ctl.counts["bad"] += 1
            return None
        return self._command(name, header, payload, t_rx_ns)

    def _command(self, name: str, header: F.Header, payload: bytes, t_rx_ns: int) -> bytes:
        ctl = self.controller
        if name == "StopMove":
            ctl.stop(t_rx_ns)
        elif name == "AutomaticErrorRecovery":
            ctl.recover()
        elif name == "Move":
            ctl.counts["refused"] += 1
            return F.encode_response(header, self.proto.move_not_possible)
        elif name == "GetRobotModel":
            return F.encode_response(header, F.SUCCESS, self.urdf.encode())
        elif name == "GetCartesianLimit":
            return F.encode_response(header, F.SUCCESS, _CARTESIAN_LIMIT)
        elif name == "LoadModelLibrary":
            return F.encode_response(header, LOAD_MODEL_ERROR)
        else:
            self._setter(name, payload)
        return F.encode_response(header, F.SUCCESS)

    def _setter(self, name: str, payload: bytes) -> None:
        values = np.frombuffer(payload, dtype="<f8") if len(payload) % 8 == 0 else None
        with self.controller.lock:
            if name == "SetLoad" and values is not None:
                self.extra.update(m_load=values[0], F_x_Cload=values[1:4], I_load=values[4:13])
            elif name == "SetEEToK" and values is not None:
                self.extra["EE_T_K"] = values
            elif name == "SetNEToEE" and values is not None:
                self.extra["NE_T_EE"] = values

    def targets(self) -> list[tuple[str, int]]:
        with self.lock:
            return [s.udp_target for s in self.sessions if s.udp_target is not None]

    def send(self, data: bytes) -> int:
        """Send one state to every connected client; the number it reached."""
        sent = 0
        for target in self.targets():
            with contextlib.suppress(OSError):
                self.udp.sendto(data, target)
                sent += 1
        return sent

    def drain_commands(self) -> int:
        """Robot command datagrams received (control is not emulated): counted, dropped."""
        n = 0
        while True:
            try:
                self.udp.recv(4096)
            except (BlockingIOError, OSError):
                return n
            n += 1

    def close(self) -> None:
        self.listener.close()
        self.udp.close()
        with self.lock:
            sessions = list(self.sessions)
        for s in sessions:
            self.drop(s)


_FINE_S = 0.00025  # the stream loop's poll near a tick
_MARGIN_S = 0.0004  # ... which starts this long before the tick's world time says it can come


class FrankaEmulator(Emulator):
    """The controller's servers and its 1 kHz state stream, for one Franka device."""

    def __init__(self, device: Any, scene: Any, link: Any, options: dict) -> None:
        p = {**device.params, **{k: options[k] for k in ("frequency", "client") if k in options}}
        self.address = check_loopback(options.get("address") or device.address or DEFAULT_ADDRESS)
        client = str(p.get("client", "pylibfranka"))
        if client not in CLIENT_VERSIONS:
            raise ValueError(f"client {client!r}: expected one of {', '.join(CLIENT_VERSIONS)}")
        self.proto = CLIENT_VERSIONS[client]
        self.rate = float(p.get("frequency", 1000.0))
        if not 0.0 < self.rate <= 1000.0:
            raise ValueError(f"frequency {self.rate:g} Hz: a Franka controller sends at most 1000 Hz")
        super().__init__(device, scene, link, options)
        self.n = scene.n_joints
        self.builder = StateBuilder(self.proto, scene, 1.0 / self.rate)
        self.controller = Controller(self.side, device.name)
        self.states_out = 0
        self.commands_in = 0

    def bind(self) -> dict[str, Any]:
        lower, upper = self.builder.kin.arm.joint_limits()
        extra: dict[str, Any] = {}
        self.server = FrankaServer(self.controller, self.proto, self.address, robot_urdf("fr3", lower, upper), extra)
        self.extra = extra
        return {**self.endpoint_base("tcp", self.address), "address": self.address, "port": F.COMMAND_PORT,
                "frequency": self.rate, "protocol_version": self.proto.version, "libfranka": self.proto.libfranka}

    def close(self) -> None:
        server = getattr(self, "server", None)
        if server is not None:
            server.close()

    def stats(self) -> dict[str, Any]:
        return {**super().stats(), "states_out": self.states_out, "commands_in": self.commands_in,
                **self.controller.counts}

    def loop(self) -> None:
        reader = self.side.joint_reader()
        last_k: int | None = None
        t_seen: float | None = None
        next_check = time.monotonic() + 1.0
        while True:
            if time.monotonic() > next_check:
                next_check += 1.0
                self.heartbeat()
            for rec in reader.new():
                joints = JointRecord.from_row(rec, self.n)
                t_seen = joints.t
                k = math.floor(joints.t * self.rate + 1e-6)
                if last_k is not None and k <= last_k:
                    continue
                last_k = k
                self._send(k, joints)
            self.commands_in += self.server.drain_commands()
            time.sleep(self._pause(t_seen, last_k))

    def _send(self, k: int, joints: JointRecord) -> None:
        with self.controller.lock:
            mode = self.controller.robot_mode
            for name, value in self.extra.items():
                self.builder.state[name] = value
        ms_per_tick = 1000.0 / self.rate
        data = self.builder.build(round(k * ms_per_tick), joints, mode)
        if self.server.send(data):
            self.states_out += 1

    def _pause(self, t_seen: float | None, last_k: int | None) -> float:
        """Sleep finely near the next tick, and until near it when it is further off (as ``ur.py``)."""
        if t_seen is None or last_k is None:
            return _FINE_S
        return max(_FINE_S, (last_k + 1) / self.rate - t_seen - _MARGIN_S)


def serve(device: Any, scene: Any, link: Any, ready: Any, options: dict) -> None:
    """The emulator process: bind, report the endpoint on ``ready``, stream until terminated."""
    serve_with(FrankaEmulator, device, scene, link, ready, options)

