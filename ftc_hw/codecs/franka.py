"""Franka's FCI network protocol (libfranka's "research interface"): the command messages on TCP port
1337 and the robot state and robot command datagrams on UDP. No I/O.

Two protocol versions, one per libfranka generation (:data:`VERSIONS`):

- version 5: libfranka 0.9.x, the Franka Emika Robot (FER, "Panda"); panda-python ships 0.9.2.
  Sources: libfranka 0.9.2's ``common`` submodule (frankaemika/libfranka-common e6aa0fc),
  ``include/research_interface/robot/service_types.h`` and ``rbk_types.h``.
- version 10: libfranka 0.21.x, the Franka Research 3 (FR3); pylibfranka 0.21.3. Sources:
  frankarobotics/libfranka-common d96c221 ("robot version change to 10"), the same two files: the
  robot state's arrays are float32 (double before), the accelerometers are new, the command numbers
  moved (no GetCartesianLimit, SetFilters, LoadModelLibrary; GetRobotModel added).

Every message is little-endian and packed (``#pragma pack(1)``). A TCP message is a 12-byte header
(uint32 command, uint32 command_id, uint32 size: the whole message's bytes, header included) and the
command's request or response struct; a response carries the request's command and command_id. A
response starts with a uint8 status (0: success). The robot state and command are single datagrams
of exactly their struct's size (libfranka throws "incorrect object size" for any other).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import FrameFormatError

COMMAND_PORT = 1337  # research_interface::robot::kCommandPort, fixed in libfranka (robot.cpp)
N_JOINTS = 7
N_ERRORS = 41  # std::array<bool, 41> errors, reflex_reason (both versions)

HEADER = struct.Struct("<III")
HEADER_SIZE = HEADER.size  # 12
CONNECT_REQUEST = struct.Struct("<HH")  # version, udp_port
CONNECT_RESPONSE = struct.Struct("<BH")  # status, version
SUCCESS = 0

# RobotState enums (rbk_types.h, uint8)
MOTION_IDLE = 0  # MotionGeneratorMode::kIdle
CONTROLLER_JOINT_IMPEDANCE = 0  # ControllerMode::kJointImpedance
ROBOT_MODES = ("other", "idle", "move", "guiding", "reflex", "user_stopped", "automatic_error_recovery")
MODE_OTHER, MODE_IDLE, MODE_MOVE, MODE_GUIDING, MODE_REFLEX, MODE_USER_STOPPED, MODE_RECOVERY = range(7)

# The robot state's arrays, in order (name, shape) between message_id and the enums. Version 10 adds
# the accelerometers (joints 1-6, x y z) after dtheta.
_STATE_ARRAYS: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("O_T_EE", (16,)), ("O_T_EE_d", (16,)), ("F_T_EE", (16,)), ("EE_T_K", (16,)), ("F_T_NE", (16,)),
    ("NE_T_EE", (16,)), ("m_ee", ()), ("I_ee", (9,)), ("F_x_Cee", (3,)), ("m_load", ()), ("I_load", (9,)),
    ("F_x_Cload", (3,)), ("elbow", (2,)), ("elbow_d", (2,)), ("tau_J", (7,)), ("tau_J_d", (7,)),
    ("dtau_J", (7,)), ("q", (7,)), ("q_d", (7,)), ("dq", (7,)), ("dq_d", (7,)), ("ddq_d", (7,)),
    ("joint_contact", (7,)), ("cartesian_contact", (6,)), ("joint_collision", (7,)),
    ("cartesian_collision", (6,)), ("tau_ext_hat_filtered", (7,)), ("O_F_ext_hat_K", (6,)),
    ("K_F_ext_hat_K", (6,)), ("O_dP_EE_d", (6,)), ("O_ddP_O", (3,)), ("elbow_c", (2,)), ("delbow_c", (2,)),
    ("ddelbow_c", (2,)), ("O_T_EE_c", (16,)), ("O_dP_EE_c", (6,)), ("O_ddP_EE_c", (6,)), ("theta", (7,)),
    ("dtheta", (7,)),
)
_ACCELEROMETERS = (("accelerometer_top", (6, 3)), ("accelerometer_bottom", (6, 3)))


def _state_dtype(real: str, accelerometers: bool) -> np.dtype:
    arrays = _STATE_ARRAYS + (_ACCELEROMETERS if accelerometers else ())
    fields: list[tuple[Any, ...]] = [("message_id", "<u8")]
    fields += [(name, real, shape) if shape else (name, real) for name, shape in arrays]
    fields += [("motion_generator_mode", "u1"), ("controller_mode", "u1"), ("errors", "u1", (N_ERRORS,)),
               ("reflex_reason", "u1", (N_ERRORS,)), ("robot_mode", "u1"), ("control_command_success_rate", real)]
    return np.dtype(fields)  # numpy's structured dtypes are packed unless align=True


def _command_dtype(torque_finished: bool) -> np.dtype:
    motion = [("q_c", "<f8", (7,)), ("dq_c", "<f8", (7,)), ("O_T_EE_c", "<f8", (16,)), ("O_dP_EE_c", "<f8", (6,)),
              ("elbow_c", "<f8", (2,)), ("valid_elbow", "u1"), ("motion_generation_finished", "u1")]
    control = [("tau_J_d", "<f8", (7,))] + ([("torque_command_finished", "u1")] if torque_finished else [])
    return np.dtype([("message_id", "<u8"), ("motion", motion), ("control", control)])


@dataclass(frozen=True)
class ProtocolVersion:
    """One version of the protocol: its number, which libfranka speaks it, its command numbers (by
    libfranka's names), the Move status "command not possible", and the two UDP structs."""

    version: int
    libfranka: str
    robot: str
    commands: dict[str, int]
    move_not_possible: int
    state: np.dtype = field(repr=False)
    command: np.dtype = field(repr=False)

    @property
    def names(self) -> dict[int, str]:
        return {v: k for k, v in self.commands.items()}

    @property
    def state_size(self) -> int:
        return self.state.itemsize

    @property
    def command_size(self) -> int:
        return self.command.itemsize


_COMMON = ("Connect", "Move", "StopMove")
V5 = ProtocolVersion(
    5, "0.9.2", "Franka Emika Robot (FER, Panda)",
    {n: i for i, n in enumerate(_COMMON + (
        "GetCartesianLimit", "SetCollisionBehavior", "SetJointImpedance", "SetCartesianImpedance", "SetGuidingMode",
        "SetEEToK", "SetNEToEE", "SetLoad", "SetFilters", "AutomaticErrorRecovery", "LoadModelLibrary"))},
    move_not_possible=3, state=_state_dtype("<f8", accelerometers=False), command=_command_dtype(False))
V10 = ProtocolVersion(
    10, "0.21.3", "Franka Research 3 (FR3)",
    {n: i for i, n in enumerate(_COMMON + (
        "SetCollisionBehavior", "SetJointImpedance", "SetCartesianImpedance", "SetGuidingMode", "SetEEToK",
        "SetNEToEE", "SetLoad", "AutomaticErrorRecovery", "GetRobotModel"))},
    move_not_possible=5, state=_state_dtype("<f4", accelerometers=True), command=_command_dtype(True))
VERSIONS: dict[int, ProtocolVersion] = {5: V5, 10: V10}

# The request payload sizes of the commands whose size the protocol fixes (a request of another size
# is a protocol error); Move and GetRobotModel's are version-specific or variable: not checked.
_D = 8
REQUEST_SIZES: dict[str, int] = {
    "Connect": CONNECT_REQUEST.size, "StopMove": 0, "AutomaticErrorRecovery": 0,
    "SetCollisionBehavior": _D * (4 * 7 + 4 * 6), "SetJointImpedance": _D * 7, "SetCartesianImpedance": _D * 6,
    "SetGuidingMode": 7, "SetEEToK": _D * 16, "SetNEToEE": _D * 16, "SetLoad": _D * 13, "GetCartesianLimit": 4,
    "SetFilters": _D * 5, "LoadModelLibrary": 2,
}


class FrankaProtocolError(FrameFormatError):
    """A message that is not what the protocol allows (size, command number, version)."""


@dataclass(frozen=True)
class Header:
    command: int
    command_id: int
    size: int  # the whole message, header included


def encode_header(command: int, command_id: int, payload_size: int) -> bytes:
    return HEADER.pack(command, command_id, HEADER_SIZE + payload_size)


def decode_header(data: bytes) -> Header:
    """The header at the start of ``data``; FrankaProtocolError when short or its size is impossible."""
    if len(data) < HEADER_SIZE:
        raise FrankaProtocolError(f"TCP header: {len(data)} of {HEADER_SIZE} bytes", consumed=0)
    header = Header(*HEADER.unpack_from(data))
    if header.size < HEADER_SIZE:
        raise FrankaProtocolError(f"TCP message size {header.size} is below its header's {HEADER_SIZE}",
                                  consumed=HEADER_SIZE)
    return header


def encode_request(proto: ProtocolVersion, name: str, command_id: int, payload: bytes = b"") -> bytes:
    """A request message (the client's side: tests and the adapter's probe)."""
    return encode_header(proto.commands[name], command_id, len(payload)) + payload


def encode_connect(proto: ProtocolVersion, command_id: int, udp_port: int) -> bytes:
    return encode_request(proto, "Connect", command_id, CONNECT_REQUEST.pack(proto.version, udp_port))


def decode_connect(payload: bytes) -> tuple[int, int]:
    """Connect's request payload -> (library version, UDP port)."""
    if len(payload) != CONNECT_REQUEST.size:
        raise FrankaProtocolError(f"Connect request of {len(payload)} bytes, expected {CONNECT_REQUEST.size}")
    return CONNECT_REQUEST.unpack(payload)


def encode_response(header: Header, status: int, body: bytes = b"") -> bytes:
    """The response to the request with ``header``: status byte, then the command's response fields."""
    return encode_header(header.command, header.command_id, 1 + len(body)) + bytes([status]) + body


def encode_connect_response(header: Header, status: int, version: int) -> bytes:
    return encode_header(header.command, header.command_id, CONNECT_RESPONSE.size) + CONNECT_RESPONSE.pack(
        status, version)


def decode_response(data: bytes) -> tuple[Header, int, bytes]:
    """A whole response message -> (header, status, the bytes after the status)."""
    header = decode_header(data)
    if len(data) != header.size or header.size < HEADER_SIZE + 1:
        raise FrankaProtocolError(f"response of {len(data)} bytes, its header says {header.size}", consumed=0)
    return header, data[HEADER_SIZE], data[HEADER_SIZE + 1:]


def check_request(proto: ProtocolVersion, header: Header) -> str:
    """The name of the request's command; FrankaProtocolError for an unknown number or a wrong size."""
    name = proto.names.get(header.command)
    if name is None:
        raise FrankaProtocolError(f"unknown command {header.command} in protocol version {proto.version}", consumed=0)
    want = REQUEST_SIZES.get(name)
    if want is not None and header.size != HEADER_SIZE + want:
        raise FrankaProtocolError(f"{name} request of {header.size} bytes, expected {HEADER_SIZE + want}", consumed=0)
    return name


# -- UDP ----------------------------------------------------------------------------------------------------
def new_state(proto: ProtocolVersion) -> np.ndarray:
    """A zeroed robot state record (a numpy structured scalar array of shape ()) to fill field by field."""
    return np.zeros((), dtype=proto.state)


def encode_state(state: np.ndarray) -> bytes:
    return state.tobytes()


def decode_state(proto: ProtocolVersion, data: bytes) -> np.ndarray:
    """A robot state datagram -> its record (fields by libfranka's names; SI units: m, rad, N, N m; the 4x4
    poses column-major, as libfranka stores them)."""
    if len(data) != proto.state_size:
        raise FrankaProtocolError(f"robot state of {len(data)} bytes, version {proto.version} sends "
                                  f"{proto.state_size}", consumed=len(data))
    state = np.frombuffer(data, dtype=proto.state)[0]
    if state["robot_mode"] >= len(ROBOT_MODES):
        raise FrankaProtocolError(f"robot_mode {state['robot_mode']} is none of libfranka's", consumed=len(data))
    return state


def decode_command(proto: ProtocolVersion, data: bytes) -> np.ndarray:
    """A robot command datagram (the client's control output) -> its record."""
    if len(data) != proto.command_size:
        raise FrankaProtocolError(f"robot command of {len(data)} bytes, version {proto.version} sends "
                                  f"{proto.command_size}", consumed=len(data))
    return np.frombuffer(data, dtype=proto.command)[0]


def column_major(pose: np.ndarray) -> np.ndarray:
    """A 4x4 homogeneous pose as libfranka's 16 values (column-major, as Eigen maps them)."""
    return np.asarray(pose, dtype=float).reshape(4, 4).T.reshape(16)

