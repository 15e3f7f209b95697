"""Device parameters by adapter kind, as data: what a scene's ``[devices.params]`` (and the
``--device NAME.KEY=VALUE`` and ``--rig FILE`` overrides) may say for each device kind -- each
parameter's name, type, allowed range or choices, default and meaning -- and the checks that use it.

The keys are the ones the adapters (``ftc_hw.devices``), the emulators (``ftc_hw.sim_devices``) and the
benches read; the defaults are the adapters' own (an emulator's may differ: said in the meaning).
Units are SI unless the name says otherwise (``latency_timer_ms``, ``return_delay_time``: 2 us units).
"""
from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal

ParamType = Literal["int", "number", "str", "bool", "ints", "numbers", "strs", "number_or_numbers",
                    "name_or_table", "table"]

_FORMS: dict[str, str] = {
    "int": "an integer (19200, 0x10)", "number": "a number (0.05, 500)", "str": "a string", "bool": "true or false",
    "ints": "a list of integers (11,12,13)", "numbers": "a list of numbers (300,300,500,30,30,30)",
    "strs": "a list of names (joint_a,joint_b)",
    "number_or_numbers": "a number or a list of numbers", "name_or_table": "a name or a table",
    "table": "a table",
}


@dataclass(frozen=True)
class Param:
    """One device parameter. ``lo``/``hi`` bound a number (or every item of a list), inclusive;
    ``above`` makes ``lo`` exclusive; ``length`` fixes a list's length; ``default`` None: none."""

    name: str
    type: ParamType
    meaning: str
    default: Any = None
    lo: float | None = None
    hi: float | None = None
    above: bool = False
    choices: tuple[Any, ...] = ()
    length: int | None = None
    required: bool = False

    @property
    def form(self) -> str:
        """What a value looks like, for messages and docs."""
        if self.choices:
            one_of = "one of " + ", ".join(str(c) for c in self.choices)
            return f"a list, each {one_of}" if self.type in ("ints", "numbers") else one_of
        text = _FORMS[self.type]
        if self.length is not None:
            text += f" of {self.length}"
        if self.lo is not None or self.hi is not None:
            low = "" if self.lo is None else f"{'>' if self.above else '>='} {_num(self.lo)}"
            high = "" if self.hi is None else f"<= {_num(self.hi)}"
            text += " " + " and ".join(p for p in (low, high) if p)
        return text


@dataclass(frozen=True)
class DeviceKind:
    """A device kind: its transports, what its ``address`` is (``example``: a typical one), the params
    that can locate it instead of the address (``locators``), and its params."""

    kind: str
    transports: tuple[str, ...]
    address: str
    example: str
    params: tuple[Param, ...]
    locators: tuple[str, ...] = ()

    def param(self, name: str) -> Param | None:
        return next((p for p in self.params if p.name == name), None)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)


class ParamError(ValueError):
    """A device parameter is unknown or its value is wrong: ``key`` and ``problem`` say which and why."""

    def __init__(self, key: str, problem: str) -> None:
        self.key, self.problem = key, problem
        super().__init__(f"{key}: {problem}")


PORT = (1, 65535)
_STALE_S = Param("stale_after_s", "number", "seconds without a frame before a stale event (adapter default: "
                 "50 ms for streams and TCP, 100 ms for RTU polling)", lo=0.0, hi=60.0, above=True)
_RANGE = Param("range", "numbers", "saturation limits Fx Fy Fz (N) Tx Ty Tz (N m), default the device model's or "
               "the scene sensor's", lo=0.0, above=True, length=6)
_DEVICE_ID = Param("device_id", "int", "Modbus unit id", 1, 1, 247)
_MODBUS = (
    Param("baudrate", "int", "RS-485 bit rate (Modbus RTU), bit/s", 19200, 1200, 4_000_000),
    Param("port", "int", "Modbus TCP port (also the emulator's, where 0 takes a free one)", 502, 0, 65535),
    Param("identity", "table", "the emulator's identity registers by name ({serial = \"...\"})"),
    _STALE_S, _RANGE,
)
_MODBUS_ADDRESS = "the serial port of its RS-485 adapter, or host[:port] with transport modbus-tcp"
# ESTIMATE: 1000 messages hold 1 s of a 1 kHz stream while the reader is held up (a keep-last history drops
# its oldest, reliable or not; a loaded 2-core host held the monitor up to 140 ms at a time). A reliable
# subscription matches the drivers' publishers (rclcpp's SystemDefaultsQoS: reliable under Fast DDS and
# Cyclone DDS); best_effort also matches a SensorDataQoS publisher.
_ROS_QOS = (
    Param("reliability", "str", "the subscription's QoS reliability: reliable matches only reliable publishers "
          "(the drivers' default), best_effort matches every publisher but is never resent a lost message",
          "reliable", choices=("reliable", "best_effort")),
    Param("depth", "int", "the subscription's QoS history depth (keep last), messages", 1000, 1, 100_000),
    Param("rate_hz", "number", "the driver's publishing rate, Hz: messages missing between two header stamps "
          "more than 1.5 periods apart are counted lost and the next frame flagged SEQ_GAP (default: no such "
          "check)", lo=0.0, hi=100_000.0, above=True),
)

KINDS: dict[str, DeviceKind] = {k.kind: k for k in (
    DeviceKind("ft300", ("modbus-rtu", "modbus-tcp"), _MODBUS_ADDRESS, "/dev/ttyUSB0", (
        Param("mode", "str", "stream: the 100 Hz data stream (RTU only); poll: registers 180-185", "stream",
              choices=("stream", "poll")),
        replace(_DEVICE_ID, default=9), *_MODBUS,
        Param("poll_hz", "number", "poll rate in poll mode, Hz", 100.0, 0.0, 1000.0, above=True),
    )),
    DeviceKind("modbus-ft", ("modbus-rtu", "modbus-tcp"), _MODBUS_ADDRESS, "/dev/ttyUSB0", (
        Param("map", "name_or_table", "register map: a built-in name (ft300, generic-float32) or a table "
              "(docs/ft-devices.md)", required=True),
        _DEVICE_ID, *_MODBUS,
        Param("poll_hz", "number", "poll rate, Hz", 500.0, 0.0, 10000.0, above=True),
    )),
    DeviceKind("ft-serial-stream", ("serial",), "the serial port", "/dev/ttyUSB0", (
        Param("format", "name_or_table", "frame format: a built-in name (ftc-1k, ft300) or a table "
              "(docs/ft-devices.md)", "ftc-1k"),
        Param("baudrate", "int", "serial bit rate, bit/s", 1_000_000, 1200, 20_000_000),
        _STALE_S, _RANGE,
    )),
    DeviceKind("ft-can", ("can-serial", "can"), "the CAN channel: a serial CAN adapter's port, can0, ...",
               "/dev/ttyACM0", (
        Param("channel", "str", "python-can channel: the serial CAN adapter's port with interface serial "
              "(/dev/ttyACM0), can0 with socketcan, ...; default: the address"),
        Param("interface", "str", "python-can interface (serial, socketcan, pcan, kvaser, ...)", "serial"),
        Param("dbc", "str", "DBC file of the sensor's frames (a built-in name or a path)", "ati_netft_can.dbc"),
        Param("base_id", "int", "the Net F/T's CAN base id (DIP switches); answers on base+1..+4", 8, 0, 0x7FB),
        Param("bitrate", "int", "CAN bit rate, bit/s (set on the adapter; the emulator reports it)", 1_000_000,
              10_000, 1_000_000),
        Param("mode", "str", "stream: every sample; poll: one sample per request", "stream",
              choices=("stream", "poll")),
        Param("poll_hz", "number", "request rate in poll mode, Hz", 100.0, 0.0, 7000.0, above=True),
        Param("rate_hz", "number", "the sensor's sample rate, Hz (the sample counter's clock)", 1000.0, 0.0,
              7000.0, above=True),
        _STALE_S,
    ), locators=("channel",)),
    DeviceKind("ft-rdt", ("udp",), "the Net F/T box's IP address", "192.168.1.1", (
        Param("port", "int", "RDT's UDP port (also the emulator's, where 0 takes a free one)", 49152, 0, 65535),
        Param("http_port", "int", "the box's web server, which serves its configuration and calibration pages "
              "(/netftapi2.xml, /netftcalapi.xml)", 80,
              0, 65535),
        Param("tcp_port", "int", "the box's TCP interface, asked READCALINFO where the calibration page is "
              "missing", 49151, 0, 65535),
        Param("mode", "str", "realtime: one record per packet; buffered: several per packet", "realtime",
              choices=("realtime", "buffered")),
        Param("rate_hz", "number", "the RDT output rate, Hz (the F/T sequence's clock); default the box's "
              "comrdtrate, checked against it when given", lo=0.0, hi=7000.0, above=True),
        Param("buffer", "int", "records per packet in buffered mode; default the box's comrdtbsiz (the "
              "emulator's: 10), checked against it", lo=1, hi=40),
        Param("counts_per_force", "number", "counts per N, overriding the box's calcpf (or cfgcpf), which "
              "must agree per SI unit when it is read", lo=0.0, above=True),
        Param("counts_per_torque", "number", "counts per N m, overriding the box's calcpt (or cfgcpt)", lo=0.0,
              above=True),
        Param("read_calibration", "bool", "read the box's calibration over HTTP (false: counts_per_force and "
              "counts_per_torque, in N and N m, are required)", True),
        _STALE_S,
    )),
    DeviceKind("dynamixel", ("serial",), "the serial port of the U2D2 / USB adapter", "/dev/ttyUSB0", (
        Param("ids", "ints", "servo ids, one per scene joint in order", lo=0, hi=252, required=True),
        Param("protocol", "number", "DYNAMIXEL protocol version", 2.0, choices=(2.0,)),
        Param("model", "str", "servo model", "XM430-W350", choices=("XM430-W350", "XM430-W210")),
        Param("baudrate", "int", "bus bit rate, bit/s (the emulator's default: 57600, the factory setting)",
              1_000_000, choices=(9600, 57600, 115200, 1_000_000, 2_000_000, 3_000_000, 4_000_000, 4_500_000)),
        Param("zero_ticks", "ints", "Present Position of each joint's zero, ticks (default the centre, 2048)",
              lo=0, hi=4095),
        Param("directions", "ints", "+1 or -1 per joint: q = direction * (ticks - zero) * 2 pi / 4096",
              choices=(-1, 1)),
        Param("torque_constant", "number_or_numbers", "N m / A at the horn (default the model's)", lo=0.0,
              above=True),
        Param("rate_hz", "number", "Sync Read cycles per second", 500.0, 0.0, 4000.0, above=True),
        Param("fast_read", "bool", "Fast Sync Read instead of Sync Read", False),
        Param("stale_after", "number", "seconds without a good cycle before a stale event", 0.05, 0.0, 60.0,
              above=True),
        Param("dead_after", "number", "seconds without data before the link is reopened", 0.5, 0.0, 60.0,
              above=True),
        Param("error_poll_s", "number", "Hardware Error Status poll period, s", 0.5, 0.0, 60.0, above=True),
        Param("latency_timer_ms", "int", "dynamixel_sdk's LATENCY_TIMER, ms (match the USB adapter's)", lo=0,
              hi=255),
        Param("return_delay_time", "int", "Return Delay Time written to the servos, 2 us units (emulator)",
              lo=0, hi=254),
        Param("bus_time", "bool", "the emulator spends each packet's time on the wire at the baud rate (bytes x "
              "10 / baud) and each servo's Return Delay Time; false: answers at once, for speed tests (emulator)",
              True),
    )),
    DeviceKind("ur-rtde", ("tcp",), "the controller's IP address", "192.168.1.10", (
        Param("frequency", "number", "RTDE output rate, Hz (500 e-Series, 125 CB3)", 500.0, 0.0, 500.0,
              above=True),
        Param("controller_version", "str", "the emulator's controller version (5.x e-Series, 3.x CB3)", "5.9"),
        Param("torque_constant", "numbers", "N m / A per joint (default the scene's)", lo=0.0, above=True,
              length=6),
        Param("stale_after", "number", "seconds without a packet before a stale event (default max(50 ms, "
              "10 periods))", lo=0.0, hi=60.0, above=True),
        Param("dead_after", "number", "seconds without data before the link is reopened", 0.5, 0.0, 60.0,
              above=True),
        Param("dashboard_port", "int", "dashboard server port", 29999, *PORT),
        Param("serial", "str", "the emulator's serial number", "20205500001"),
        Param("robot_model", "str", "the emulator's robot model", "UR5"),
        Param("ft", "bool", "read the e-Series' built-in flange F/T sensor (ft_raw_wrench) on the same RTDE "
              "connection and publish it as the rig's F/T stream (default: when the scene's pipeline uses a "
              "flange sensor, [sensor] mount = \"flange\", and no F/T device is declared)"),
        Param("ft_range", "numbers", "the flange sensor's saturation limits Fx Fy Fz (N) Tx Ty Tz (N m), "
              "default the scene sensor's range", lo=0.0, above=True, length=6),
    )),
    DeviceKind("franka", ("tcp",), "the arm controller's IP address (FCI)", "172.16.0.2", (
        Param("client", "str", "the client library the arm's system takes: panda-py (libfranka 0.9.2, protocol 5: "
              "Franka Emika Robot, Panda) or pylibfranka (libfranka 0.21, protocol 10: Franka Research 3); the "
              "emulator plays that system", "pylibfranka", choices=("panda-py", "pylibfranka")),
        Param("frequency", "number", "robot state rate, Hz (the controller's 1 kHz; the emulator may send fewer)",
              1000.0, 0.0, 1000.0, above=True),
        Param("stop_timeout", "number", "seconds stop() waits for the controller's reply to StopMove", 1.0, 0.0,
              60.0, above=True),
    )),
    DeviceKind("ros-joint-state", ("ros",), "a ROS 2 topic of sensor_msgs/JointState (params.topic)",
               "/joint_states", (
        Param("topic", "str", "the topic a ROS driver publishes the arm's sensor_msgs/JointState on (docs/ros.md)",
              required=True),
        Param("effort", "str", "what the message's effort is: current (A: ur_robot_driver), torque (N m: "
              "franka_ros2's tau_J) or none (ignored); default torque where the scene has [joint_torque], else "
              "current where it has torque constants, else none", choices=("current", "torque", "none")),
        Param("joints", "strs", "the message's joint name of each scene joint, in the scene's order (default: "
              "joint_prefix + the scene's joint names); joints are matched by name, never by position"),
        Param("joint_prefix", "str", "prefixed to the scene's joint names when joints is not given (a driver's "
              "tf_prefix; fr3_ for franka_ros2 on an FR3)", ""),
        Param("torque_constant", "numbers", "N m / A per joint with effort current (default the scene's)", lo=0.0,
              above=True),
        *_ROS_QOS,
        Param("stale_after", "number", "seconds without a message before a stale event (default max(50 ms, 10 "
              "periods) with rate_hz, else 0.1 s)", lo=0.0, hi=60.0, above=True),
        Param("stop_service", "str", "a std_srvs/Trigger service that stops the arm, called by --reflex stop "
              "(ur_robot_driver: /dashboard_client/stop); without it the stop reflex is refused"),
    ), locators=("topic",)),
    DeviceKind("ros-wrench", ("ros",), "a ROS 2 topic of geometry_msgs/WrenchStamped (params.topic)",
               "/force_torque_sensor_broadcaster/wrench", (
        Param("topic", "str", "the topic a ROS driver publishes the sensor's geometry_msgs/WrenchStamped on "
              "(docs/ros.md)", required=True),
        Param("frame_id", "str", "the driver's header.frame_id, which must be the scene's sensor frame (a message "
              "in another frame is not used: an error event, counted in wrong_frame); default the scene's "
              "[sensor] site"),
        *_ROS_QOS,
        _STALE_S, _RANGE,
    ), locators=("topic",)),
)}

# The keys of a device beside its params (overrides may set them too).
DEVICE_KEYS = ("address", "transport")


def device_kind(kind: str) -> DeviceKind:
    """The kind's schema; ParamError naming the known kinds (and a close match) otherwise."""
    entry = KINDS.get(kind)
    if entry is None:
        raise ParamError("kind", f"unknown device kind {kind!r} (known: {', '.join(KINDS)}){close_match(kind, KINDS)}")
    return entry


def check_params(kind: str, params: Mapping[str, Any]) -> dict[str, Any]:
    """``params`` checked against the kind's schema (unknown keys, types, ranges, choices, required):
    returned as given (values are not converted). ParamError names the first key at fault."""
    entry = device_kind(kind)
    for key, value in params.items():
        param = entry.param(key)
        if param is None:
            raise ParamError(key, f"unknown parameter of device kind {kind} (accepted: {', '.join(entry.names)})"
                             + close_match(key, entry.names))
        check_value(param, value)
    for p in entry.params:
        if p.required and p.name not in params:
            raise ParamError(p.name, f"required by device kind {kind}: {p.meaning} ({p.form})")
    return dict(params)


def check_transport(kind: str, transport: str) -> str:
    entry = device_kind(kind)
    if transport not in entry.transports:
        raise ParamError("transport", f"device kind {kind} has transport {', '.join(entry.transports)}, "
                         f"not {transport!r}{close_match(transport, entry.transports)}")
    return transport


def check_value(param: Param, value: Any) -> Any:
    """``value`` if it fits ``param``; ParamError (key: the param's name) otherwise."""
    problem = _problem(param, value)
    if problem is not None:
        raise ParamError(param.name, f"expected {param.form}, got {value!r}{problem}")
    return value


def parse_value(param: Param, text: str) -> Any:
    """A command-line value for ``param`` (``19200``, ``0x10``, ``11,12,13``, ``true``), checked."""
    try:
        value = _parse(param.type, text.strip())
    except ValueError:
        raise ParamError(param.name, f"expected {param.form}, got {text!r}") from None
    return check_value(param, value)


def located(kind: str, address: str | None, params: Mapping[str, Any]) -> bool:
    """Whether a device of ``kind`` says where it is: an address, or one of its kind's locators."""
    entry = KINDS.get(kind)
    return bool(address) or (entry is not None and any(params.get(k) for k in entry.locators))


def locator_key(kind: str) -> str:
    """The key that says where a device of ``kind`` is (``channel`` for CAN, else ``address``)."""
    entry = KINDS.get(kind)
    return entry.locators[0] if entry is not None and entry.locators else "address"


# -- helpers -----------------------------------------------------------------------------------------
def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else f"{x:g}"


def close_match(word: str, options: Any) -> str:
    """'; did you mean ...?' for the closest of ``options``, or ''."""
    match = difflib.get_close_matches(str(word), list(options), n=1, cutoff=0.6)
    return f"; did you mean {match[0]!r}?" if match else ""


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return (_is_int(v) or isinstance(v, float)) and math.isfinite(v)


_SCALARS = {"int": _is_int, "number": _is_number, "str": lambda v: isinstance(v, str),
            "bool": lambda v: isinstance(v, bool), "table": lambda v: isinstance(v, dict),
            "name_or_table": lambda v: isinstance(v, str | dict)}


def _problem(p: Param, value: Any) -> str | None:
    """None when ``value`` fits, else what to add to "expected ..., got ..." ('' for the wrong type)."""
    if p.type in _SCALARS or (p.type == "number_or_numbers" and _is_number(value)):
        if not _SCALARS.get(p.type, _is_number)(value):
            return ""
        items = [value]
    else:
        each = {"ints": _is_int, "strs": lambda v: isinstance(v, str) and bool(v)}.get(p.type, _is_number)
        if not isinstance(value, list) or not value or not all(each(v) for v in value):
            return ""
        if p.length is not None and len(value) != p.length:
            return f" ({len(value)} values)"
        items = value
    for v in items:
        if p.choices and v not in p.choices:
            return ""
        if (p.lo is not None and (v <= p.lo if p.above else v < p.lo)) or (p.hi is not None and v > p.hi):
            return " (out of range)"
    return None


def _parse(kind: str, text: str) -> Any:
    if kind == "int":
        return int(text, 0)
    if kind == "number":
        return float(text)
    if kind == "bool":
        words = {"true": True, "1": True, "yes": True, "on": True, "false": False, "0": False, "no": False,
                 "off": False}
        if text.lower() not in words:
            raise ValueError(text)
        return words[text.lower()]
    if kind in ("ints", "numbers", "strs") or (kind == "number_or_numbers" and "," in text):
        parts = [t.strip() for t in text.strip("[]").split(",")]
        if kind == "strs":
            return parts
        return [int(t, 0) if kind == "ints" else float(t) for t in parts]
    if kind == "number_or_numbers":
        return float(text)
    if kind == "table":
        raise ValueError("a table is given in a rig file, not on the command line")
    return text
