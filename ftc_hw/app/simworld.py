"""What ``ftc monitor --sim`` connects to: the scene's physics world and its protocol emulators (the
code ``ftc sim`` runs, :class:`~ftc_hw.sim_devices.runner.SimRunner`) in a child process, one more process
per emulator.

The world is built and its emulators started, then it runs in real time holding the scenario's start
pose (a pre-roll: the devices stream, the adapters connect -- ur_rtde needs data to connect -- and
the monitor tares the sensor at rest) until :meth:`SimWorld.go`; the scenario then starts from its own
t = 0 (its scripted events with it: ``World.start_script``) and runs ``duration`` simulated seconds in real time;
the world reports the end and goes on (a post-roll, without truth) until it is closed. Ground truth
goes to a JSON Lines file from that start: ``ftc sim --truth``'s records (``t``: scenario time;
``t_world``: the world's) plus ``t_host_ns``, the host
``time.monotonic_ns()`` (one clock for all processes) at which the world published the sample to its
emulators, and ``t_due_ns``, the host time at which it was due (the same, unless the world ran late:
a loaded machine), so contact events (host time) can be compared with it.

A scene without an arm device (leng2016) has its joint state read from the world's shared-memory
joint ring by :class:`SimJointSource`, which publishes it like an arm adapter would.
"""
from __future__ import annotations

import contextlib
import json
import multiprocessing as mp
import random
import socket
import time
from pathlib import Path
from typing import Any

import numpy as np

from ftc_hw.bus import Bus, JointFrame, joints_topic
from ftc_hw.devices.base import Adapter
from ftc_hw.scene import Scene

UR_PORTS = (30004, 29999)  # RTDE (hard-coded by ur_rtde) and dashboard


def free_loopback(ports: tuple[int, ...] = UR_PORTS) -> str:
    """A loopback address 127.0.0.k with all ``ports`` free (a UR emulator needs fixed ports)."""
    candidates = list(range(100, 250))
    random.shuffle(candidates)
    for k in candidates:
        address = f"127.0.0.{k}"
        socks = []
        try:
            for port in ports:
                s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                socks.append(s)
                s.bind((address, port))
            return address
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError(f"no loopback address with ports {ports} free")


class _Quit(Exception):
    pass


class _Go(Exception):
    pass


def _main(conn, scene: Scene, scenario: str, duration: float, seed: int, noise: bool, truth: str | None,
          options: dict) -> None:
    from ftc_hw.sim_devices.runner import SimRunner
    from ftc_hw.sim_devices.world import Hold, truth_record

    try:
        runner = SimRunner(scene, scenario, duration=duration, seed=seed, noise=noise, options=options)
        endpoints = runner.start()
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which raises
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    counts = {"samples": 0, "contact": 0}
    world = runner.world
    setup = world.setup
    try:
        conn.send(("ready", {"endpoints": endpoints, "joint_ring": runner.link.joints.name,
                             "sample_period_s": 1.0 / scene.sensor.rate_hz}))

        def commands(go_ok: bool) -> None:
            while conn.poll():
                op = conn.recv()[0]
                if op == "halt":
                    world.halt()
                elif op == "quit":
                    raise _Quit
                elif op == "go" and go_ok:
                    raise _Go

        # Pre-roll: the arm holds the scenario's start pose, in real time (devices stream, adapters
        # connect, the monitor tares), until "go"; then the scenario starts from its own t = 0.
        world.set_reference(Hold(np.asarray(setup.trajectory.reference(0.0)[0], dtype=float)))
        world.hold_script()  # nothing scripted happens before go, however long the pre-roll
        runner.duration = 1e9
        with contextlib.suppress(_Go):
            runner.run(realtime=True, on_sample=lambda _state: commands(True))
        t_go = world.t
        world.set_reference(setup.trajectory)
        world.start_script()
        runner.duration = duration
        clock0, t0 = time.monotonic_ns(), world.t
        with contextlib.ExitStack() as stack:
            out = stack.enter_context(open(truth, "w", encoding="utf-8")) if truth else None

            def on_sample(state) -> None:
                now = time.monotonic_ns()
                counts["samples"] += 1
                counts["contact"] += bool(state.contacts)
                if out is not None:
                    rec = truth_record(state)
                    rec["t"] = round(state.t - t_go, 9)  # scenario time
                    rec["t_world"] = round(state.t, 9)
                    rec["t_host_ns"] = now
                    rec["t_due_ns"] = clock0 + round((state.t - t0) * 1e9)
                    out.write(json.dumps(rec, separators=(",", ":")) + "\n")
                commands(False)

            runner.run(realtime=True, on_sample=on_sample)
        conn.send(("done", {**counts, "t": world.t - t_go, "preroll_s": t_go}))
        # Post-roll: the scenario goes on (no truth) and the devices stream until "quit": an adapter whose
        # device falls silent goes stale (and ur_rtde cannot be closed cleanly then); halting the arm
        # here would jerk it, which the monitor may rightly call a contact.
        runner.duration = 1e9
        runner.run(realtime=True, on_sample=lambda _state: commands(False))
    except (_Quit, EOFError, BrokenPipeError, KeyboardInterrupt):
        pass
    finally:
        runner.stop()


class SimWorld:
    """``start()`` (emulators up, world waiting) -> connect adapters -> ``go()`` -> ``done`` -> ``close()``.

    ``truth``: the ground-truth JSON Lines file to write. ``options``: per device name, emulator
    options; a UR arm gets a free loopback address unless one is given.
    """

    def __init__(self, scene: Scene, scenario: str, *, duration: float, seed: int = 0, noise: bool = True,
                 truth: Path | None = None, options: dict[str, dict] | None = None) -> None:
        self.scene = scene
        options = {k: dict(v) for k, v in (options or {}).items()}
        for d in scene.devices:
            if d.kind == "ur-rtde":
                options.setdefault(d.name, {}).setdefault("address", free_loopback())
        self._args = (scene, scenario, duration, seed, noise, str(truth) if truth else None, options)
        self._proc: Any = None
        self._conn: Any = None
        self.endpoints: dict[str, dict[str, Any]] = {}
        self.joint_ring = ""
        self.sample_period_s = 1.0 / scene.sensor.rate_hz
        self.result: dict[str, Any] | None = None

    def start(self, timeout: float = 90.0) -> dict[str, dict[str, Any]]:
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        # not a daemon: it starts the emulator processes; it quits when our end of the pipe closes
        self._proc = ctx.Process(target=_main, args=(child, *self._args), name="ftc-monitor-world")
        self._proc.start()
        child.close()
        if not self._conn.poll(timeout):
            self.close()
            raise RuntimeError(f"the simulated world did not start within {timeout:g} s")
        try:
            kind, info = self._conn.recv()
        except (EOFError, OSError):
            kind, info = "error", f"the world process exited (code {self._proc.exitcode})"
        if kind != "ready":
            self.close()
            raise RuntimeError(f"the simulated world failed to start: {info}")
        self.endpoints = {e["name"]: e for e in info["endpoints"]}
        self.joint_ring = info["joint_ring"]
        self.sample_period_s = info["sample_period_s"]
        return self.endpoints

    def go(self) -> None:
        self._conn.send(("go", None))

    def halt(self) -> None:
        """Stop the arm where it is (what a stop command does), for scenes without an arm device."""
        with contextlib.suppress(OSError, BrokenPipeError):
            self._conn.send(("halt", None))

    @property
    def done(self) -> bool:
        if self.result is None and self._conn is not None:
            try:
                while self.result is None and self._conn.poll():
                    kind, info = self._conn.recv()
                    if kind == "done":
                        self.result = info
            except (EOFError, OSError):
                self.result = {"error": "the world process ended without a report"}
        return self.result is not None

    def close(self) -> None:
        if self._conn is not None:
            with contextlib.suppress(OSError, BrokenPipeError):
                self._conn.send(("quit", None))
        if self._proc is not None:
            self._proc.join(20.0)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join(5.0)
        self.done  # noqa: B018 - collect the final report if it came
        if self._conn is not None:
            self._conn.close()
        self._conn = self._proc = None

    def __enter__(self) -> SimWorld:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SimJointSource(Adapter):
    """The world's joint state from its shared-memory ring on ``joints/<name>`` at ``rate_hz``, with
    the world's time as device time: the arm of a scene that declares no arm device. ``stop()`` halts
    the world's arm."""

    kind = "sim-joints"

    def __init__(self, name: str, bus: Bus, world: SimWorld, *, rate_hz: float = 500.0) -> None:
        super().__init__(name, bus, poll_timeout=0.001)
        self.world = world
        self.n = world.scene.n_joints
        self.period = 1.0 / rate_hz
        self.topic = joints_topic(name)
        self._ring = None
        self._reader = None
        self._next_t = 0.0
        self._seq = 0

    def _connect(self) -> None:
        from ftc_hw.sim_devices.link import Ring, RingReader, joint_width

        # attached, not owned (Ring does not register it with the resource tracker): closing it
        # never unlinks the world's ring
        self._ring = Ring(joint_width(self.n), name=self.world.joint_ring, create=False)
        self._reader = RingReader(self._ring)

    def _read_once(self) -> None:
        recs = self._reader.new()
        n = self.n
        for rec in recs:
            t = float(rec[0])
            if t + 1e-9 < self._next_t:
                continue
            self._next_t = (np.floor(t / self.period + 1e-6) + 1) * self.period
            self.bus.publish(self.topic, JointFrame.make(time.monotonic_ns(), rec[1:1 + n], rec[1 + n:1 + 2 * n],
                                                         rec[1 + 3 * n:1 + 4 * n], rec[1 + 4 * n:1 + 5 * n],
                                                         source=self.name, seq=self._seq,
                                                         t_device_ns=round(t * 1e9)))
            self._seq += 1
        if not recs:
            time.sleep(self.poll_timeout)

    def _disconnect(self) -> None:
        if self._ring is not None:
            self._ring.close()
            self._ring = self._reader = None

    def stop(self) -> None:
        self.world.halt()
        self.counters["stops"] += 1
