"""One emulated DYNAMIXEL servo: its control-table memory and the rules of reading and writing it.

Memory is a byte array laid out as the model's control table (``ftc_hw.codecs.dxl_table``). Reads return
the stored bytes (present values are refreshed from the world first by the bus); Indirect Data k
reads and writes the byte at Indirect Address k. A write must cover whole items: a partial item is
a Data Length Error, a read-only item or reserved byte an Access Error, an EEPROM item while torque
is on an Access Error (ROM lock), a value outside the item's range a Data Range Error, outside a
range set by other items (Goal Position between the position limits, Goal Current within the
Current Limit, ...) a Data Limit Error. Nothing is committed when any item fails.

Joint angle convention: ``present_ticks = zero_tick + homing_offset + direction * q / rad_per_tick``
(q in rad, the scene's joint angle), velocity and current likewise with ``direction``. For the
OpenMANIPULATOR-X, ROBOTIS puts 0 rad at tick 2048 (the horn's centre) with direction +1 (the
gripper's -1: its scene angle opens the gripper).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, field

from ftc_hw.codecs.dxl_table import (
    ERR_ACCESS,
    ERR_DATA_LENGTH,
    ERR_DATA_LIMIT,
    ERR_DATA_RANGE,
    ERR_RESULT_FAIL,
    EXTENDED_POSITION_RANGE,
    OP_POSITION,
    POSITION_MODES,
    Item,
    ServoModel,
)


@dataclass
class WriteEffects:
    """What a write changed that the world must hear about."""

    torque: bool | None = None  # new Torque Enable
    goal: bool = False  # Goal Position changed while torque is on in a position mode
    changed: set[str] = field(default_factory=set)


_FORMATS = {(1, False): "<B", (2, False): "<H", (4, False): "<I", (1, True): "<b", (2, True): "<h", (4, True): "<i"}


def _field(it: Item) -> tuple[int, struct.Struct, int, int]:
    bits = 8 * it.size
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if it.signed else (0, (1 << bits) - 1)
    return it.address, struct.Struct(_FORMATS[(it.size, it.signed)]), lo, hi


class Servo:
    def __init__(self, model: ServoModel, dxl_id: int, joint: int, *, zero_tick: int | None = None,
                 direction: int = 1, eeprom: dict[str, int] | None = None) -> None:
        self.model = model
        self.joint = joint
        self.zero_tick = model.center_tick if zero_tick is None else int(zero_tick)
        if direction not in (1, -1):
            raise ValueError(f"direction must be +1 or -1, got {direction!r}")
        self.direction = direction
        self.mem = bytearray(model.size)
        self._fields = {it.name: _field(it) for it in model.items}
        self._item_at: list[Item | None] = [None] * model.size
        for it in model.items:
            for a in range(it.address, it.end):
                self._item_at[a] = it
        self._indirect_data = {model.item(f"Indirect Data {k}").address: model.item(f"Indirect Address {k}")
                               for k in range(1, 57)}
        self._eeprom_overrides = dict(eeprom or {})
        self.factory_reset(0xFF)
        self.set("ID", dxl_id)
        for name, value in self._eeprom_overrides.items():
            self.set(name, value)
        self.turn_offset = 0  # Clear instruction: ticks removed from the present position
        self.booting_until = 0.0
        self.registered: tuple[int, bytes] | None = None

    # -- raw access ------------------------------------------------------------------------------------
    def get(self, name: str) -> int:
        address, fmt, _, _ = self._fields[name]
        return fmt.unpack_from(self.mem, address)[0]

    def set(self, name: str, value: int) -> None:
        """Store ``value`` (saturated to what the item's bytes hold)."""
        address, fmt, lo, hi = self._fields[name]
        fmt.pack_into(self.mem, address, min(max(int(value), lo), hi))

    @property
    def id(self) -> int:
        return self.mem[self.model.item("ID").address]

    @property
    def torque_on(self) -> bool:
        return bool(self.get("Torque Enable"))

    def reset_ram(self) -> None:
        for it in self.model.items:
            if not it.eeprom:
                self.set(it.name, it.default)

    def factory_reset(self, option: int) -> None:
        keep = {"ID": self.get("ID"), "Baud Rate": self.get("Baud Rate")} if any(self.mem) else {}
        for it in self.model.items:
            self.set(it.name, it.default)
        if option in (0x01, 0x02) and keep:
            self.set("ID", keep["ID"])
        if option == 0x02 and keep:
            self.set("Baud Rate", keep["Baud Rate"])

    # -- the joint convention --------------------------------------------------------------------------
    def ticks(self, q: float) -> int:
        return self.zero_tick + self.get("Homing Offset") + round(self.direction * q / self.model.rad_per_tick) \
            + self.turn_offset

    def angle(self, ticks: int) -> float:
        return self.direction * (ticks - self.zero_tick - self.get("Homing Offset") - self.turn_offset) \
            * self.model.rad_per_tick

    def refresh(self, q: float, qd: float, current: float, tick_ms: int, temperature: float) -> None:
        """Present values from the world's joint state (rad, rad/s, A) and the servo's clock."""
        m = self.model
        pos = self.ticks(q)
        vel = round(self.direction * qd / m.rad_s_per_unit)
        self.set("Present Position", pos)
        self.set("Present Velocity", vel)
        self.set("Present Current", round(self.direction * current / m.current_unit_a))
        self.set("Velocity Trajectory", vel)
        self.set("Position Trajectory", self.get("Goal Position") if self.torque_on else pos)
        self.set("Moving", int(abs(vel) > self.get("Moving Threshold")))
        self.set("Realtime Tick", tick_ms % 32768)
        self.set("Present Temperature", round(temperature))

    # -- protocol-level read and write -------------------------------------------------------------------
    def read(self, address: int, length: int) -> tuple[int, bytes]:
        """(error number, data) of a Read of ``length`` bytes at ``address``. A read beyond the table is an
        Access Error; its status still carries ``length`` zero bytes (up to 1000) so that clients which
        index the data before looking at the error (dynamixel_sdk's read*ByteTxRx do) do not crash."""
        if length < 1 or address < 0 or address + length > len(self.mem):
            return ERR_ACCESS, bytes(length) if 0 < length <= 1000 else b""
        out = bytearray(self.mem[address:address + length])
        for a in range(address, address + length):
            ind = self._indirect_data.get(a)
            if ind is not None:
                target = int.from_bytes(self.mem[ind.address:ind.end], "little")
                out[a - address] = self.mem[target] if target < len(self.mem) else 0
        return 0, bytes(out)

    def limit_range(self, item: Item) -> tuple[int, int]:
        mode = self.get("Operating Mode")
        if item.limit == "position":
            if mode == OP_POSITION:
                return self.get("Min Position Limit"), self.get("Max Position Limit")
            return EXTENDED_POSITION_RANGE
        bound = {"velocity": "Velocity Limit", "current": "Current Limit", "pwm": "PWM Limit"}[item.limit or ""]
        v = self.get(bound)
        return -v, v

    def write(self, address: int, data: bytes, hardware_error: bool = False) -> tuple[int, WriteEffects]:
        """(error number, effects) of a Write; nothing changes unless the error number is 0."""
        fx = WriteEffects()
        if not data or address < 0 or address + len(data) > len(self.mem):
            return ERR_ACCESS, fx
        writes: dict[int, int] = {}
        for k, b in enumerate(data):
            a = address + k
            ind = self._indirect_data.get(a)
            if ind is not None:
                a = int.from_bytes(self.mem[ind.address:ind.end], "little")
            writes[a] = b
        items: dict[str, Item] = {}
        for a in writes:
            it = self._item_at[a] if a < len(self._item_at) else None
            if it is None:
                return ERR_ACCESS, fx
            items[it.name] = it
        torque_on = self.torque_on
        new: dict[str, int] = {}
        for it in items.values():
            if it.access != "RW" or (it.eeprom and torque_on):
                return ERR_ACCESS, fx
            if any(a not in writes for a in range(it.address, it.end)):
                return ERR_DATA_LENGTH, fx
            value = int.from_bytes(bytes(writes[a] for a in range(it.address, it.end)), "little", signed=it.signed)
            if it.lo is not None and not it.lo <= value <= (it.hi if it.hi is not None else value):
                return ERR_DATA_RANGE, fx
            if it.limit is not None:
                lo, hi = self.limit_range(it)
                if not lo <= value <= hi:
                    return ERR_DATA_LIMIT, fx
            new[it.name] = value
        if new.get("Torque Enable") == 1 and hardware_error:
            return ERR_RESULT_FAIL, fx  # after a shutdown only a reboot re-enables torque
        for name, value in new.items():
            if self.get(name) != value:
                fx.changed.add(name)
            self.set(name, value)
        if "Torque Enable" in new and new["Torque Enable"] != int(torque_on):
            fx.torque = bool(new["Torque Enable"])
            if fx.torque:  # the servo holds where it is: Goal Position := Present Position
                self.set("Goal Position", self.get("Present Position"))
        if "Goal Position" in new and self.torque_on and self.get("Operating Mode") in POSITION_MODES:
            fx.goal = True
        return 0, fx
