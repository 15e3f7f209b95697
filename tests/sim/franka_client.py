"""A libfranka client in its own process (the tests' stand-in for a user's program): connects to the
controller at ADDRESS through CLIENT's library, reads COUNT states, then calls stop() and
automatic_error_recovery(); prints one JSON line: the states read (time ms, q, tau_J, robot mode) and
what each call did, or the connect error.

    python franka_client.py CLIENT ADDRESS COUNT
"""
from __future__ import annotations

import importlib
import json
import sys
import time

MODULES = {"panda-py": "panda_py.libfranka", "pylibfranka": "pylibfranka"}


def main(client: str, address: str, count: int) -> dict:
    lib = importlib.import_module(MODULES[client])
    try:
        robot = lib.Robot(address, lib.RealtimeConfig.kIgnore)
    except Exception as exc:  # noqa: BLE001 - reported to the test
        return {"connect_error": f"{type(exc).__name__}: {exc}"}
    states = []
    t0 = time.monotonic()
    for _ in range(count):
        s = robot.read_once()
        states.append([round(s.time.to_sec() * 1000), list(s.q), list(s.tau_J), str(s.robot_mode)])
    out: dict = {"states": states, "seconds": time.monotonic() - t0}
    for call in ("stop", "automatic_error_recovery"):
        try:
            getattr(robot, call)()
            out[call] = "ok"
        except Exception as exc:  # noqa: BLE001 - reported to the test
            out[call] = f"{type(exc).__name__}: {exc}"
        time.sleep(0.05)
    return out


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], sys.argv[2], int(sys.argv[3]))))
