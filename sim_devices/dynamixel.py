"""DYNAMIXEL Protocol 2.0 emulator: a chain of X-series servos on a pty, driving the world's joints.

The emulator owns the pty master; clients open the slave through a stable symlink
(``/tmp/ftc-<scene>-<device>-<world pid>.tty`` unless ``options["path"]`` names one), re-pointed on
every (re)start so that an adapter can reopen the same path. Servo ``ids[i]`` is joint ``i`` of the
scene's ``[robot] joints``.

Instructions: ping (unicast and broadcast), read, write, reg write + action, factory reset, reboot,
clear, sync read/write, fast sync read, bulk read/write, fast bulk read. Status packets carry the
error number of the protocol (CRC error for a damaged packet addressed to a servo, instruction error
for an unknown instruction or an action without reg write, data length error for parameters of the
wrong size, and the control table's access/range/limit errors, see ``dxl_servo``) and the alert bit
while Hardware Error Status is non-zero. Broadcast instructions get no status (except ping), and the
Status Return Level is honoured. A servo answers only when the pty's baud rate (as the client set it)
equals its Baud Rate item, and not while it reboots.

World: present position, velocity and current come from the world's newest joint sample (current is
the world's motor current); Present Temperature from a thermal model on that current. Goal Position
writes (position modes, torque on) become ``Command("goal")`` for all joints (joints without a goal
keep their present angle); Torque Enable becomes ``Command("torque")`` -- the world has one torque
switch, on while any servo's torque is on. Enabling torque sets Goal Position to Present Position.
Not emulated: velocity/current/PWM control modes (goals stored, the world not driven), profiles,
Drive Mode (normal direction always), Bus Watchdog, Shutdown conditions at run time
(``options["hardware_error"]`` sets Hardware Error Status at start: torque off, alert bit, reboot
clears it).

Bus time (on by default): a pty moves bytes at once, a DYNAMIXEL bus at its baud rate, half duplex. Each
instruction packet is taken to end ``bytes x 10 / baud`` after the bus was last free (its arrival, or the
end of the previous packet); an instruction without an answer (Sync Write, a broadcast) reaches the
world only then, and each status packet is written once its Return Delay Time (the servo's
control table, 2 us units, factory 250 = 500 us) and its own ``bytes x 10 / baud`` have passed, so that a
client sees what a real chain allows (a Sync Read of 10 bytes from 5 servos at 1 Mbit/s: 124 bytes,
1.24 ms, about 806 a second). The device param ``bus_time = false`` (or ``options["bus_time"]``) turns
it off, Return Delay Time included, for speed tests: answers then go out as soon as they are made.

Options: ``path``, ``bus_time`` (bool, overrides the device param), ``return_delay_us`` (overrides every
servo's Return Delay Time),
``reboot_s`` (silence after a reboot, default 0.1 s), ``hardware_error`` ({id: bits}),
``torque_on`` (default True: the world starts under joint control, as if a controller had enabled
torque).
"""
from __future__ import annotations

import contextlib
import os
import select
import termios
import time
import tty
from collections.abc import Callable
from typing import Any

import numpy as np

from ftc_hw.codecs.dxl_table import (
    ACTION,
    BAUD_CODES,
    BAUD_RATES,
    BROADCAST_ID,
    BULK_READ,
    BULK_WRITE,
    CLEAR,
    ERR_ALERT,
    ERR_CRC,
    ERR_DATA_LENGTH,
    ERR_DATA_RANGE,
    ERR_INSTRUCTION,
    ERR_RESULT_FAIL,
    FACTORY_RESET,
    FAST_BULK_READ,
    FAST_SYNC_READ,
    MODELS,
    PING,
    READ,
    REBOOT,
    REG_WRITE,
    SYNC_READ,
    SYNC_WRITE,
    WRITE,
)

from .dxl_protocol import Instruction, PacketReader, fast_status, status
from .dxl_servo import Servo
from .emulator import Emulator, serve_with
from .link import Command, EmulatorSide
from .thermal import ThermalModel

Reply = tuple[Servo, bytes]
PACKET_GAP_S = 0.01  # an incomplete packet is dropped after this much silence

_TERMIOS_BAUD = {getattr(termios, f"B{b}"): b for b in
                 (9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600, 1000000, 1152000,
                  2000000, 2500000, 3000000, 3500000, 4000000) if hasattr(termios, f"B{b}")}


class WorldPort:
    """The servos' view of the world: joint state in, commands out."""

    def __init__(self, side: EmulatorSide | None, n_joints: int, source: str) -> None:
        self.side = side
        self.n = n_joints
        self.source = source
        self.sent: list[Command] = []

    def state(self) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        s = self.side.joint_state() if self.side is not None else None
        if s is None:
            z = np.zeros(self.n)
            return 0.0, z, z, z
        return s.t, s.q, s.qd, s.current

    def send(self, cmd: Command) -> None:
        self.sent.append(cmd)
        if self.side is not None:
            self.side.send(cmd)


class DxlBus:
    """The servos of one chain and the instruction handling; transport-free (``handle`` returns replies)."""

    def __init__(self, servos: list[Servo], world: WorldPort, *, reboot_s: float = 0.1,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.servos = servos
        self.world = world
        self.reboot_s = reboot_s
        self.clock = clock
        self.t0 = clock()
        self.thermal = ThermalModel(len(servos), ambient_c=25.0, gain_c_per_a2=2.0, tau_s=300.0)
        self.goal_q: list[float | None] = [None] * world.n
        self._world_torque = True  # the world starts under joint control
        self._goal_dirty = False
        self.line_baud: int | None = None  # the pty's baud rate as the client set it (None: unknown)
        self.t_rx_ns = 0  # when the instruction being handled was read off the line (monotonic ns)
        self.counts: dict[str, int] = {}
        self._handlers = {PING: self._ping, READ: self._read, WRITE: self._write, REG_WRITE: self._reg_write,
                          ACTION: self._action, FACTORY_RESET: self._factory_reset, REBOOT: self._reboot,
                          CLEAR: self._clear, SYNC_READ: self._sync_read, FAST_SYNC_READ: self._sync_read,
                          SYNC_WRITE: self._sync_write, BULK_READ: self._bulk_read, FAST_BULK_READ: self._bulk_read,
                          BULK_WRITE: self._bulk_write}

    # -- helpers ---------------------------------------------------------------------------------------
    def _by_id(self, dxl_id: int) -> Servo | None:
        for s in self.servos:
            if s.id == dxl_id and self._listening(s):
                return s
        return None

    def _listening(self, s: Servo) -> bool:
        if self.clock() < s.booting_until:
            return False
        return self.line_baud is None or BAUD_RATES.get(s.get("Baud Rate")) == self.line_baud

    def _answers(self, s: Servo, kind: str) -> bool:
        level = s.get("Status Return Level")
        return kind == "ping" or level == 2 or (level == 1 and kind == "read")

    @staticmethod
    def _err(s: Servo, number: int = 0) -> int:
        return number | (ERR_ALERT if s.get("Hardware Error Status") else 0)

    def _status(self, s: Servo, number: int = 0, params: bytes = b"") -> Reply:
        return s, status(s.id, self._err(s, number), params)

    def _refresh(self) -> None:
        t, q, qd, cur = self.world.state()
        joints = [s.joint for s in self.servos]
        temps = self.thermal.update(t, cur[joints])
        tick = int((self.clock() - self.t0) * 1000.0)
        for s, temp in zip(self.servos, temps, strict=True):
            s.refresh(float(q[s.joint]), float(qd[s.joint]), float(cur[s.joint]), tick, float(temp))

    @staticmethod
    def _needs_present(address: int, length: int) -> bool:
        """Does a write there need fresh present values (Torque Enable sets Goal := Present; indirect
        data may point anywhere)?"""
        end = address + length
        return address <= 64 < end or (address < 252 and end > 224) or (address < 662 and end > 634)

    def _apply_write(self, s: Servo, address: int, data: bytes) -> int:
        err, fx = s.write(address, data, hardware_error=bool(s.get("Hardware Error Status")))
        if fx.goal:
            self.goal_q[s.joint] = s.angle(s.get("Goal Position"))
            self._goal_dirty = True
        return err

    # -- dispatch ----------------------------------------------------------------------------------------
    def handle(self, ins: Instruction) -> list[Reply]:
        """The status packets ``ins`` asks for, in bus order; world commands are sent by ``flush()``."""
        key = f"inst_{ins.instruction:#04x}" if ins.crc_ok else "crc_errors"
        self.counts[key] = self.counts.get(key, 0) + 1
        if not ins.crc_ok:
            s = self._by_id(ins.id)
            return [self._status(s, ERR_CRC)] if s is not None else []
        handler = self._handlers.get(ins.instruction)
        if handler is None:
            s = self._by_id(ins.id)
            return [self._status(s, ERR_INSTRUCTION)] if s is not None and self._answers(s, "other") else []
        return handler(ins)

    def flush(self) -> None:
        """Tell the world what the last instructions changed (torque first, then goals)."""
        on = any(s.torque_on for s in self.servos)
        if on != self._world_torque:
            self._world_torque = on
            self.world.send(Command(self.world.source, "torque", on=on, extra={"t_rx_ns": self.t_rx_ns}))
            if on:
                self.goal_q = [None] * self.world.n
        if self._goal_dirty:
            self._goal_dirty = False
            q = self.world.state()[1] if None in self.goal_q else None
            goal = [float(q[j]) if g is None else g for j, g in enumerate(self.goal_q)]
            self.goal_q = list(goal)
            self.world.send(Command(self.world.source, "goal", q=tuple(goal), extra={"t_rx_ns": self.t_rx_ns}))

    # -- instructions --------------------------------------------------------------------------------------
    def _ping(self, ins: Instruction) -> list[Reply]:
        targets = sorted((s for s in self.servos if self._listening(s)), key=lambda s: s.id) \
            if ins.id == BROADCAST_ID else [s for s in [self._by_id(ins.id)] if s is not None]
        m = [(s, s.get("Model Number").to_bytes(2, "little") + bytes([s.get("Firmware Version")])) for s in targets]
        return [self._status(s, 0, p) for s, p in m]

    def _read(self, ins: Instruction) -> list[Reply]:
        s = self._by_id(ins.id)
        if s is None or not self._answers(s, "read"):
            return []
        if len(ins.params) != 4:
            return [self._status(s, ERR_DATA_LENGTH)]
        self._refresh()
        err, data = s.read(int.from_bytes(ins.params[:2], "little"), int.from_bytes(ins.params[2:], "little"))
        return [self._status(s, err, data)]

    def _write(self, ins: Instruction) -> list[Reply]:
        p = ins.params
        targets = [s for s in self.servos if self._listening(s)] if ins.id == BROADCAST_ID else \
            [s for s in [self._by_id(ins.id)] if s is not None]
        out = []
        for s in targets:
            if len(p) < 3:
                err = ERR_DATA_LENGTH
            else:
                address = int.from_bytes(p[:2], "little")
                if self._needs_present(address, len(p) - 2):
                    self._refresh()
                err = self._apply_write(s, address, p[2:])
            if ins.id != BROADCAST_ID and self._answers(s, "other"):
                out.append(self._status(s, err))
        return out

    def _reg_write(self, ins: Instruction) -> list[Reply]:
        s = self._by_id(ins.id)
        if s is None:
            return []
        err = ERR_DATA_LENGTH if len(ins.params) < 3 else 0
        if not err:
            s.registered = (int.from_bytes(ins.params[:2], "little"), ins.params[2:])
            s.set("Registered Instruction", 1)
        return [self._status(s, err)] if self._answers(s, "other") else []

    def _action(self, ins: Instruction) -> list[Reply]:
        targets = [s for s in self.servos if self._listening(s)] if ins.id == BROADCAST_ID else \
            [s for s in [self._by_id(ins.id)] if s is not None]
        out = []
        for s in targets:
            if s.registered is None:
                err = ERR_INSTRUCTION
            else:
                self._refresh()
                err = self._apply_write(s, *s.registered)
                s.registered = None
                s.set("Registered Instruction", 0)
            if ins.id != BROADCAST_ID and self._answers(s, "other"):
                out.append(self._status(s, err))
        return out

    def _factory_reset(self, ins: Instruction) -> list[Reply]:
        if ins.id == BROADCAST_ID:  # "Reset all" to the broadcast ID is not executed (firmware 42+)
            if ins.params[:1] != b"\xff":
                for s in self.servos:
                    s.factory_reset(ins.params[0] if ins.params else 0x01)
            return []
        s = self._by_id(ins.id)
        if s is None:
            return []
        if len(ins.params) != 1 or ins.params[0] not in (0x01, 0x02, 0xFF):
            return [self._status(s, ERR_DATA_RANGE)]
        reply = self._status(s)
        s.factory_reset(ins.params[0])
        return [reply]

    def _reboot(self, ins: Instruction) -> list[Reply]:
        s = self._by_id(ins.id)
        if s is None:
            return []
        reply = self._status(s)  # answered before the reboot
        s.reset_ram()
        s.registered = None
        s.booting_until = self.clock() + self.reboot_s
        self.goal_q[s.joint] = None
        return [reply]

    def _clear(self, ins: Instruction) -> list[Reply]:
        s = self._by_id(ins.id)
        if s is None:
            return []
        if ins.params != b"\x01\x44\x58\x4c\x22":
            return [self._status(s, ERR_DATA_RANGE if len(ins.params) == 5 else ERR_DATA_LENGTH)]
        self._refresh()
        if s.get("Moving"):
            return [self._status(s, ERR_RESULT_FAIL)]
        present = s.get("Present Position")
        s.turn_offset -= present - present % s.model.ticks_per_rev
        return [self._status(s)]

    def _sync_read(self, ins: Instruction) -> list[Reply]:
        p = ins.params
        if ins.id != BROADCAST_ID or len(p) < 5:
            return []
        address, length = int.from_bytes(p[0:2], "little"), int.from_bytes(p[2:4], "little")
        self._refresh()
        found = [s for s in (self._by_id(i) for i in p[4:]) if s is not None and self._answers(s, "read")]
        if ins.instruction == FAST_SYNC_READ:
            blocks = []
            for s in found:
                err, data = s.read(address, length)
                blocks.append((self._err(s, err), s.id, data.ljust(length, b"\x00")[:length]))
            return [(found[0], fast_status(blocks))] if found else []
        return [self._status(s, *s.read(address, length)) for s in found]

    def _bulk_read(self, ins: Instruction) -> list[Reply]:
        p = ins.params
        if ins.id != BROADCAST_ID or not p or len(p) % 5:
            return []
        self._refresh()
        entries = []
        for k in range(0, len(p), 5):
            s = self._by_id(p[k])
            if s is not None and self._answers(s, "read"):
                entries.append((s, int.from_bytes(p[k + 1:k + 3], "little"), int.from_bytes(p[k + 3:k + 5], "little")))
        if ins.instruction == FAST_BULK_READ:
            blocks = []
            for s, address, length in entries:
                err, data = s.read(address, length)
                blocks.append((self._err(s, err), s.id, data.ljust(length, b"\x00")[:length]))
            return [(entries[0][0], fast_status(blocks))] if entries else []
        return [self._status(s, *s.read(address, length)) for s, address, length in entries]

    def _sync_write(self, ins: Instruction) -> list[Reply]:
        p = ins.params
        if ins.id != BROADCAST_ID or len(p) < 4:
            return []
        address, length = int.from_bytes(p[0:2], "little"), int.from_bytes(p[2:4], "little")
        if length < 1 or (len(p) - 4) % (length + 1):
            return []
        if self._needs_present(address, length):
            self._refresh()
        for k in range(4, len(p), length + 1):
            s = self._by_id(p[k])
            if s is not None:
                self._apply_write(s, address, p[k + 1:k + 1 + length])
        return []

    def _bulk_write(self, ins: Instruction) -> list[Reply]:
        p = ins.params
        if ins.id != BROADCAST_ID:
            return []
        self._refresh()
        k = 0
        while k + 5 <= len(p):
            address, length = int.from_bytes(p[k + 1:k + 3], "little"), int.from_bytes(p[k + 3:k + 5], "little")
            s = self._by_id(p[k])
            if s is not None and k + 5 + length <= len(p):
                self._apply_write(s, address, p[k + 5:k + 5 + length])
            k += 5 + length
        return []


# -- the pty transport --------------------------------------------------------------------------------------
def _wait_until(deadline: float) -> None:
    """Sleep until ``deadline`` (perf_counter). No busy wait: on a shared host a spinning emulator takes the
    core from the client it serves; a late wake-up (tens of us) delays one packet, and the next packets keep
    the schedule, so lateness does not add up."""
    left = deadline - time.perf_counter()
    if left > 0:
        time.sleep(left)


class PtyTransport:
    """Owns a pty pair: the master end is the bus; ``path`` is a symlink to the slave for clients."""

    def __init__(self, path: str, *, bus_time: bool = True) -> None:
        if os.path.exists(path) and not os.path.islink(path):
            raise FileExistsError(f"{path} exists and is no symlink: not replacing it")
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.slave_name = os.ttyname(self.slave)
        self.path = path
        tmp = f"{path}.{os.getpid()}.tmp"
        os.symlink(self.slave_name, tmp)
        os.replace(tmp, path)
        self.bus_time = bus_time
        self.bus_free_at = 0.0  # perf_counter time when the last packet on the bus ends

    def line_baud(self) -> int | None:
        return _TERMIOS_BAUD.get(termios.tcgetattr(self.slave)[5])

    def serve(self, bus: DxlBus, heartbeat: Callable[[], None]) -> None:
        """Answer the instructions on the line; ``heartbeat()`` whenever it is quiet (it ends the
        process once the world's is gone)."""
        reader = PacketReader()
        while True:
            ready, _, _ = select.select([self.master], [], [], PACKET_GAP_S if reader.pending else 0.5)
            if not ready:
                if reader.pending:
                    reader.expire()
                else:
                    heartbeat()
                continue
            data = os.read(self.master, 4096)
            t_rx = time.perf_counter()
            bus.t_rx_ns = time.monotonic_ns()
            for ins in reader.feed(data):
                bus.line_baud = self.line_baud()
                replies = bus.handle(ins)
                self._send(replies, t_rx, len(ins.raw), bus.line_baud)
                bus.flush()

    def _send(self, replies: list[Reply], t_rx: float, request_bytes: int, baud: int | None) -> None:
        if not self.bus_time:
            for _, frame in replies:
                os.write(self.master, frame)
            return
        byte_s = 10.0 / (baud or 1_000_000)  # 8N1: a start bit, 8 data bits, a stop bit
        t = max(t_rx, self.bus_free_at) + request_bytes * byte_s
        if not replies:  # a Sync Write, a broadcast: the servos act once the whole instruction is in
            _wait_until(t)
        for servo, frame in replies:
            t += servo.get("Return Delay Time") * 2e-6 + len(frame) * byte_s
            _wait_until(t)
            os.write(self.master, frame)
        self.bus_free_at = t

    def close(self) -> None:
        try:
            if os.path.islink(self.path) and os.readlink(self.path) == self.slave_name:
                os.unlink(self.path)
        except OSError:
            pass
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)


# -- the emulator process ------------------------------------------------------------------------------------
def build_servos(device: Any, n_joints: int, options: dict) -> list[Servo]:
    p = device.params
    if float(p.get("protocol", 2.0)) != 2.0:
        raise ValueError(f"only DYNAMIXEL protocol 2.0 is emulated, not {p.get('protocol')}")
    model_name = p.get("model", "XM430-W350")
    if model_name not in MODELS:
        raise ValueError(f"unknown servo model {model_name!r} (known: {', '.join(MODELS)})")
    ids = [int(i) for i in p.get("ids", [])]
    if not ids or len(set(ids)) != len(ids) or not all(0 <= i <= 252 for i in ids) or len(ids) > n_joints:
        raise ValueError(f"ids must be 1..{n_joints} distinct numbers in 0..252, got {ids}")
    baud = int(p.get("baudrate", 57600))
    if baud not in BAUD_CODES:
        raise ValueError(f"baud rate {baud} is not one of the X series' {sorted(BAUD_CODES)}")
    model = MODELS[model_name]
    zeros = p.get("zero_ticks", [model.center_tick] * len(ids))
    dirs = p.get("directions", [1] * len(ids))
    eeprom = {"Baud Rate": BAUD_CODES[baud]}
    if "return_delay_time" in p:
        eeprom["Return Delay Time"] = int(p["return_delay_time"])
    if "return_delay_us" in options:
        eeprom["Return Delay Time"] = round(float(options["return_delay_us"]) / 2.0)
    servos = [Servo(model, i, j, zero_tick=int(zeros[j]), direction=int(dirs[j]), eeprom=eeprom)
              for j, i in enumerate(ids)]
    errors = {int(k): int(v) for k, v in (options.get("hardware_error") or {}).items()}
    for s in servos:
        if options.get("torque_on", True) and s.id not in errors:
            s.set("Torque Enable", 1)
        s.set("Hardware Error Status", errors.get(s.id, 0))
    return servos


def default_path(scene_name: str, device_name: str) -> str:
    return f"/tmp/ftc-{scene_name}-{device_name}-{os.getppid()}.tty"


class DynamixelEmulator(Emulator):
    """A chain of servos on a pty (``options``: the module's)."""

    def __init__(self, device: Any, scene: Any, link: Any, options: dict) -> None:
        servos = build_servos(device, scene.n_joints, options)
        super().__init__(device, scene, link, options)
        self.servos = servos
        world = WorldPort(self.side, scene.n_joints, device.name)
        self.bus = DxlBus(servos, world, reboot_s=float(self.options.get("reboot_s", 0.1)))
        state = self.side.joint_state()
        if state is not None:  # the goal registers start where the arm is
            for s in servos:
                s.refresh(float(state.q[s.joint]), 0.0, 0.0, 0, 25.0)
                s.set("Goal Position", s.get("Present Position"))
        self.bus.flush()  # torque off in the world if no servo starts with torque on
        self.transport: PtyTransport | None = None

    def bind(self) -> dict[str, Any]:
        path = self.options.get("path") or default_path(self.scene.name, self.device.name)
        on = self.options.get("bus_time", self.device.params.get("bus_time", True))
        self.transport = PtyTransport(path, bus_time=bool(on))
        return {**self.endpoint_base("serial", self.transport.path), "pty": self.transport.slave_name,
                "protocol": 2.0, "baudrate": int(self.device.params.get("baudrate", 57600)),
                "bus_time": self.transport.bus_time,
                "ids": [s.id for s in self.servos], "model": self.servos[0].model.name}

    def loop(self) -> None:
        self.transport.serve(self.bus, self.heartbeat)

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()


def serve(device: Any, scene: Any, link: Any, ready: Any, options: dict) -> None:
    """The emulator process: bind the pty, report the endpoint on ``ready``, serve until terminated."""
    serve_with(DynamixelEmulator, device, scene, link, ready, options)
