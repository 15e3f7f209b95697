"""DYNAMIXEL arm adapter (Protocol 2.0, dynamixel_sdk): joint state on ``joints/<name>``, goals, torque, stop.

Every cycle (``rate_hz``, default 500 Hz, as fast as the bus allows when it cannot keep up) one group
Sync Read (or Fast Sync Read, ``fast_read=True``) of Present Current .. Present Position (126..135) for
all servos, converted to SI in the scene's joint convention: ``q = direction * (ticks - zero_tick) *
2 pi / 4096`` (Homing Offset assumed 0), ``qd = direction * units * 0.229 rpm``, ``current = direction *
units * 2.69 mA`` and ``tau = torque_constant * current`` (the servo model's constant unless given).
DYNAMIXEL servos send no timestamp: ``t_device_ns`` is None and ``t_host_ns`` is the host time at
which the Sync Read's last status packet was received (the samples are about half a transaction older).

Each status packet is checked for its servo's ID *and* the expected length (dynamixel_sdk's own
group reads check the ID only): after a timeout, a late answer to an earlier request would otherwise
be read as the next request's -- a torque state read as a position, which a stop() then commands.
After a failed transaction the adapter waits 2 ms and flushes the input.

Health: a cycle that fails (timeout, corrupt answer) is counted; with no good cycle for
``stale_after`` s a ``stale`` event is published (``recovered`` on the next good one); after
``dead_after`` s, or at once when the port fails (pty or USB adapter gone), the link is declared
broken and reopened with backoff (the base class). Hardware Error Status is polled every
``error_poll_s`` and a change published as an ``error`` event.

``stop()``, the monitor's reflex: a Sync Write of Goal Position := Present Position (the cyclic
read's, or a fresh one when that is older than two cycles) to every servo -- the servos hold where
they are, torque stays on (a torque-off "stop" would let the arm fall). One bus transaction, and the
servos answer none; it waits only for a transaction the reader has in flight (a half-duplex bus).

The reader sleeps on the port until the answer arrives (``select``) instead of letting
dynamixel_sdk's rxPacket poll the non-blocking port in a busy loop: the spinning took the CPU the
answer (and, on a loaded host, the stop) needed.
"""
from __future__ import annotations

import contextlib
import select
import threading
import time
from collections.abc import Iterator, Sequence
from typing import Any

import dynamixel_sdk as sdk
import numpy as np
import serial

from ftc_hw.bus import Bus, JointFrame, joints_topic
from ftc_hw.codecs.dxl_table import MODELS, PRESENT_LENGTH, PRESENT_START

from .arm_base import ArmAdapter
from .base import DeviceError, DeviceIOError

DEFAULT_MODEL = "XM430-W350"  # a scene's servo model when it names none

try:
    import termios

    _PORT_ERRORS: tuple[type[BaseException], ...] = (OSError, serial.SerialException, termios.error)
except ImportError:  # Windows: pyserial raises SerialException / OSError only
    _PORT_ERRORS = (OSError, serial.SerialException)

_HW_ERROR_NAMES = {1: "input voltage", 4: "overheating", 8: "motor encoder", 16: "electrical shock", 32: "overload"}


def _signed(value: int, bits: int) -> int:
    return value - (1 << bits) if value & (1 << (bits - 1)) else value


class DynamixelArm(ArmAdapter):
    kind = "dynamixel"
    moves_on_goals = True

    def __init__(self, name: str, bus: Bus, port: str, ids: Sequence[int], *, model: str = DEFAULT_MODEL,
                 baudrate: int = 1_000_000, zero_ticks: Sequence[int] | None = None,
                 directions: Sequence[int] | None = None, torque_constant: Sequence[float] | float | None = None,
                 rate_hz: float = 500.0, fast_read: bool = False, stale_after: float = 0.05,
                 dead_after: float = 0.5, error_poll_s: float = 0.5, latency_timer_ms: int | None = None,
                 reconnect_backoff: tuple[float, float] = (0.05, 0.5)) -> None:
        super().__init__(name, bus, reconnect_backoff=reconnect_backoff)
        if model not in MODELS:
            raise DeviceError(f"unknown DYNAMIXEL model {model!r} (known: {', '.join(MODELS)})")
        self.model = MODELS[model]
        self.port_name = port
        self.ids = [int(i) for i in ids]
        n = len(self.ids)
        self.baudrate = int(baudrate)
        self.zero = np.array(zero_ticks if zero_ticks is not None else [self.model.center_tick] * n, dtype=float)
        self.direction = np.array(directions if directions is not None else [1] * n, dtype=float)
        kt = self.model.torque_constant if torque_constant is None else torque_constant
        self.torque_constant = np.broadcast_to(np.asarray(kt, dtype=float), (n,)).copy()
        self.period = 1.0 / float(rate_hz)
        self.fast_read = fast_read
        self.stale_after = stale_after
        self.dead_after = dead_after
        self.error_poll_s = error_poll_s
        self.latency_timer_ms = latency_timer_ms
        self.topic = joints_topic(name)
        self.hardware_errors: dict[int, int] = {}
        self.latest_ticks: np.ndarray | None = None
        self.stop_position_age_s: float | None = None
        self._port: Any = None
        self._ph: Any = None
        self._io = threading.RLock()  # one bus transaction at a time (the reader, stop(), commands)
        self._seq = 0
        self._next = 0.0
        self._last_ok = 0.0
        self._next_error_poll = 0.0

    @classmethod
    def from_spec(cls, spec: Any, bus: Bus, endpoint: dict | str | None = None, *, scene: Any = None,
                  **overrides: Any) -> DynamixelArm:
        """From a scene's ``[[devices]]`` entry; ``endpoint``: ``ftc sim``'s endpoint dict or a port path
        (default: the spec's ``address``). ``scene`` is accepted for a uniform factory signature: the
        torque constant is the servo model's (or the device's ``torque_constant``)."""
        p = dict(spec.params)
        port = endpoint.get("endpoint") if isinstance(endpoint, dict) else endpoint
        port = port or spec.address
        if not port:
            raise DeviceError(f"device {spec.name!r}: no serial port (give an endpoint or an address)")
        keys = ("model", "baudrate", "zero_ticks", "directions", "torque_constant", "rate_hz", "fast_read",
                "stale_after", "dead_after", "error_poll_s", "latency_timer_ms")
        kwargs = {k: p[k] for k in keys if k in p}
        kwargs.update(overrides)
        return cls(spec.name, bus, port, p["ids"], **kwargs)

    def describe(self) -> str:
        return f"{self.kind} {self.model.name} x{len(self.ids)} on {self.port_name} at {self.baudrate} bps"

    # -- link -------------------------------------------------------------------------------------------
    def _connect(self) -> None:
        if self.latency_timer_ms is not None:
            sdk.port_handler.LATENCY_TIMER = self.latency_timer_ms  # module-wide in dynamixel_sdk
        port = sdk.PortHandler(self.port_name)
        try:
            if not port.openPort() or not port.setBaudRate(self.baudrate):
                raise DeviceIOError(f"cannot open {self.port_name} at {self.baudrate} bps")
        except (OSError, serial.SerialException) as exc:
            raise DeviceIOError(f"cannot open {self.port_name}: {exc}") from exc
        port.ser.write_timeout = 0.1  # a hung device must not block us in write()
        ph = sdk.PacketHandler(2.0)
        self._port, self._ph = port, ph
        with self._io:
            for i in self.ids:
                for _ in range(3):  # a device that is just starting answers soon: not worth a backoff
                    number, res, _ = self._guard(ph.ping, port, i)
                    if res == sdk.COMM_SUCCESS:
                        break
                    self._resync()
                if res != sdk.COMM_SUCCESS:
                    raise DeviceIOError(f"servo {i} does not answer ping: {ph.getTxRxResult(res)}")
                if number != self.model.model_number:
                    raise DeviceError(f"servo {i} is model number {number}, not {self.model.name} "
                                      f"({self.model.model_number})")
        self.latest_ticks = None  # nothing read on this link yet
        self._last_ok = self._next = time.monotonic()
        self._next_error_poll = self._last_ok

    def _disconnect(self) -> None:
        port, self._port = self._port, None
        if port is not None and port.ser is not None:
            port.closePort()

    def _guard(self, fn: Any, *args: Any) -> Any:
        """Run one SDK call; a failing port (pty closed, adapter unplugged) is a broken link. The SDK
        flushes the input (termios) before every packet it sends: on a port that is gone that raises
        termios.error, which is no OSError."""
        try:
            return fn(*args)
        except _PORT_ERRORS as exc:
            if self._port is not None:
                self._port.is_using = False
            raise DeviceIOError(f"{self.port_name}: {exc}") from exc

    # -- the reader loop ----------------------------------------------------------------------------------
    def _read_once(self) -> None:
        now = time.monotonic()
        if now < self._next and self._stop.wait(self._next - now):
            return
        self._next = max(self._next + self.period, time.monotonic())
        self._stale_on_failure(self._cycle)

    def _sync_read(self, address: int, size: int) -> tuple[int, dict[int, bytes], int]:
        """One Sync Read (or Fast Sync Read) of ``size`` bytes at ``address`` from every servo: (result,
        data per id, OR of the status error bytes). Unlike GroupSyncRead this checks every status
        packet's ID *and length*, so a late answer to an earlier, timed-out request is skipped instead
        of being read as this one's (dynamixel_sdk's readRx checks the ID only)."""
        port, ph, ids = self._port, self._ph, self.ids
        res = self._guard(ph.syncReadTx, port, address, size, ids, len(ids), self.fast_read)
        if res != sdk.COMM_SUCCESS:
            return res, {}, 0
        out: dict[int, bytes] = {}
        errors = 0
        if self.fast_read:
            while True:
                self._wait_readable()
                pkt, res = self._guard(ph.rxPacket, port, True)
                if res != sdk.COMM_SUCCESS:
                    return res, {}, 0
                if pkt[4] == sdk.BROADCAST_ID and (pkt[5] | pkt[6] << 8) == 1 + len(ids) * (size + 4):
                    break
                self.counters["stray_packets"] += 1
            for k, i in enumerate(ids):
                block = pkt[8 + k * (size + 4):8 + (k + 1) * (size + 4)]
                if block[1] != i:
                    return sdk.COMM_RX_CORRUPT, {}, 0
                errors |= block[0]
                out[i] = bytes(block[2:2 + size])
            return res, out, errors
        for i in ids:
            port.is_using = True  # rxPacket releases the port after each packet
            while True:
                self._wait_readable()
                pkt, res = self._guard(ph.rxPacket, port, False)
                if res != sdk.COMM_SUCCESS:
                    return res, {}, 0
                if pkt[4] == i and (pkt[5] | pkt[6] << 8) == size + 4:
                    break
                port.is_using = True
                self.counters["stray_packets"] += 1
            errors |= pkt[8]
            out[i] = bytes(pkt[9:9 + size])
        return res, out, errors

    def _wait_readable(self) -> None:
        """Sleep until the port has input or the SDK's packet timeout has passed. rxPacket polls a
        non-blocking port in a busy loop: spinning while the servos answer takes a CPU from whatever
        produces the answer (on a loaded host, the emulator, the world, the caller of stop())."""
        port = self._port
        left = (port.packet_timeout - port.getTimeSinceStart()) / 1000.0
        if left > 0:
            self._guard(select.select, [port.ser.fileno()], [], [], left)

    def _resync(self) -> None:
        """After a failed transaction: let late answers arrive, then drop them."""
        time.sleep(0.002)
        self._guard(self._port.clearPort)

    def _cycle(self) -> None:
        with self._io:
            res, data, errors = self._sync_read(PRESENT_START, PRESENT_LENGTH)
            t_ns = time.monotonic_ns()
            if res != sdk.COMM_SUCCESS:
                self._resync()
            else:  # under the lock: a stop() that waited for this transaction holds its position
                cur, vel, ticks = (np.array([np.frombuffer(data[i][a:b], fmt)[0] for i in self.ids], dtype=float)
                                   for a, b, fmt in ((0, 2, "<i2"), (2, 6, "<i4"), (6, 10, "<i4")))
                self.latest_ticks = ticks
                self._last_ok = t_ns / 1e9
        now = t_ns / 1e9
        if res != sdk.COMM_SUCCESS:
            self.counters["read_failures"] += 1
            self.counters[f"comm_{res}"] += 1
            if now - self._last_ok > self.stale_after:
                self._mark_stale(f"no good Sync Read for {now - self._last_ok:.3f} s (last: {res})")
            if now - self._last_ok > self.dead_after:
                raise DeviceIOError(f"no answer for {now - self._last_ok:.3f} s")
            return
        m = self.model
        current = self.direction * cur * m.current_unit_a
        frame = JointFrame.make(t_ns, self.direction * (ticks - self.zero) * m.rad_per_tick,
                                self.direction * vel * m.rad_s_per_unit, current, self.torque_constant * current,
                                source=self.name, seq=self._seq)
        self._seq += 1
        self.counters["frames"] += 1
        self.bus.publish(self.topic, frame)
        self._mark_fresh("Sync Read answers again")
        if now >= self._next_error_poll or (errors & 0x80 and not self.hardware_errors):
            self._next_error_poll = now + self.error_poll_s
            self._poll_hardware_errors()

    def _poll_hardware_errors(self) -> None:
        errors = self.read_item(70, 1)
        if errors is None:
            return
        changed = {i: e for i, e in errors.items() if e != self.hardware_errors.get(i, 0)}
        self.hardware_errors = errors
        for i, e in changed.items():
            names = [n for bit, n in _HW_ERROR_NAMES.items() if e & bit] or ["none"]
            self.counters["hardware_errors"] += bool(e)
            self.event("error", f"servo {i}: Hardware Error Status {e:#04x} ({', '.join(names)})")

    # -- commands ----------------------------------------------------------------------------------------
    def _require_link(self) -> None:
        if self._port is None or not self.connected.is_set():
            raise DeviceError(f"{self.name}: not connected")

    def read_item(self, address: int, size: int, attempts: int = 3) -> dict[int, int] | None:
        """A Sync Read of an item (``size`` 1, 2 or 4 bytes, unsigned) from every servo, tried up to
        ``attempts`` times; None if every attempt failed."""
        self._require_link()
        for _ in range(attempts):
            with self._io:
                res, data, _ = self._sync_read(address, size)
                if res == sdk.COMM_SUCCESS:
                    return {i: int.from_bytes(d, "little") for i, d in data.items()}
                self._resync()
            self.counters["command_read_failures"] += 1
        return None

    def write_item(self, address: int, size: int, values: dict[int, int]) -> None:
        """One Sync Write (no answer) of an item to the given servos."""
        self._require_link()
        group = sdk.GroupSyncWrite(self._port, self._ph, address, size)
        for i, v in values.items():
            group.addParam(i, list((v & ((1 << (8 * size)) - 1)).to_bytes(size, "little")))
        with self._io:
            res = self._guard(group.txPacket)
        if res != sdk.COMM_SUCCESS:
            raise DeviceIOError(f"Sync Write to {address} failed: {self._ph.getTxRxResult(res)}")

    def set_goal(self, q: Sequence[float]) -> None:
        """Goal Position for every joint (rad, the scene's convention)."""
        q = np.asarray(q, dtype=float)
        if q.shape != self.zero.shape:
            raise ValueError(f"expected {len(self.ids)} joint positions (servos {self.ids}), got shape {q.shape}")
        ticks = np.rint(self.zero + self.direction * q / self.model.rad_per_tick).astype(int)
        self.write_item(116, 4, {i: int(t) for i, t in zip(self.ids, ticks, strict=True)})

    servo_period_s = 0.005  # a Sync Write of Goal Position every 5 ms between the 2 ms Sync Reads

    def prepare_servo(self) -> None:
        """Nothing to open: a setpoint is a Sync Write of Goal Position on the bus the reader uses."""
        self._require_link()

    def servo(self, q: Sequence[float]) -> None:
        """The next setpoint of a stream: Goal Position for every joint (one Sync Write, no answer)."""
        self.set_goal(q)
        self.counters["setpoints"] += 1

    def end_servo(self) -> None:
        """The servos hold the last Goal Position: nothing to send."""

    def torque_states(self) -> dict[int, bool]:
        states = self.read_item(64, 1)
        if states is None:
            raise DeviceIOError("cannot read Torque Enable")
        return {i: bool(v) for i, v in states.items()}

    def set_torque(self, on: bool | dict[int, bool]) -> None:
        """Torque Enable for every servo (a bool) or per servo (id -> bool); read back to check."""
        want = {i: bool(on) for i in self.ids} if isinstance(on, bool) else dict(on)
        self.write_item(64, 1, {i: int(v) for i, v in want.items()})
        got = self.torque_states()
        if any(got[i] != v for i, v in want.items()):
            raise DeviceError(f"Torque Enable did not take: wanted {want}, servos report {got}")

    @contextlib.contextmanager
    def torque(self, on: bool = True) -> Iterator[DynamixelArm]:
        """``with arm.torque(False): ...`` -- sets torque, and always restores each servo's previous state."""
        previous = self.torque_states()
        try:
            self.set_torque(on)
            yield self
        finally:
            self.set_torque(previous)

    def stop(self) -> None:
        """The monitor's reflex: Goal Position := Present Position for every servo (they hold there).

        Present Position is the cyclic read's when that read completed less than two cycles ago --
        on schedule it is less than one cycle old; the second cycle only absorbs the reader's jitter --
        else a fresh Sync Read (if that fails, the cyclic read's while it is younger than
        ``stale_after``); then one Sync Write of Goal Position to all servos, which no servo answers.
        Why a position up to a cycle old is safe: it is a point the arm passed on its way here, so
        holding it pulls the arm back along the path it came (away from what it hit) by speed x age
        (at the XM430's 4.8 rad/s no-load speed, < 10 mrad per cycle); a fresh read would delay the
        halt by a whole transaction while the arm keeps going. ``stop_position_age_s``: the age of
        the position the last stop() held.
        """
        self._require_link()
        with self._io:
            age = time.monotonic() - self._last_ok
            cached = None if self.latest_ticks is None else \
                {i: int(t) for i, t in zip(self.ids, self.latest_ticks, strict=True)}
            present = cached if cached is not None and age < 2.0 * self.period else None
            if present is None:
                res, data, _ = self._sync_read(PRESENT_START, PRESENT_LENGTH)
                if res == sdk.COMM_SUCCESS:
                    present = {i: int(np.frombuffer(d[6:10], "<i4")[0]) for i, d in data.items()}
                    age = 0.0
                    self.counters["stop_fresh_reads"] += 1
                else:
                    self._resync()
                    self.counters["stop_read_failures"] += 1
                    if cached is None or time.monotonic() - self._last_ok >= self.stale_after:
                        raise DeviceIOError(f"stop: cannot read Present Position ({self._ph.getTxRxResult(res)})"
                                            " and no recent one")
                    present, age = cached, time.monotonic() - self._last_ok
            self.write_item(116, 4, present)
        self.stop_position_age_s = age
        self.counters["stops"] += 1
