"""Universal Robots controller emulator: an RTDE server (protocol v2) and a dashboard server subset.

Binds ``<address>:30004`` (RTDE; ur_rtde hard-codes the port, so every emulator gets its own loopback
address: ``options["address"]``, else the device spec's ``address``, else ``DEFAULT_ADDRESS``,
127.0.0.2; non-loopback addresses are refused)
and ``<address>:29999`` (dashboard).

RTDE: the version request is accepted for protocol 2 only; the controller version is the device's
``controller_version`` (default "5.9"). Output recipes may hold any variable of ``ur_data.OUTPUTS``
(every one ur_rtde's receive interface asks for at 3.x or 5.x); an unknown name is answered
``NOT_FOUND`` (recipe id 0), a frequency outside (0, max] refused (id 0), max = 500 Hz for e-Series
(5.x and later), 125 Hz for CB3. Input recipes (ids from 1, separate from output ids) may hold any
``ur_data.INPUTS`` name, ``IN_USE`` if another connection's recipe holds it; data packages set the
digital/analog outputs, speed slider and input registers, which output recipes then report.

Stream: paced by the world's clock. Each world joint sample whose time crosses a multiple of a
recipe's period (1/frequency) is sent to that recipe's clients: ``timestamp`` is the world time of the
sample and ``actual_q/qd/current`` its values, bit for bit. ``target_*`` report the actual values.
``joint_temperatures`` come from a thermal model on the world's currents (``thermal.py``).
F/T (sim_devices/SOURCES.md, "UR F/T"): with a flange sensor (the scene's ``[sensor] mount = "flange"``,
an e-Series' built-in one: ``controller_version`` 5.9 or later and its site the ``[robot] flange``
frame, refused otherwise) ``ft_raw_wrench`` is that sensor's reading from the world's F/T ring -- the
newest sample at or before the packet's time (``ur_ft.py``), as the scene's sensor reports it (frame,
sign, noise, bias, range) -- and ``actual_TCP_force`` the external wrench it implies, in base axes
(``ur_model.flange_wrench_base``). Without one (a base sensor, which no UR has, or none)
``actual_TCP_force`` is the controller's current-based estimate at the TCP (base axes) and
``ft_raw_wrench`` the same wrench in the flange frame (``ur_model.py``). Counted in the stats:
``ft_missing`` (none published yet: zeros sent), ``ft_not_at_time`` (no F/T sample at or before the
packet's time: the oldest held one was sent) and ``ft_late`` (the one sent is more than two sensor
periods old).
Not modelled: momentum, tool I/O, euromap (0).

Program: besides the scenario, the controller runs the control-loop program of UR's RTDE example with
joint targets (``ur_program.py``, docs/arms.md "Streamed setpoints"): a write of the flag input register
hands it the joint input registers as a servo target (the scenario stops there), within the scene's joint
limits, with ``rtde_set_watchdog(..., "PAUSE")`` semantics (option ``watchdog_hz``, default 1 Hz).

Options: ``address``, ``rtde_port``, ``dashboard_port``, ``controller_version`` and ``frequency``
(override the device's), ``resume_after_s`` (below), ``watchdog_hz`` (the program's watchdog).

Dashboard (``ur_dashboard.py``: every command of the e-Series dashboard server that UR's client
library and ur_rtde's DashboardClient wrap, as a table of commands, replies and sources; an unknown
one is answered ``could not understand: '<line>'``). The emulated robot starts powered, brakes
released, in remote control, operational mode AUTOMATIC, its program (the world's scenario,
``/programs/ftc-scenario.urp``) playing; ``load <x>.urp`` stops it and loads x (the world plays on
from where it halted at the next ``play``), ``shutdown`` and ``restart safety`` power the arm off.
``stop`` and ``pause`` (while playing) and ``power off`` halt the arm (``Command("stop")``: it holds
where it is); ``play`` (from paused or stopped) continues the scenario from where it was halted
(``Command("resume")``; a real controller starts a stopped program from its beginning, the world has
only the one scenario). Option ``resume_after_s``: an operator presses play that long after every
stop or pause (a sweep then meets each of its contacts with a stop). Modes show in RTDE's
robot_mode, safety_mode, runtime_state, robot_status_bits and joint_mode.
"""
from __future__ import annotations

import math
import socket
import struct
import threading
import time
from functools import cached_property
from typing import Any

import numpy as np

from ftc_hw.codecs.ur_control_loop import ControlLoopRegisters

from . import ur_data as D
from .emulator import Emulator, serve_with
from .link import Command, JointRecord
from .listener import Listener, drop_session
from .loopback import check_loopback
from .thermal import ThermalModel
from .ur_dashboard import answer, serve_connection
from .ur_ft import FlangeSamples
from .ur_model import URKinematics, flange_wrench_base
from .ur_program import ControlLoopProgram


def parse_version(text: str) -> tuple[int, int, int, int]:
    parts = [int(p) for p in str(text).split(".")]
    if not 1 <= len(parts) <= 4:
        raise ValueError(f"controller_version {text!r}: expected major.minor[.bugfix[.build]]")
    return tuple(parts + [0] * (4 - len(parts)))  # type: ignore[return-value]


# -- the controller's state (modes, I/O) ------------------------------------------------------------------
class Controller:
    def __init__(self, version: tuple[int, int, int, int], world: Any, source: str, serial: str, model: str,
                 resume_after_s: float | None = None) -> None:
        self.version = version
        self.resume_after_s = resume_after_s
        self._operator: threading.Timer | None = None
        self.world = world  # .send(Command)
        self.source = source
        self.serial = serial
        self.model = model
        self.lock = threading.Lock()
        self.robot_mode = D.ROBOT_RUNNING
        self.safety_mode = D.SAFETY_NORMAL
        self.runtime = D.RUNTIME_PLAYING
        self.program_path = "/programs/ftc-scenario.urp"
        self.installation = "default.installation"
        self.operational_mode = "AUTOMATIC"  # a password is set for the mode, so never NONE
        self.remote_control = True
        self.popup: str | None = None
        self.log: list[str] = []
        self.digital_out = 0  # standard bits 0-7, configurable 8-15, tool 16-17
        self.analog_out = [0.0, 0.0]
        self.analog_types = 0
        self.speed_fraction = 1.0
        self.input_int = [0] * 48
        self.input_double = [0.0] * 48
        self.input_bits = 0  # input bit registers 0..127
        self.external_wrench = [0.0] * 6
        self.control_loop: ControlLoopProgram | None = None  # the program that follows streamed joint setpoints
        self.halts = 0
        self._t_rx_ns = 0  # when the dashboard line being handled was read (monotonic ns)

    def halt(self) -> None:
        self.halts += 1
        if self.control_loop is not None:
            self.control_loop.halt()
        self.world.send(Command(self.source, "stop", extra={"t_rx_ns": self._t_rx_ns}))
        if self.resume_after_s is not None and self.robot_mode == D.ROBOT_RUNNING:
            if self._operator is not None:
                self._operator.cancel()
            self._operator = threading.Timer(self.resume_after_s, self._operator_plays)
            self._operator.daemon = True
            self._operator.start()

    def _operator_plays(self) -> None:
        with self.lock:
            answer(self, "play")

    def watchdog_pause(self) -> None:
        """``rtde_set_watchdog(..., "PAUSE")`` fired: the program pauses, the arm halts where it is."""
        with self.lock:
            if self.runtime == D.RUNTIME_PLAYING:
                self.runtime = D.RUNTIME_PAUSED
                self.log.append("RTDE input watchdog: program paused")
            self.halt()

    def play(self) -> None:
        if self.runtime != D.RUNTIME_PLAYING:
            self.world.send(Command(self.source, "resume"))
        self.runtime = D.RUNTIME_PLAYING

    # -- RTDE views ----------------------------------------------------------------------------------------
    @property
    def robot_status_bits(self) -> int:
        powered = self.robot_mode in (4, D.ROBOT_IDLE, D.ROBOT_RUNNING)
        return int(powered) | (int(self.runtime == D.RUNTIME_PLAYING) << 1)

    @property
    def safety_status_bits(self) -> int:
        return 1 if self.safety_mode == D.SAFETY_NORMAL else 1 << 10

    @property
    def joint_mode(self) -> int:
        return {D.ROBOT_POWER_OFF: D.JOINT_POWER_OFF, D.ROBOT_IDLE: D.JOINT_IDLE}.get(self.robot_mode, D.JOINT_RUNNING)

    def apply_input(self, values: dict[str, Any], t_rx_ns: int = 0) -> None:
        """An input data package's values (``t_rx_ns``: when it was read, monotonic ns)."""
        with self.lock:
            def masked(name: str, shift: int) -> None:
                mask = values.get(f"{name}_mask")
                if mask is not None and name in values:
                    self.digital_out = (self.digital_out & ~(mask << shift)) | ((values[name] & mask) << shift)
            masked("standard_digital_output", 0)
            masked("configurable_digital_output", 8)
            masked("tool_digital_output", 16)
            if values.get("speed_slider_mask", 0) & 1 and "speed_slider_fraction" in values:
                self.speed_fraction = min(max(float(values["speed_slider_fraction"]), 0.0), 1.0)
            amask = values.get("standard_analog_output_mask", 0)
            for k in (0, 1):
                if amask & (1 << k) and f"standard_analog_output_{k}" in values:
                    self.analog_out[k] = float(values[f"standard_analog_output_{k}"])
                    kind = values.get("standard_analog_output_type", 0) >> k & 1
                    self.analog_types = (self.analog_types & ~(1 << (k + 2))) | (kind << (k + 2))
            for name, v in values.items():
                if name.startswith("input_int_register_"):
                    self.input_int[int(name.rsplit("_", 1)[1])] = int(v)
                elif name.startswith("input_double_register_"):
                    self.input_double[int(name.rsplit("_", 1)[1])] = float(v)
                elif name.startswith("input_bit_register_"):
                    bit = int(name.rsplit("_", 1)[1])
                    self.input_bits = (self.input_bits & ~(1 << bit)) | (int(bool(v)) << bit)
                elif name == "input_bit_registers0_to_31":
                    self.input_bits = (self.input_bits & ~0xFFFFFFFF) | int(v)
                elif name == "input_bit_registers32_to_63":
                    self.input_bits = (self.input_bits & ~(0xFFFFFFFF << 32)) | (int(v) << 32)
                elif name == "external_force_torque":
                    self.external_wrench = list(v)
            program = self.control_loop
            if program is not None and program.registers.flag_name in values:
                if self.runtime != D.RUNTIME_PLAYING:  # a stopped or paused program reads no registers
                    program.counts["not_playing"] += 1
                else:
                    program.on_flag(int(values[program.registers.flag_name]), self.input_double, self.input_int,
                                    t_rx_ns)

    # -- dashboard ------------------------------------------------------------------------------------------
    @property
    def program(self) -> str:
        """The loaded program's file name ("" when none)."""
        return self.program_path.rsplit("/", 1)[-1]

    def dashboard(self, line: str, t_rx_ns: int = 0) -> str:
        """The reply to one dashboard line; ``t_rx_ns``: when it was read (recorded with a halt)."""
        return self.dashboard_line(line, t_rx_ns)[0]

    def dashboard_line(self, line: str, t_rx_ns: int = 0) -> tuple[str, bool]:
        """The reply to one dashboard line and whether the server closes the connection after it."""
        with self.lock:
            self._t_rx_ns = t_rx_ns
            return answer(self, line.strip())


# -- one stream sample and the value of every output variable ----------------------------------------------
class Tick:
    """One packet's values. ``ft``: the flange sensor's reading (shape (6,), sensor = flange frame, the
    scene's convention), None without a flange sensor; ``ft_sign``: the scene sensor's ``reading_sign``."""

    def __init__(self, joints: JointRecord, ctl: Controller, kin: URKinematics | None,
                 temperatures: np.ndarray, exec_ms: float, ft: np.ndarray | None = None,
                 ft_sign: float = 1.0) -> None:
        self.t, self.q, self.qd, self.qdd = joints.t, joints.q, joints.qd, joints.qdd
        self.current, self.tau = joints.current, joints.tau
        self.ctl, self.kin, self.temperatures, self.exec_ms = ctl, kin, temperatures, exec_ms
        self.ft, self.ft_sign = ft, ft_sign

    @cached_property
    def _kin(self) -> URKinematics:
        if self.kin is None:
            raise RuntimeError("no kinematics")
        self.kin.update(self.q, self.qd, self.qdd)
        return self.kin

    @cached_property
    def tcp_pose(self) -> np.ndarray:
        return self._kin.tcp_pose()

    @cached_property
    def tcp_speed(self) -> np.ndarray:
        return self._kin.tcp_speed(self.qd)

    @cached_property
    def tcp_force(self) -> np.ndarray:
        if self.ft is not None:
            return flange_wrench_base(self.ft, self.ft_sign, self._kin.tcp_rotation())
        return self._kin.tcp_wrench(self.qd, self.tau)

    @cached_property
    def ft_raw(self) -> np.ndarray:
        if self.ft is not None:
            return self.ft
        r = self._kin.tcp_rotation()
        return np.concatenate([r.T @ self.tcp_force[:3], r.T @ self.tcp_force[3:]])

    @cached_property
    def elbow(self) -> tuple[np.ndarray, np.ndarray]:
        return self._kin.elbow()


def _powered(c: Controller) -> bool:
    return c.robot_mode != D.ROBOT_POWER_OFF


_Z3, _Z6 = (0.0,) * 3, (0.0,) * 6
VALUES: dict[str, Any] = {
    "timestamp": lambda k: k.t,
    "target_q": lambda k: k.q, "target_qd": lambda k: k.qd, "target_qdd": lambda k: k.qdd,
    "target_current": lambda k: k.current, "target_moment": lambda k: k.tau,
    "actual_q": lambda k: k.q, "actual_qd": lambda k: k.qd, "actual_current": lambda k: k.current,
    "actual_current_window": lambda k: _Z6, "actual_current_as_torque": lambda k: k.tau,
    "joint_control_output": lambda k: k.current,
    "actual_TCP_pose": lambda k: k.tcp_pose, "target_TCP_pose": lambda k: k.tcp_pose,
    "actual_TCP_speed": lambda k: k.tcp_speed, "target_TCP_speed": lambda k: k.tcp_speed,
    "actual_TCP_force": lambda k: k.tcp_force, "tcp_force_scalar": lambda k: float(np.linalg.norm(k.tcp_force[:3])),
    "ft_raw_wrench": lambda k: k.ft_raw,
    "actual_digital_input_bits": lambda k: 0, "joint_temperatures": lambda k: k.temperatures,
    "actual_execution_time": lambda k: k.exec_ms,
    "robot_mode": lambda k: k.ctl.robot_mode, "joint_mode": lambda k: (k.ctl.joint_mode,) * 6,
    "safety_mode": lambda k: k.ctl.safety_mode, "safety_status": lambda k: k.ctl.safety_mode,
    "actual_tool_accelerometer": lambda k: k._kin.accelerometer(),
    "speed_scaling": lambda k: k.ctl.speed_fraction, "target_speed_fraction": lambda k: k.ctl.speed_fraction,
    "actual_momentum": lambda k: 0.0, "actual_main_voltage": lambda k: 48.0,
    "actual_robot_voltage": lambda k: 48.0 if _powered(k.ctl) else 0.0,
    "actual_robot_current": lambda k: 0.3 + float(np.abs(k.tau * k.qd).sum()) / 48.0 if _powered(k.ctl) else 0.0,
    "actual_joint_voltage": lambda k: (48.0 if _powered(k.ctl) else 0.0,) * 6,
    "actual_digital_output_bits": lambda k: k.ctl.digital_out, "runtime_state": lambda k: k.ctl.runtime,
    "elbow_position": lambda k: k.elbow[0], "elbow_velocity": lambda k: k.elbow[1],
    "robot_status_bits": lambda k: k.ctl.robot_status_bits, "safety_status_bits": lambda k: k.ctl.safety_status_bits,
    "analog_io_types": lambda k: k.ctl.analog_types,
    "standard_analog_input0": lambda k: 0.0, "standard_analog_input1": lambda k: 0.0,
    "standard_analog_output0": lambda k: k.ctl.analog_out[0], "standard_analog_output1": lambda k: k.ctl.analog_out[1],
    "io_current": lambda k: 0.0, "euromap67_input_bits": lambda k: 0, "euromap67_output_bits": lambda k: 0,
    "euromap67_24V_voltage": lambda k: 0.0, "euromap67_24V_current": lambda k: 0.0,
    "tool_mode": lambda k: 0, "tool_analog_input_types": lambda k: 0, "tool_analog_input0": lambda k: 0.0,
    "tool_analog_input1": lambda k: 0.0, "tool_output_voltage": lambda k: 0, "tool_output_current": lambda k: 0.0,
    "tool_temperature": lambda k: float(k.temperatures[-1]),
    "output_bit_registers0_to_31": lambda k: 0, "output_bit_registers32_to_63": lambda k: 0,
    "input_bit_registers0_to_31": lambda k: k.ctl.input_bits & 0xFFFFFFFF,
    "input_bit_registers32_to_63": lambda k: (k.ctl.input_bits >> 32) & 0xFFFFFFFF,
    "tool_output_mode": lambda k: 0, "tool_digital_output0_mode": lambda k: 0, "tool_digital_output1_mode": lambda k: 0,
    "payload": lambda k: 0.0, "payload_cog": lambda k: _Z3, "payload_inertia": lambda k: _Z6,
    "script_control_line": lambda k: 0,
    "joint_position_deviation_ratio": lambda k: 0.0, "collision_detection_ratio": lambda k: 0.0,
}
for _k in range(48):
    VALUES[f"output_int_register_{_k}"] = lambda k: 0
    VALUES[f"output_double_register_{_k}"] = lambda k: 0.0
    VALUES[f"input_int_register_{_k}"] = lambda k, i=_k: k.ctl.input_int[i]
    VALUES[f"input_double_register_{_k}"] = lambda k, i=_k: k.ctl.input_double[i]
for _k in range(64, 128):
    VALUES[f"output_bit_register_{_k}"] = lambda k: False
    VALUES[f"input_bit_register_{_k}"] = lambda k, i=_k: bool(k.ctl.input_bits >> i & 1)
assert set(VALUES) == set(D.OUTPUTS), set(VALUES) ^ set(D.OUTPUTS)


def _format(types: list[str]) -> struct.Struct:
    return struct.Struct(">B" + "".join(D.TYPES[t] for t in types))


class OutputRecipe:
    def __init__(self, rid: int, names: list[str], frequency: float) -> None:
        self.id, self.names, self.frequency = rid, names, frequency
        self.types = [D.OUTPUTS[n] for n in names]
        self.vector = [t.startswith("VECTOR") for t in self.types]
        self.getters = [VALUES[n] for n in names]
        self.struct = _format(self.types)
        self.last_k: int | None = None

    def pack(self, tick: Tick) -> bytes:
        vals: list[Any] = [self.id]
        for get, vec in zip(self.getters, self.vector, strict=True):
            v = get(tick)
            if vec:
                vals.extend(v)
            else:
                vals.append(v)
        return self.struct.pack(*vals)


class InputRecipe:
    def __init__(self, rid: int, names: list[str]) -> None:
        self.id, self.names = rid, names
        self.types = [D.INPUTS[n] for n in names]
        self.struct = _format(self.types)

    def unpack(self, payload: bytes) -> dict[str, Any]:
        flat = list(self.struct.unpack(payload))[1:]
        out: dict[str, Any] = {}
        for name, typ in zip(self.names, self.types, strict=True):
            size = int(D.TYPES[typ][0]) if D.TYPES[typ][0].isdigit() else 1
            out[name] = tuple(flat[:size]) if size > 1 else flat[0]
            del flat[:size]
        return out


# -- RTDE connections ---------------------------------------------------------------------------------------
class RtdeSession:
    def __init__(self, server: RtdeServer, sock: socket.socket) -> None:
        self.server, self.sock = server, sock
        self.send_lock = threading.Lock()
        self.outputs: dict[int, OutputRecipe] = {}
        self.inputs: dict[int, InputRecipe] = {}
        self.started = False
        self.closed = False
        self.counts = {"data_in": 0, "data_out": 0, "bad": 0}

    def send(self, cmd: int, payload: bytes) -> None:
        with self.send_lock:
            self.sock.sendall(struct.pack(">HB", len(payload) + 3, cmd) + payload)

    def text(self, message: str, level: int = 1) -> None:
        m, s = message.encode()[:255], b"ftc-emulator"
        self.send(D.TEXT_MESSAGE, bytes([len(m)]) + m + bytes([len(s)]) + s + bytes([level]))

    def _recv(self, n: int) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            try:
                chunk = self.sock.recv(n - len(buf))
            except TimeoutError:
                if self.closed:
                    raise ConnectionError("closed") from None
                continue
            if not chunk:
                raise ConnectionError("peer closed")
            buf += chunk
        return bytes(buf)

    def run(self) -> None:
        try:
            while True:
                size, cmd = struct.unpack(">HB", self._recv(3))
                self.handle(cmd, self._recv(size - 3) if size > 3 else b"")
        except (OSError, ConnectionError, struct.error):
            pass
        finally:
            self.server.drop(self)

    def handle(self, cmd: int, payload: bytes) -> None:
        srv = self.server
        if cmd == D.REQUEST_PROTOCOL_VERSION:
            version = struct.unpack(">H", payload[:2])[0] if len(payload) >= 2 else 0
            self.send(cmd, bytes([int(version == D.PROTOCOL_VERSION)]))
        elif cmd == D.GET_URCONTROL_VERSION:
            self.send(cmd, struct.pack(">IIII", *srv.controller.version))
        elif cmd == D.SETUP_OUTPUTS:
            frequency = struct.unpack(">d", payload[:8])[0] if len(payload) >= 8 else 0.0
            names = [n for n in payload[8:].decode(errors="replace").split(",") if n]
            types = [D.OUTPUTS.get(n, "NOT_FOUND") for n in names]
            ok = bool(names) and "NOT_FOUND" not in types and 0.0 < frequency <= srv.max_rate
            rid = 0
            if ok:
                rid = len(self.outputs) + 1
                self.outputs[rid] = OutputRecipe(rid, names, frequency)
            self.send(cmd, bytes([rid]) + ",".join(types).encode())  # id 0: refused
        elif cmd == D.SETUP_INPUTS:
            names = [n for n in payload.decode(errors="replace").split(",") if n]
            types = [D.INPUTS.get(n, "NOT_FOUND") if not srv.input_taken(n, self) else "IN_USE" for n in names]
            rid = 0
            if names and "NOT_FOUND" not in types and "IN_USE" not in types:
                rid = len(self.inputs) + 1
                self.inputs[rid] = InputRecipe(rid, names)
            self.send(cmd, bytes([rid]) + ",".join(types).encode())
        elif cmd == D.START:
            self.started = True
            self.send(cmd, b"\x01")
        elif cmd == D.PAUSE:
            self.started = False
            self.send(cmd, b"\x01")
        elif cmd == D.DATA_PACKAGE:
            recipe = self.inputs.get(payload[0]) if payload else None
            if recipe is None or len(payload) != recipe.struct.size:
                self.counts["bad"] += 1
                self.text(f"data package for unknown input recipe or of wrong size ({len(payload)} bytes)", level=2)
                return
            self.counts["data_in"] += 1
            srv.controller.apply_input(recipe.unpack(payload), time.monotonic_ns())
        elif cmd == D.TEXT_MESSAGE:
            return
        else:
            self.counts["bad"] += 1
            self.text(f"unknown RTDE command {cmd}", level=2)

    def stream(self, tick: Tick) -> None:
        if not self.started:
            return
        for r in self.outputs.values():
            k = math.floor(tick.t * r.frequency + 1e-6)
            if r.last_k is None and abs(tick.t * r.frequency - k) > 1e-6:
                r.last_k = k  # a slower recipe starts on its own grid
            if r.last_k is not None and k <= r.last_k:
                continue
            r.last_k = k
            self.send(D.DATA_PACKAGE, r.pack(tick))
            self.counts["data_out"] += 1


class RtdeServer:
    def __init__(self, controller: Controller, address: str, port: int, max_rate: float) -> None:
        self.controller, self.max_rate = controller, max_rate
        self.sessions: list[RtdeSession] = []
        self.lock = threading.Lock()
        self.listener = Listener(address, port, self._client, "rtde-accept")

    def _client(self, conn: socket.socket) -> None:
        conn.settimeout(0.2)  # bounds a send to a client that stopped reading
        s = RtdeSession(self, conn)
        with self.lock:
            self.sessions.append(s)
        threading.Thread(target=s.run, name="rtde-session", daemon=True).start()

    def input_taken(self, name: str, me: RtdeSession) -> bool:
        with self.lock:
            return any(name in r.names for s in self.sessions if s is not me for r in s.inputs.values())

    def drop(self, s: RtdeSession) -> None:
        drop_session(self.lock, self.sessions, s)

    def stream(self, tick: Tick) -> None:
        with self.lock:
            sessions = list(self.sessions)
        for s in sessions:
            try:
                s.stream(tick)
            except OSError:
                self.drop(s)


class DashboardServer:
    def __init__(self, controller: Controller, address: str, port: int) -> None:
        self.controller = controller
        self.listener = Listener(address, port, self._client, "dashboard-accept")

    def _client(self, conn: socket.socket) -> None:
        threading.Thread(target=self._serve, args=(conn,), name="dashboard", daemon=True).start()

    def close(self) -> None:
        self.listener.close()

    def _serve(self, conn: socket.socket) -> None:
        serve_connection(conn, lambda line: self.controller.dashboard_line(line, time.monotonic_ns()),
                         D.DASHBOARD_WELCOME)


# -- the emulator process ---------------------------------------------------------------------------------
_FINE_S = 0.00025  # the stream loop's poll near a grid point
_MARGIN_S = 0.0006  # ... which starts this long before the grid point's world time says it can come
DEFAULT_ADDRESS = "127.0.0.2"  # where an emulated controller listens unless told (scenes name no address)


class UREmulator(Emulator):
    """Servers, controller state and the stream loop, for one UR device."""

    def __init__(self, device: Any, scene: Any, link: Any, options: dict) -> None:
        p = {**device.params, **{k: options[k] for k in ("controller_version", "frequency") if k in options}}
        if scene.n_joints != 6:
            raise ValueError(f"a UR arm has 6 joints; scene {scene.name!r} has {scene.n_joints}")
        self.address = check_loopback(options.get("address") or device.address or DEFAULT_ADDRESS)
        self.version = parse_version(p.get("controller_version", "5.9"))
        version_max = 500.0 if self.version[0] >= 5 else 125.0
        self.rate = float(p.get("frequency", version_max))
        if not 0.0 < self.rate <= version_max:
            raise ValueError(f"frequency {self.rate:g} Hz: a {'e-Series' if version_max > 125 else 'CB3'} "
                             f"controller streams at most {version_max:g} Hz")
        resume = options.get("resume_after_s")
        if resume is not None and not 0.0 <= float(resume) <= 3600.0:
            raise ValueError(f"resume_after_s {resume!r}: expected seconds in [0, 3600]")
        self.kin = URKinematics(scene)
        sensor = scene.sensor
        self.flange_ft = sensor is not None and sensor.mount == "flange"
        if self.flange_ft:
            if self.version[:2] < (5, 9):  # ft_raw_wrench came with PolyScope 5.9 (UR's RTDE guide)
                raise ValueError(f"controller_version {'.'.join(map(str, self.version))}: a flange F/T sensor "
                                 "is an e-Series' and RTDE reports it (ft_raw_wrench) from 5.9")
            self.kin.check_flange_sensor(sensor.site)
        self.ft_sign = sensor.reading_sign if sensor is not None else 1.0
        super().__init__(device, scene, link, options)
        self.n = scene.n_joints
        self.controller = Controller(self.version, self.side, device.name, str(p.get("serial", "20205500001")),
                                     str(p.get("robot_model", "UR5")),
                                     resume_after_s=None if resume is None else float(resume))
        self.controller.control_loop = ControlLoopProgram(
            n=self.n, period_s=1.0 / version_max, send_goal=self._send_goal, joint_state=self._joint_state,
            pause=self.controller.watchdog_pause, max_speed=scene.robot.max_speed,
            max_acceleration=scene.robot.max_acceleration,
            registers=ControlLoopRegisters(watchdog_hz=float(self.options.get("watchdog_hz", 1.0))))
        self.thermal = ThermalModel(self.n, ambient_c=25.0, gain_c_per_a2=0.5, tau_s=900.0)
        self.rtde_port = int(self.options.get("rtde_port", D.RTDE_PORT))
        self.dashboard_port = int(self.options.get("dashboard_port", D.DASHBOARD_PORT))

    def stats(self) -> dict[str, Any]:
        return {**super().stats(), "program": dict(self.controller.control_loop.counts)}

    def _send_goal(self, q: np.ndarray, qd: np.ndarray, horizon_s: float, t_rx_ns: int) -> None:
        self.side.send(Command(self.device.name, "goal", q=tuple(float(x) for x in q),
                               extra={"qd": [float(x) for x in qd], "horizon_s": horizon_s, "t_rx_ns": t_rx_ns}))

    def _joint_state(self) -> tuple[np.ndarray, np.ndarray] | None:
        rec = self.side.joint_state()
        return None if rec is None else (rec.q.copy(), rec.qd.copy())

    def bind(self) -> dict[str, Any]:
        self.rtde = RtdeServer(self.controller, self.address, self.rtde_port, self.rate)
        self.dashboard = DashboardServer(self.controller, self.address, self.dashboard_port)
        return {**self.endpoint_base("tcp", self.address), "address": self.address, "rtde_port": self.rtde_port,
                "dashboard_port": self.dashboard_port, "frequency": self.rate,
                "controller_version": ".".join(map(str, self.version))}

    def loop(self) -> None:
        program = self.controller.control_loop
        threading.Thread(target=program.run, args=(threading.Event(),), name="ur-program", daemon=True).start()
        reader = self.side.joint_reader()
        ft = FlangeSamples(self.side.ft_reader(), self.scene.sensor.rate_hz) if self.flange_ft else None
        if ft is not None:
            self.extra_stats = ft.counts  # written with the stats
        latest = reader.latest()  # start at the next grid point, never mid-period
        last_k = math.floor(JointRecord.from_row(latest, self.n).t * self.rate + 1e-6) if latest is not None else None
        exec_ms = 0.0
        next_check = time.monotonic() + 1.0
        t_seen = None  # world time of the newest sample read
        while True:
            if time.monotonic() > next_check:
                next_check += 1.0
                self.heartbeat()  # the world's process is gone: so are we
            for rec in reader.new():
                t_seen = float(rec[0])  # most samples fall between grid points (at 7 kHz, 13 of 14 for 500 Hz)
                k = math.floor(t_seen * self.rate + 1e-6)
                if last_k is None and abs(t_seen * self.rate - k) > 1e-6:
                    last_k = k  # the first sample is off the grid: wait for the next grid point
                if last_k is not None and k <= last_k:
                    continue
                last_k = k
                joints = JointRecord.from_row(rec, self.n)
                t0 = time.perf_counter()
                temps = self.thermal.update(joints.t, joints.current)
                wrench = None if ft is None else ft.at(joints.t)
                self.rtde.stream(Tick(joints, self.controller, self.kin, temps, exec_ms, wrench, self.ft_sign))
                exec_ms = (time.perf_counter() - t0) * 1e3
            time.sleep(self._pause(t_seen, last_k))

    def _pause(self, t_seen: float | None, last_k: int | None) -> float:
        """How long to sleep before looking again: finely (0.25 ms) near the next grid point, and until
        near it when it is further off. The world never publishes a sample before its time, so the
        next grid sample is at least its distance in world time from the newest one away; the margin
        covers how late that newest one was read."""
        if t_seen is None or last_k is None:
            return _FINE_S
        ahead_s = (last_k + 1) / self.rate - t_seen
        return max(_FINE_S, ahead_s - _MARGIN_S)


def serve(device: Any, scene: Any, link: Any, ready: Any, options: dict) -> None:
    """The emulator process: bind, report the endpoint on ``ready``, stream until terminated."""
    serve_with(UREmulator, device, scene, link, ready, options)
