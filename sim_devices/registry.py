"""Which emulator serves which device kind. Each entry names ``module:function`` with the signature

    serve(device: DeviceSpec, scene: Scene, link: LinkInfo, ready: multiprocessing.Queue,
          options: dict) -> None

run in its own process: it binds its endpoint (loopback or a pty), puts one dict on ``ready``
(``{"name", "kind", "transport", "endpoint", ...protocol parameters}``, or ``{"error": message}``),
then serves until the process is terminated.
"""
from __future__ import annotations

EMULATORS: dict[str, str] = {
    "ft300": "ftc_hw.sim_devices.ft300:serve",
    "ft-serial-stream": "ftc_hw.sim_devices.serial_stream:serve",
    "ft-can": "ftc_hw.sim_devices.can_ft:serve",
    "ft-rdt": "ftc_hw.sim_devices.netft_rdt:serve",
    "modbus-ft": "ftc_hw.sim_devices.modbus_ft:serve",
    "dynamixel": "ftc_hw.sim_devices.dynamixel:serve",
    "ur-rtde": "ftc_hw.sim_devices.ur:serve",
    "franka": "ftc_hw.sim_devices.franka:serve",
}
