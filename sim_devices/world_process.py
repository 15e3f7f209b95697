"""The world and some of its emulators in a separate process, steered over a pipe.

Tests and benchmarks run device clients (dynamixel_sdk, ur_rtde, the adapters) in their own process;
the world must keep real time next to them, and the protocol notes forbid in-process emulators. A
:class:`WorldProcess` runs a :class:`~ftc_hw.sim_devices.runner.SimRunner` (the code ``ftc sim`` runs) in a
child process, limited to the devices asked for, and lets the caller kill, restart, suspend (SIGSTOP,
a hung device) and resume an emulator, read the world's joint samples from the shared-memory ring,
and list the commands the world applied with the host time (``time.monotonic_ns``, comparable across
processes) and the simulated time at which it applied them.
"""
from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing as mp
import os
import signal
import threading
import time
from typing import Any

import numpy as np

from ftc_hw.model import Payload
from ftc_hw.scene import Scene, load_scene

from .link import Command, Ring, RingReader, joint_width
from .runner import EmulatorProcess, SimRunner


@dataclasses.dataclass(frozen=True)
class AppliedCommand:
    t_host_ns: int  # time.monotonic_ns() in the world process when the world applied it
    t_sim: float  # world time (s) at that step
    kind: str
    q: tuple[float, ...] | None
    on: bool | None = None
    t_sent_ns: int = 0  # when the emulator sent it (time.monotonic_ns() in its process)
    t_due_ns: int = 0  # host time at which t_sim is due in the real-time run: the arm's own clock
    t_rx_ns: int = 0  # when the emulator read the request that caused it (0: not recorded)


class _RecordingRunner(SimRunner):
    """A SimRunner that remembers when it applied each command."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.applied: list[AppliedCommand] = []

    def _apply(self, cmd: Command) -> None:
        t = self.world.t
        self.applied.append(AppliedCommand(time.monotonic_ns(), t, cmd.kind, cmd.q, cmd.on, cmd.t_sent_ns,
                                           self.due_ns(t) or 0, int(cmd.extra.get("t_rx_ns", 0))))
        super()._apply(cmd)


class _Quit(Exception):
    pass


def _main(conn, scene: Scene, scenario: str, seed: int, noise: bool, options: dict, payload=None) -> None:
    runner = _RecordingRunner(scene, scenario, duration=1e6, seed=seed, noise=noise, options=options,
                              payload=payload)
    try:
        endpoints = runner.start()
    except Exception as exc:  # noqa: BLE001 - reported to the parent
        conn.send(("error", f"{type(exc).__name__}: {exc}"))  # SimRunner.start cleaned up
        return
    send_lock = threading.Lock()

    def reply(kind: str, value: Any) -> None:
        with send_lock:
            conn.send((kind, value))

    def emulator(name: str) -> EmulatorProcess:
        return next(e for e in runner.emulators if e.device.name == name)

    def restart(name: str, new_options: dict | None) -> None:  # in a thread: the world keeps stepping
        try:
            old = emulator(name)
            old.stop()
            if new_options is not None:
                options[name] = new_options
            new = EmulatorProcess.start(old.device, scene, runner.link.info, options.get(name))
            runner.emulators[runner.emulators.index(old)] = new
            reply("ok", new.endpoint)
        except Exception as exc:  # noqa: BLE001
            reply("error", f"{type(exc).__name__}: {exc}")

    def handle(msg: tuple) -> None:
        op, arg = msg
        if op == "quit":
            raise _Quit
        try:
            if op == "kill":
                emulator(arg).kill()
            elif op in ("suspend", "resume"):
                os.kill(emulator(arg).process.pid, signal.SIGSTOP if op == "suspend" else signal.SIGCONT)
            elif op == "restart":
                threading.Thread(target=restart, args=arg, daemon=True).start()
                return
            elif op == "applied":
                reply("ok", runner.applied[arg or 0:])
                return
            elif op == "applied_count":
                reply("ok", len(runner.applied))
                return
            elif op == "time":
                reply("ok", runner.world.t)
                return
            elif op == "goal":  # applied like an emulator's goal command, between two steps
                runner._apply(Command("world-process", "goal", q=tuple(float(x) for x in arg)))
            reply("ok", None)
        except Exception as exc:  # noqa: BLE001
            reply("error", f"{type(exc).__name__}: {exc}")

    def poll(_state: Any = None) -> None:
        while conn.poll():
            handle(conn.recv())

    reply("ready", {"endpoints": endpoints, "joint_ring": runner.link.joints.name, "n_joints": scene.n_joints})
    try:
        runner.run(realtime=True, on_sample=poll)
    except (_Quit, EOFError, BrokenPipeError):
        pass
    finally:
        runner.stop()


class WorldProcess:
    """``with WorldProcess("ur5e", devices=["arm"]) as w:`` -- ``w.endpoints`` lists what to connect to.

    ``devices``: the scene's device names to emulate (None: all of them). ``options``: per device name,
    the emulator options. The world runs in real time until :meth:`close`.
    """

    def __init__(self, scene: Scene | str, scenario: str = "hold", *, devices: list[str] | None = None,
                 options: dict[str, dict] | None = None, seed: int = 0, noise: bool = False,
                 payload: Payload | None = None) -> None:
        scene = load_scene(scene) if isinstance(scene, str) else scene
        if devices is not None:
            missing = set(devices) - {d.name for d in scene.devices}
            if missing:
                raise ValueError(f"scene {scene.name!r} has no device(s) {sorted(missing)}")
            scene = dataclasses.replace(scene, devices=tuple(d for d in scene.devices if d.name in devices))
        self.scene = scene
        self._args = (scene, scenario, seed, noise, options or {}, payload)
        self._proc: Any = None
        self._conn: Any = None
        self._ring: Ring | None = None
        self.endpoints: list[dict[str, Any]] = []

    def start(self, timeout: float = 60.0) -> list[dict[str, Any]]:
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        # not a daemon: it starts the emulator processes
        self._proc = ctx.Process(target=_main, args=(child, *self._args), name="ftc-world")
        self._proc.start()
        child.close()
        kind, info = self._recv(timeout)
        if kind != "ready":
            self.close()
            raise RuntimeError(f"world process failed to start: {info}")
        self.endpoints = info["endpoints"]
        self._ring = Ring(joint_width(info["n_joints"]), name=info["joint_ring"], create=False)
        return self.endpoints

    def endpoint(self, name: str) -> dict[str, Any]:
        return next(e for e in self.endpoints if e.get("name") == name)

    # -- steering -------------------------------------------------------------------------------------
    def _recv(self, timeout: float) -> tuple[str, Any]:
        if not self._conn.poll(timeout):
            raise TimeoutError(f"no answer from the world process within {timeout:g} s")
        return self._conn.recv()

    def _call(self, op: str, arg: Any = None, timeout: float = 30.0) -> Any:
        self._conn.send((op, arg))
        kind, value = self._recv(timeout)
        if kind != "ok":
            raise RuntimeError(f"world process: {op} {arg if arg is not None else ''}: {value}")
        return value

    def kill(self, name: str) -> None:
        """SIGKILL the emulator of device ``name`` (a pulled plug)."""
        self._call("kill", name)

    def restart(self, name: str, options: dict | None = None) -> dict[str, Any]:
        """Start the emulator of ``name`` again (with new ``options`` if given); returns its endpoint once
        it is ready."""
        endpoint = self._call("restart", (name, options), timeout=60.0)
        self.endpoints = [endpoint if e.get("name") == name else e for e in self.endpoints]
        return endpoint

    def suspend(self, name: str) -> None:
        """SIGSTOP the emulator (a hung device: sockets and ptys stay open, nothing answers)."""
        self._call("suspend", name)

    def resume(self, name: str) -> None:
        self._call("resume", name)

    def applied(self, since: int = 0) -> list[AppliedCommand]:
        """The commands the world applied, from the ``since``-th on."""
        return self._call("applied", since)

    def applied_count(self) -> int:
        return self._call("applied_count")

    def sim_time(self) -> float:
        return self._call("time")

    def goal(self, q) -> None:
        """Set the world's joint targets (a hold at q, rad), applied like an emulator's goal command:
        how a simulated arm whose protocol has no motion command (UR RTDE receive) is moved."""
        self._call("goal", [float(x) for x in q])

    # -- the world's joint samples ----------------------------------------------------------------------
    def joint_reader(self, from_start: bool = False) -> RingReader:
        """A reader of the world's joint ring: records ``[t, q..., qd..., qdd..., current..., tau...]``."""
        assert self._ring is not None, "start() first"
        return RingReader(self._ring, from_start=from_start)

    def latest_joints(self) -> dict[str, np.ndarray | float] | None:
        rec = self.joint_reader().latest()
        if rec is None:
            return None
        n = self.scene.n_joints
        return {"t": float(rec[0]), "q": rec[1:1 + n], "qd": rec[1 + n:1 + 2 * n], "qdd": rec[1 + 2 * n:1 + 3 * n],
                "current": rec[1 + 3 * n:1 + 4 * n], "tau": rec[1 + 4 * n:1 + 5 * n]}

    # -- lifecycle ----------------------------------------------------------------------------------------
    def close(self) -> None:
        if self._conn is not None:
            with contextlib.suppress(OSError, BrokenPipeError):
                self._conn.send(("quit", None))
        if self._proc is not None:
            self._proc.join(15.0)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join(5.0)
        if self._ring is not None:
            self._ring.close()  # attached, not owned: closes without unlinking
            self._ring = None
        if self._conn is not None:
            self._conn.close()
        self._conn = self._proc = None

    def __enter__(self) -> WorldProcess:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
