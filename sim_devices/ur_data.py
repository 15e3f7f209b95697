"""Universal Robots RTDE and dashboard server facts, as data.

Sources: Universal Robots, "Real-Time Data Exchange (RTDE) Guide" (variable names and types, message
formats, protocol v2), "Dashboard Server e-Series" command list and replies, and the URScript
manual's mode enumerations; checked against what ur_rtde 1.6.5 sends (``protocol-notes.md``).
"""
from __future__ import annotations

# -- RTDE messages: header ">HB" (size including the header, command) ------------------------------
RTDE_PORT = 30004
DASHBOARD_PORT = 29999
REQUEST_PROTOCOL_VERSION = ord("V")
GET_URCONTROL_VERSION = ord("v")
TEXT_MESSAGE = ord("M")
DATA_PACKAGE = ord("U")
SETUP_OUTPUTS = ord("O")
SETUP_INPUTS = ord("I")
START = ord("S")
PAUSE = ord("P")
PROTOCOL_VERSION = 2

# RTDE type name -> struct format (big-endian, repeated for vectors).
TYPES: dict[str, str] = {"BOOL": "?", "UINT8": "B", "UINT32": "I", "UINT64": "Q", "INT32": "i", "DOUBLE": "d",
                         "VECTOR3D": "3d", "VECTOR6D": "6d", "VECTOR6INT32": "6i", "VECTOR6UINT32": "6I"}

_V6 = "VECTOR6D"
OUTPUTS: dict[str, str] = {
    "timestamp": "DOUBLE",
    "target_q": _V6, "target_qd": _V6, "target_qdd": _V6, "target_current": _V6, "target_moment": _V6,
    "actual_q": _V6, "actual_qd": _V6, "actual_current": _V6, "actual_current_window": _V6,
    "actual_current_as_torque": _V6, "joint_control_output": _V6,
    "actual_TCP_pose": _V6, "actual_TCP_speed": _V6, "actual_TCP_force": _V6,
    "target_TCP_pose": _V6, "target_TCP_speed": _V6,
    "actual_digital_input_bits": "UINT64", "joint_temperatures": _V6, "actual_execution_time": "DOUBLE",
    "robot_mode": "INT32", "joint_mode": "VECTOR6INT32", "safety_mode": "INT32", "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D", "speed_scaling": "DOUBLE", "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE", "actual_main_voltage": "DOUBLE", "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE", "actual_joint_voltage": _V6, "actual_digital_output_bits": "UINT64",
    "runtime_state": "UINT32", "elbow_position": "VECTOR3D", "elbow_velocity": "VECTOR3D",
    "robot_status_bits": "UINT32", "safety_status_bits": "UINT32", "analog_io_types": "UINT32",
    "standard_analog_input0": "DOUBLE", "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE", "standard_analog_output1": "DOUBLE", "io_current": "DOUBLE",
    "euromap67_input_bits": "UINT32", "euromap67_output_bits": "UINT32",
    "euromap67_24V_voltage": "DOUBLE", "euromap67_24V_current": "DOUBLE",
    "tool_mode": "UINT32", "tool_analog_input_types": "UINT32", "tool_analog_input0": "DOUBLE",
    "tool_analog_input1": "DOUBLE", "tool_output_voltage": "INT32", "tool_output_current": "DOUBLE",
    "tool_temperature": "DOUBLE", "tcp_force_scalar": "DOUBLE",
    "output_bit_registers0_to_31": "UINT32", "output_bit_registers32_to_63": "UINT32",
    "input_bit_registers0_to_31": "UINT32", "input_bit_registers32_to_63": "UINT32",
    "tool_output_mode": "UINT8", "tool_digital_output0_mode": "UINT8", "tool_digital_output1_mode": "UINT8",
    "payload": "DOUBLE", "payload_cog": "VECTOR3D", "payload_inertia": _V6, "script_control_line": "UINT32",
    "ft_raw_wrench": _V6, "joint_position_deviation_ratio": "DOUBLE", "collision_detection_ratio": "DOUBLE",
}
for _k in range(48):
    OUTPUTS[f"output_int_register_{_k}"] = "INT32"
    OUTPUTS[f"output_double_register_{_k}"] = "DOUBLE"
    OUTPUTS[f"input_int_register_{_k}"] = "INT32"
    OUTPUTS[f"input_double_register_{_k}"] = "DOUBLE"
for _k in range(64, 128):
    OUTPUTS[f"output_bit_register_{_k}"] = "BOOL"
    OUTPUTS[f"input_bit_register_{_k}"] = "BOOL"

INPUTS: dict[str, str] = {
    "speed_slider_mask": "UINT32", "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8", "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8", "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8", "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8", "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE", "standard_analog_output_1": "DOUBLE",
    "input_bit_registers0_to_31": "UINT32", "input_bit_registers32_to_63": "UINT32",
    "external_force_torque": _V6,
}
for _k in range(48):
    INPUTS[f"input_int_register_{_k}"] = "INT32"
    INPUTS[f"input_double_register_{_k}"] = "DOUBLE"
for _k in range(64, 128):
    INPUTS[f"input_bit_register_{_k}"] = "BOOL"

# -- modes (RTDE integers and their dashboard names) ------------------------------------------------
ROBOT_MODES = {-1: "NO_CONTROLLER", 0: "DISCONNECTED", 1: "CONFIRM_SAFETY", 2: "BOOTING", 3: "POWER_OFF",
               4: "POWER_ON", 5: "IDLE", 6: "BACKDRIVE", 7: "RUNNING", 8: "UPDATING_FIRMWARE"}
ROBOT_POWER_OFF, ROBOT_IDLE, ROBOT_RUNNING = 3, 5, 7
SAFETY_MODES = {1: "NORMAL", 2: "REDUCED", 3: "PROTECTIVE_STOP", 4: "RECOVERY", 5: "SAFEGUARD_STOP",
                6: "SYSTEM_EMERGENCY_STOP", 7: "ROBOT_EMERGENCY_STOP", 8: "VIOLATION", 9: "FAULT",
                10: "VALIDATE_JOINT_ID", 11: "UNDEFINED_SAFETY_MODE", 12: "AUTOMATIC_MODE_SAFEGUARD_STOP",
                13: "SYSTEM_THREE_POSITION_ENABLING_STOP"}
SAFETY_NORMAL, SAFETY_PROTECTIVE_STOP = 1, 3
RUNTIME_STOPPING, RUNTIME_STOPPED, RUNTIME_PLAYING, RUNTIME_PAUSING, RUNTIME_PAUSED, RUNTIME_RESUMING = range(6)
RUNTIME_NAMES = {RUNTIME_STOPPED: "STOPPED", RUNTIME_PLAYING: "PLAYING", RUNTIME_PAUSED: "PAUSED"}
JOINT_POWER_OFF, JOINT_RUNNING, JOINT_IDLE = 239, 253, 255
# robot_status_bits: 0 power on, 1 program running, 2 teach button pressed, 3 power button pressed.
# safety_status_bits: 0 normal, 1 reduced, 2 protective stopped, 3 recovery, 4 safeguard stopped,
# 5 system emergency stopped, 6 robot emergency stopped, 7 emergency stopped, 8 violation, 9 fault,
# 10 stopped due to safety.

# -- dashboard server ---------------------------------------------------------------------------------
DASHBOARD_WELCOME = "Connected: Universal Robots Dashboard Server"
