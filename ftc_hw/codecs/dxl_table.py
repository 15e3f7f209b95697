"""DYNAMIXEL X-series (Protocol 2.0) control table and servo models, as data.

Shared by the arm adapter (``ftc_hw.devices.dynamixel``) and the emulator (``ftc_hw.sim_devices.dynamixel``).
Source: ROBOTIS e-manual, XM430-W350 and XM430-W210 pages, "Control Table"
(https://emanual.robotis.com/docs/en/dxl/x/xm430-w350/#control-table, .../xm430-w210/), and the
Protocol 2.0 page (https://emanual.robotis.com/docs/en/dxl/protocol2/) for instructions and errors.

An :class:`Item` is one control-table entry: address, size in bytes, access (``R``/``RW``), memory area
(EEPROM items are write-locked while torque is on), factory default and valid range. ``limit`` names
a range that depends on other items (Goal Position between the position limits, ...): writing
outside it is a Data Limit Error rather than a Data Range Error.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property


@dataclass(frozen=True)
class Item:
    name: str
    address: int
    size: int
    access: str  # "R" or "RW"
    eeprom: bool
    default: int = 0
    lo: int | None = None  # valid range (None: any value the size holds)
    hi: int | None = None
    signed: bool = False
    limit: str | None = None  # range given by other items (see ``limit_range`` in the emulator)

    @property
    def end(self) -> int:
        return self.address + self.size


def _x_series(model_number: int, current_limit: int) -> tuple[Item, ...]:
    e, r = True, False
    items = [
        Item("Model Number", 0, 2, "R", e, model_number),
        Item("Model Information", 2, 4, "R", e, 0),
        Item("Firmware Version", 6, 1, "R", e, 46),
        Item("ID", 7, 1, "RW", e, 1, 0, 252),
        Item("Baud Rate", 8, 1, "RW", e, 1, 0, 7),
        Item("Return Delay Time", 9, 1, "RW", e, 250, 0, 254),  # 2 us per unit
        Item("Drive Mode", 10, 1, "RW", e, 0, 0, 13),
        Item("Operating Mode", 11, 1, "RW", e, 3, 0, 16),
        Item("Secondary ID", 12, 1, "RW", e, 255, 0, 255),
        Item("Protocol Type", 13, 1, "RW", e, 2, 1, 2),
        Item("Homing Offset", 20, 4, "RW", e, 0, -1_044_479, 1_044_479, signed=True),
        Item("Moving Threshold", 24, 4, "RW", e, 10, 0, 1023),
        Item("Temperature Limit", 31, 1, "RW", e, 80, 0, 100),
        Item("Max Voltage Limit", 32, 2, "RW", e, 160, 95, 160),
        Item("Min Voltage Limit", 34, 2, "RW", e, 95, 95, 160),
        Item("PWM Limit", 36, 2, "RW", e, 885, 0, 885),
        Item("Current Limit", 38, 2, "RW", e, current_limit, 0, current_limit),
        Item("Velocity Limit", 44, 4, "RW", e, 200, 0, 1023),
        Item("Max Position Limit", 48, 4, "RW", e, 4095, 0, 4095),
        Item("Min Position Limit", 52, 4, "RW", e, 0, 0, 4095),
        Item("External Port Mode 1", 56, 1, "RW", e, 3, 0, 3),
        Item("External Port Mode 2", 57, 1, "RW", e, 3, 0, 3),
        Item("External Port Mode 3", 58, 1, "RW", e, 3, 0, 3),
        Item("Shutdown", 63, 1, "RW", e, 52, 0, 255),
        Item("Torque Enable", 64, 1, "RW", r, 0, 0, 1),
        Item("LED", 65, 1, "RW", r, 0, 0, 1),
        Item("Status Return Level", 68, 1, "RW", r, 2, 0, 2),
        Item("Registered Instruction", 69, 1, "R", r, 0),
        Item("Hardware Error Status", 70, 1, "R", r, 0),
        Item("Velocity I Gain", 76, 2, "RW", r, 1920, 0, 16383),
        Item("Velocity P Gain", 78, 2, "RW", r, 100, 0, 16383),
        Item("Position D Gain", 80, 2, "RW", r, 0, 0, 16383),
        Item("Position I Gain", 82, 2, "RW", r, 0, 0, 16383),
        Item("Position P Gain", 84, 2, "RW", r, 800, 0, 16383),
        Item("Feedforward 2nd Gain", 88, 2, "RW", r, 0, 0, 16383),
        Item("Feedforward 1st Gain", 90, 2, "RW", r, 0, 0, 16383),
        Item("Bus Watchdog", 98, 1, "RW", r, 0, 0, 127),  # stored, not emulated
        Item("Goal PWM", 100, 2, "RW", r, 0, signed=True, limit="pwm"),
        Item("Goal Current", 102, 2, "RW", r, 0, signed=True, limit="current"),
        Item("Goal Velocity", 104, 4, "RW", r, 0, signed=True, limit="velocity"),
        Item("Profile Acceleration", 108, 4, "RW", r, 0, 0, 32767),
        Item("Profile Velocity", 112, 4, "RW", r, 0, 0, 32767),
        Item("Goal Position", 116, 4, "RW", r, 0, signed=True, limit="position"),
        Item("Realtime Tick", 120, 2, "R", r, 0),
        Item("Moving", 122, 1, "R", r, 0),
        Item("Moving Status", 123, 1, "R", r, 0),
        Item("Present PWM", 124, 2, "R", r, 0, signed=True),
        Item("Present Current", 126, 2, "R", r, 0, signed=True),
        Item("Present Velocity", 128, 4, "R", r, 0, signed=True),
        Item("Present Position", 132, 4, "R", r, 0, signed=True),
        Item("Velocity Trajectory", 136, 4, "R", r, 0, signed=True),
        Item("Position Trajectory", 140, 4, "R", r, 0, signed=True),
        Item("Present Input Voltage", 144, 2, "R", r, 120),
        Item("Present Temperature", 146, 1, "R", r, 30),
        Item("Backup Ready", 147, 1, "R", r, 0),
    ]
    # Indirect Address k (2 bytes, default: its own Indirect Data k) and Indirect Data k (1 byte).
    for k in range(1, 57):
        addr = 168 + 2 * (k - 1) if k <= 28 else 578 + 2 * (k - 29)
        data = 224 + (k - 1) if k <= 28 else 634 + (k - 29)
        items.append(Item(f"Indirect Address {k}", addr, 2, "RW", r, data, 64, 661))
        items.append(Item(f"Indirect Data {k}", data, 1, "RW", r, 0))
    return tuple(sorted(items, key=lambda i: i.address))


@dataclass(frozen=True)
class ServoModel:
    """One servo model: its control table and the units of its present/goal values."""

    name: str
    model_number: int
    items: tuple[Item, ...]
    ticks_per_rev: int = 4096  # Present/Goal Position: 0.088 deg per pulse
    center_tick: int = 2048  # the horn's middle position (0 rad in ROBOTIS's joint convention)
    velocity_unit_rpm: float = 0.229  # Present/Goal Velocity
    current_unit_a: float = 0.00269  # Present/Goal Current, 2.69 mA
    torque_constant: float = 1.78  # N m / A at the horn, from the stall torque / stall current

    @property
    def rad_per_tick(self) -> float:
        return 2.0 * math.pi / self.ticks_per_rev

    @property
    def rad_s_per_unit(self) -> float:
        return self.velocity_unit_rpm * 2.0 * math.pi / 60.0

    def item(self, name: str) -> Item:
        return self.by_name[name]

    @cached_property
    def by_name(self) -> dict[str, Item]:
        return {i.name: i for i in self.items}

    @cached_property
    def size(self) -> int:
        return max(i.end for i in self.items)


MODELS: dict[str, ServoModel] = {
    # XM430-W350: stall torque 4.1 N m at 12 V and 2.3 A -> 1.78 N m/A (the scene's torque constant).
    "XM430-W350": ServoModel("XM430-W350", 1020, _x_series(1020, 1193), torque_constant=4.1 / 2.3),
    # XM430-W210: stall torque 3.0 N m at 12 V and 2.3 A -> 1.30 N m/A.
    "XM430-W210": ServoModel("XM430-W210", 1030, _x_series(1030, 1193), torque_constant=3.0 / 2.3),
}

# Baud Rate item value -> bits per second (X series).
BAUD_RATES: dict[int, int] = {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000,
                              6: 4_000_000, 7: 4_500_000}
BAUD_CODES: dict[int, int] = {v: k for k, v in BAUD_RATES.items()}

# Operating Mode values; the ones driven through Goal Position.
OP_CURRENT, OP_VELOCITY, OP_POSITION, OP_EXTENDED_POSITION, OP_CURRENT_POSITION, OP_PWM = 0, 1, 3, 4, 5, 16
POSITION_MODES = frozenset({OP_POSITION, OP_EXTENDED_POSITION, OP_CURRENT_POSITION})
EXTENDED_POSITION_RANGE = (-1_048_575, 1_048_575)

# Hardware Error Status bits.
HW_INPUT_VOLTAGE, HW_OVERHEATING, HW_ENCODER, HW_ELECTRICAL_SHOCK, HW_OVERLOAD = 1, 4, 8, 16, 32

# Protocol 2.0 instructions.
PING, READ, WRITE, REG_WRITE, ACTION, FACTORY_RESET, REBOOT, CLEAR = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x08, 0x10
STATUS = 0x55
SYNC_READ, SYNC_WRITE, FAST_SYNC_READ = 0x82, 0x83, 0x8A
BULK_READ, BULK_WRITE, FAST_BULK_READ = 0x92, 0x93, 0x9A
BROADCAST_ID = 0xFE

# Status packet error numbers (bits 0-6) and the alert bit.
ERR_RESULT_FAIL, ERR_INSTRUCTION, ERR_CRC, ERR_DATA_RANGE, ERR_DATA_LENGTH, ERR_DATA_LIMIT, ERR_ACCESS = range(1, 8)
ERR_ALERT = 0x80

# The addresses the arm adapter reads every cycle: Present Current .. Present Position (126..135).
PRESENT_START, PRESENT_LENGTH = 126, 10
