"""Franka arm adapter: the robot state through the client library the arm's system takes, stop through
its ``stop()``.

``client`` (the device's param): ``panda-py`` reads a Franka Emika Robot (FER, Panda; libfranka 0.9.2
as panda-python ships it, module ``panda_py.libfranka``), ``pylibfranka`` a Franka Research 3 (Franka's
own bindings of libfranka 0.21). Only the chosen library is imported (each carries its own libfranka).
Both connect with ``RealtimeConfig.kIgnore``: no real-time kernel is needed to read.

Publishes a ``JointFrame`` on ``joints/<name>`` per robot state (1 kHz): ``q``, ``qd`` = ``dq``, ``tau``
= ``tau_J`` (the link-side joint torque sensors, N m), ``current`` zeros (a Franka reports no motor
currents; JointFrame requires the field), ``t_device_ns`` the controller's ``time`` (ms since its
start), ``seq`` its tick at ``frequency`` (a skipped state is a gap, flagged ``SEQ_GAP``).
``robot_mode`` keeps the last state's mode name.

Measured with both libraries (tests/devices/test_franka_adapter.py, this host): ``read_once()`` holds
the Python interpreter while it waits for the next state, so the reader sleeps (interpreter free)
until 0.7 of a period after the last state came, then reads. libfranka gives up on a silent controller
after its fixed 1 s UDP timeout (``libfranka: UDP receive: Timeout``), during which the interpreter is
held: the link is then broken (``stale``, ``disconnect``) and reopened with backoff. Where a monitor
must not stall for that second, run this reader in its own process (``--readers process``).

Before libfranka connects (its constructor waits forever for a controller that accepts TCP but never
answers), a plain socket sends the protocol's Connect with a timeout (:func:`probe_fci`); a controller
of the other protocol version is named in the error (the device's ``client`` is then wrong).

``stop()``, the monitor's reflex: the library's ``stop()`` (StopMove); it is run in a helper thread
and given ``stop_timeout`` s, since libfranka waits for the reply without a timeout.
"""
from __future__ import annotations

import importlib
import socket
import threading
import time
from types import ModuleType
from typing import Any

import numpy as np

from ftc_hw.bus import Bus, JointFlag, JointFrame, joints_topic
from ftc_hw.codecs import franka as F

from .arm_base import ArmAdapter
from .base import DeviceError, DeviceIOError, one_line

CLIENTS = {"panda-py": ("panda_py.libfranka", F.V5), "pylibfranka": ("pylibfranka", F.V10)}
_N = F.N_JOINTS
_ZEROS = np.zeros(_N)


def client_module(client: str) -> ModuleType:
    """The client library's module (imported on first use: two libfranka builds, one per library)."""
    if client not in CLIENTS:
        raise DeviceError(f"client {client!r}: expected one of {', '.join(CLIENTS)}")
    return importlib.import_module(CLIENTS[client][0])


def probe_fci(host: str, proto: F.ProtocolVersion, timeout: float = 0.5) -> None:
    """Raise DeviceIOError unless the controller at ``host`` answers a Connect of ``proto`` in time, and
    DeviceError when it speaks another protocol version (names the library it takes)."""
    try:
        with socket.create_connection((host, F.COMMAND_PORT), timeout=timeout) as s, \
                socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
            udp.bind(("", 0))
            s.settimeout(timeout)
            s.sendall(F.encode_connect(proto, 0, udp.getsockname()[1]))
            want = F.HEADER_SIZE + F.CONNECT_RESPONSE.size
            reply = b""
            while len(reply) < want:
                chunk = s.recv(want - len(reply))
                if not chunk:
                    raise DeviceIOError(f"{host}:{F.COMMAND_PORT} closed the connection")
                reply += chunk
    except OSError as exc:
        raise DeviceIOError(f"FCI at {host}:{F.COMMAND_PORT} does not answer: {exc}") from exc
    try:
        header, status, body = F.decode_response(reply)
        version = int.from_bytes(body, "little")
    except F.FrankaProtocolError as exc:
        raise DeviceIOError(f"FCI at {host}: not a Connect response ({exc})") from exc
    if header.command != proto.commands["Connect"]:
        raise DeviceIOError(f"FCI at {host}: answered Connect with command {header.command}")
    if status != F.SUCCESS:
        takes = next((c for c, (_, p) in CLIENTS.items() if p.version == version), None)
        hint = f"set client = {takes!r}" if takes else "no supported client speaks it"
        raise DeviceError(f"the controller at {host} speaks FCI protocol {version}, client library libfranka "
                          f"{proto.libfranka} speaks {proto.version}: {hint}")


class FrankaArm(ArmAdapter):
    kind = "franka"

    def __init__(self, name: str, bus: Bus, host: str, *, client: str = "pylibfranka", frequency: float = 1000.0,
                 stop_timeout: float = 1.0, probe_timeout: float = 0.5, idle_fraction: float = 0.7,
                 reconnect_backoff: tuple[float, float] = (0.05, 1.0)) -> None:
        super().__init__(name, bus, reconnect_backoff=reconnect_backoff)
        if client not in CLIENTS:
            raise DeviceError(f"device {name!r}: client {client!r}: expected one of {', '.join(CLIENTS)}")
        self.host, self.client = host, client
        self.proto = CLIENTS[client][1]
        self.rate = float(frequency)
        self.period = 1.0 / self.rate
        self.stop_timeout, self.probe_timeout = stop_timeout, probe_timeout
        self.idle_fraction = idle_fraction
        self.topic = joints_topic(name)
        self.robot_mode: str | None = None
        self._lib: ModuleType | None = None
        self._robot: Any = None
        self._last_seq: int | None = None
        self._last_rx = 0.0

    @classmethod
    def from_spec(cls, spec: Any, bus: Bus, endpoint: dict | str | None = None, *, scene: Any = None,
                  **overrides: Any) -> FrankaArm:
        """From a scene's ``[[devices]]`` entry; ``endpoint``: ``ftc sim``'s endpoint dict or an address."""
        host = endpoint.get("address", endpoint.get("endpoint")) if isinstance(endpoint, dict) else endpoint
        host = host or spec.address
        if not host:
            raise DeviceError(f"device {spec.name!r}: no controller address")
        kwargs = {k: spec.params[k] for k in ("client", "frequency", "stop_timeout") if k in spec.params}
        kwargs.update(overrides)
        return cls(spec.name, bus, host, **kwargs)

    def describe(self) -> str:
        return f"{self.kind} {self.host} ({self.client}, libfranka {self.proto.libfranka}) at {self.rate:g} Hz"

    # -- link -------------------------------------------------------------------------------------------
    def _connect(self) -> None:
        probe_fci(self.host, self.proto, self.probe_timeout)
        lib = self._lib = self._lib or client_module(self.client)
        try:
            self._robot = lib.Robot(self.host, lib.RealtimeConfig.kIgnore)
        except Exception as exc:  # libfranka's NetworkException / ProtocolException, as the binding raises them
            raise DeviceIOError(f"libfranka: {one_line(exc)}") from exc
        self._last_rx = time.monotonic()

    def _disconnect(self) -> None:
        self._robot = None  # libfranka closes its sockets when the Robot is destroyed

    # -- the reader loop ----------------------------------------------------------------------------------
    def _read_once(self) -> None:
        self._stale_on_failure(self._read)

    def _read(self) -> None:
        robot = self._robot
        # read_once holds the interpreter while it waits: wait here, with it free, for most of a period
        wait = self._last_rx + self.idle_fraction * self.period - time.monotonic()
        if wait > 0.0:
            time.sleep(wait)
        try:
            state = robot.read_once()
        except Exception as exc:  # the binding's NetworkException (or RuntimeError): the link is broken
            raise DeviceIOError(f"libfranka: {one_line(exc)}") from exc
        self._publish(state)

    def _publish(self, state: Any) -> None:
        t_host = time.monotonic_ns()
        ms = round(state.time.to_sec() * 1000.0)
        seq = round(ms * self.rate / 1000.0)
        flags = JointFlag.NONE
        if self._last_seq is not None:
            if seq - self._last_seq > 1:
                flags |= JointFlag.SEQ_GAP
                self.counters["missed_states"] += seq - self._last_seq - 1
            elif seq <= self._last_seq:  # the controller restarted: its clock went back
                flags |= JointFlag.CLOCK_SUSPECT
                seq = self._last_seq + 1
        frame = JointFrame.make(t_host, state.q, state.dq, _ZEROS, state.tau_J, source=self.name, seq=seq,
                                t_device_ns=ms * 1_000_000, flags=flags)
        self.robot_mode = str(state.robot_mode).rsplit(".", 1)[-1]
        self._last_seq, self._last_rx = seq, time.monotonic()
        self.counters["frames"] += 1
        self.bus.publish(self.topic, frame)
        self._mark_fresh("robot states again")

    # -- commands ----------------------------------------------------------------------------------------
    def stop(self) -> None:
        """The monitor's reflex: the library's ``stop()`` (StopMove); the arm halts."""
        robot = self._robot
        if robot is None:
            raise DeviceError(f"{self.name}: not connected to the controller; cannot stop")
        outcome: list[BaseException | None] = []

        def run() -> None:
            try:
                robot.stop()
                outcome.append(None)
            except Exception as exc:  # noqa: BLE001 - handed to the caller below
                outcome.append(exc)

        worker = threading.Thread(target=run, name=f"franka-stop:{self.name}", daemon=True)
        worker.start()
        worker.join(self.stop_timeout)
        if not outcome:
            self.counters["stop_timeouts"] += 1
            raise DeviceError(f"{self.name}: the controller did not answer StopMove within {self.stop_timeout:g} s")
        if outcome[0] is not None:
            raise DeviceError(f"{self.name}: stop failed: libfranka: {one_line(outcome[0])}") from outcome[0]
        self.counters["stops"] += 1
