"""Where emulators listen, by device name (``ftc sim --address DEVICE=ADDR``): the emulator options
that put a UR or Franka controller on a loopback IP address (``arm=127.0.0.3``: ur_rtde's and
libfranka's ports are fixed, so the address is what tells two controllers apart), a Modbus TCP device
or a Net F/T box (RDT over UDP) on ``host[:port]``, and a serial or CAN device's pty symlink at a path.
Servers bind loopback addresses only."""
from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from ftc_hw.scene import Scene

from .loopback import check_loopback


def parse_addresses(texts: Iterable[str], scene: Scene) -> dict[str, dict[str, Any]]:
    """``["arm=127.0.0.3", ...]`` -> emulator options by device name; ValueError says what is wrong."""
    options: dict[str, dict[str, Any]] = {}
    names = {d.name: d for d in scene.devices}
    for text in texts:
        name, eq, where = (t.strip() for t in text.partition("="))
        if not (eq and name and where):
            raise ValueError(f"--address {text!r}: expected DEVICE=ADDR (arm=127.0.0.3, ft=/tmp/ft.tty)")
        if name not in names:
            raise ValueError(f"--address {text!r}: scene {scene.name!r} has no device {name!r} "
                             f"(devices: {', '.join(names) or 'none'})")
        try:
            options[name] = emulator_address(names[name].kind, names[name].transport, where)
        except ValueError as exc:
            raise ValueError(f"--address {text!r}: {exc}") from None
    return options


def emulator_address(kind: str, transport: str, where: str) -> dict[str, Any]:
    """The emulator options that make a device of ``kind`` over ``transport`` listen at ``where``."""
    if kind in ("ur-rtde", "franka"):  # ports fixed by their client libraries: the address tells them apart
        return {"address": check_loopback(where)}
    if transport in ("modbus-tcp", "udp"):
        host, _, port = where.rpartition(":") if where.count(":") == 1 else (where, "", "")
        if port and not port.isdigit():
            raise ValueError(f"port {port!r} is not a number")
        return {"host": check_loopback(host), **({"port": int(port)} if port else {})}
    if not where.startswith("/"):
        raise ValueError(f"a {kind} emulator is a pty: give the absolute path of its link, not {where!r}")
    return {"path": where}
