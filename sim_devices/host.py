"""The world in its own process: the one host every caller runs a simulated world with.

A :class:`WorldHost` starts a child process that builds the scene's physics world and one emulator
process per device asked for (:class:`~ftc_hw.sim_devices.runner.SimRunner`), then steers it over a
pipe. ``ftc sim``, ``ftc monitor --sim``, ``ftc calibrate --sim``, the device benches and the tests
all run their world this way, so they all get the same world: in real time (unless ``realtime`` is
off), never in the process of a device client (the protocol notes forbid in-process emulators).

Phases. With ``preroll``, the arm holds the scenario's start pose in real time -- the devices
stream, adapters connect (ur_rtde needs data to connect), a monitor tares the sensor at rest -- and
nothing scripted happens until :meth:`WorldHost.go`; the scenario then starts from its own t = 0.
Without it the scenario starts at once. It runs ``duration`` simulated seconds (None: until the host
is closed), then the host reports the end (:attr:`WorldHost.done`, :attr:`WorldHost.result`) and
goes on, without truth, until it is closed (a post-roll: an adapter whose device falls silent goes
stale, and ur_rtde cannot be closed cleanly then).

Ground truth (``truth``: a JSON Lines file) is written over the scenario: ``ftc sim --truth``'s
records with ``t`` the scenario time, ``t_world`` the world's and, in real time, ``t_host_ns`` the
host ``time.monotonic_ns()`` (one clock for all processes) at which the world published the sample to
its emulators and ``t_due_ns`` the host time at which it was due (the same, unless the world ran late).

Computed ahead (``ahead``, ``ftc sim --world-ahead``): the world's process computes the whole run before
its emulators start (``start()`` waits for it; ``on_progress`` hears how far it got) and then only plays
it: the emulators read the stored run on the wall clock, commands are recorded and change nothing (the
arm goes on as computed: :mod:`ftc_hw.sim_devices.ahead`).

Steering: halt the arm, set its joint targets, kill, restart, suspend (SIGSTOP: a hung device) and
resume an emulator, the commands the world applied (with host and world times), the world's time,
and its joint and F/T samples from the shared-memory rings (no F/T ring when the scene has no F/T
sensor; samples then come at the joints' rate: ``ftc_hw.model.sample_rate_hz``).
"""
from __future__ import annotations

import contextlib
import dataclasses
import math
import multiprocessing as mp
import os
import random
import select
import signal
import socket
import sys
import threading
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from ftc_hw.model import Payload, sample_rate_hz
from ftc_hw.model.true_arm import true_arm_spec
from ftc_hw.priority import end_process, name_process
from ftc_hw.scene import DeviceSpec, Scene, load_scene

from .ahead import AheadError, AheadRunner, AheadSpan, TruthPlayer
from .link import FT_WIDTH, Command, JointRecord, NoFTRingError, Ring, RingReader
from .played import PlayedRing
from .runner import AppliedCommand, SimRunner
from .world import Hold, Reality, with_reality
from .world.truth import truth_line

UR_PORTS = (30004, 29999)  # RTDE (hard-coded by ur_rtde) and dashboard
START_TIMEOUT_S = 90.0  # without `ftc warm` first, the world compiles its kernels


class WorldHostError(RuntimeError):
    """The world process failed, or did not answer (the message says which)."""


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
    raise WorldHostError(f"no loopback address with ports {ports} free")


@dataclasses.dataclass(frozen=True)
class _Plan:
    """What the child builds and runs (pickled to it)."""

    scene: Scene
    scenario: str
    devices: tuple[DeviceSpec, ...]
    options: dict[str, dict]
    duration: float | None
    seed: int
    noise: bool
    preroll: bool
    realtime: bool
    truth: str | None
    payload: Payload | None
    ahead: AheadSpan | None = None  # the run computed first (this much around it), then played (ahead.py)


class _Quit(Exception):
    pass


class _Go(Exception):
    pass


class _Child:
    """The world process: the runner, the pipe, and the phases."""

    def __init__(self, conn: Any, plan: _Plan, runner: SimRunner) -> None:
        self.conn = conn
        self.plan = plan
        self.runner = runner
        self.lock = threading.Lock()
        self.counts = {"samples": 0, "contact": 0}
        self.t_go: float | None = None  # world time at go (the scenario's t = 0)
        # polled after every sample: a poll object on the pipe costs 0.3 us, the Connection's poll() 2.3 us
        self._pipe = select.poll()
        self._pipe.register(conn.fileno(), select.POLLIN)

    def reply(self, kind: str, value: Any) -> None:
        with self.lock:
            self.conn.send((kind, value))

    def poll(self, go_ok: bool = False) -> None:
        while self._pipe.poll(0):  # a message, or the parent's end closed (recv raises EOFError)
            self.handle(self.conn.recv(), go_ok)

    def handle(self, msg: tuple, go_ok: bool) -> None:
        op, arg = msg
        if op == "quit":
            raise _Quit
        if op == "go":
            if go_ok:
                raise _Go
            return
        if op == "halt":
            self.runner.world.halt()
            return
        if op == "restart":  # in a thread: the world keeps stepping while the emulator starts
            threading.Thread(target=self._restart, args=arg, daemon=True).start()
            return
        try:
            self.reply("ok", self._answer(op, arg))
        except Exception as exc:  # noqa: BLE001 - reported to the caller, which raises
            self.reply("error", f"{type(exc).__name__}: {exc}")

    def _answer(self, op: str, arg: Any) -> Any:
        runner = self.runner
        if op == "kill":
            runner.emulator(arg).kill()
        elif op in ("suspend", "resume"):
            os.kill(runner.emulator(arg).process.pid, signal.SIGSTOP if op == "suspend" else signal.SIGCONT)
        elif op == "applied":
            return runner.applied[arg or 0:]
        elif op == "applied_count":
            return len(runner.applied)
        elif op == "time":
            return runner.world.t
        elif op == "scenario_time":
            return None if self.t_go is None else runner.world.t - self.t_go
        elif op == "goal":  # applied like an emulator's goal command, between two steps
            runner.apply(Command("world-host", "goal", q=tuple(float(x) for x in arg)))
        else:
            raise ValueError(f"unknown request {op!r}")
        return None

    def _restart(self, name: str, options: dict | None) -> None:
        try:
            self.reply("ok", self.runner.restart_emulator(name, options))
        except Exception as exc:  # noqa: BLE001
            self.reply("error", f"{type(exc).__name__}: {exc}")

    def serve(self) -> None:
        runner, world = self.runner, self.runner.world
        t_go = 0.0
        if self.plan.preroll:
            world.set_reference(Hold(np.asarray(world.setup.trajectory.reference(0.0)[0], dtype=float)))
            world.hold_script()  # nothing scripted happens before go, however long the pre-roll
            runner.duration = 1e12
            with contextlib.suppress(_Go):
                runner.run(realtime=self.plan.realtime, on_sample=lambda _state: self.poll(go_ok=True))
            t_go = world.t
            world.set_reference(world.setup.trajectory)
            world.start_script()
        runner.duration = self.plan.duration if self.plan.duration is not None else 1e12
        self.t_go = t_go
        self._scenario(t_go)
        self.reply("done", {**self.counts, "t": world.t - t_go, "preroll_s": t_go})
        runner.duration = 1e12
        runner.run(realtime=self.plan.realtime, on_sample=lambda _state: self.poll())

    def _scenario(self, t_go: float) -> None:
        clock0, t0 = time.monotonic_ns(), self.runner.world.t
        with contextlib.ExitStack() as stack:
            out = stack.enter_context(open(self.plan.truth, "w", encoding="utf-8")) if self.plan.truth else None

            def on_sample(state: Any) -> None:
                now = time.monotonic_ns()
                self.counts["samples"] += 1
                self.counts["contact"] += bool(state.contacts)
                if out is not None:
                    fields = {"t": round(state.t - t_go, 9), "t_world": round(state.t, 9)}  # scenario, world time
                    if self.plan.realtime:  # as fast as it goes, the world runs ahead of any clock
                        fields["t_host_ns"] = now
                        fields["t_due_ns"] = clock0 + round((state.t - t0) * 1e9)
                    out.write(truth_line(state, fields))
                self.poll()

            self.runner.run(realtime=self.plan.realtime, on_sample=on_sample)


class _AheadChild(_Child):
    """The world process when the run was computed ahead (:class:`AheadRunner`): nothing steps; it waits on
    the pipe and the emulators' commands (recorded: the played run goes on), writes the truth lines as
    they fall due, and says when the scenario has played."""

    runner: AheadRunner

    def __init__(self, conn: Any, plan: _Plan, runner: AheadRunner) -> None:
        super().__init__(conn, plan, runner)
        self._both = select.poll()  # the pipe and the command socket: what wakes this process
        self._both.register(conn.fileno(), select.POLLIN)
        self._both.register(runner.link.fileno(), select.POLLIN)

    def handle(self, msg: tuple, go_ok: bool) -> None:
        if msg[0] == "halt":  # the world cannot halt a played run: recorded as a stop
            self.runner.apply(Command("world-host", "stop"))
            return
        super().handle(msg, go_ok)

    def _answer(self, op: str, arg: Any) -> Any:
        if op == "time":
            return self.runner.now()
        if op == "scenario_time":
            return None if self.t_go is None else self.runner.now() - self.t_go
        return super()._answer(op, arg)

    def _wait(self, timeout_s: float, go_ok: bool = False) -> None:
        self._both.poll(timeout_s * 1e3)
        self.runner.apply_pending()
        self.poll(go_ok)

    def serve(self) -> None:
        runner = self.runner
        t_go = runner.play()
        if self.plan.preroll:
            with contextlib.suppress(_Go):
                while True:
                    self._wait(0.05, go_ok=True)
            try:
                t_go = runner.go()
            except AheadError as exc:
                self.counts["late_go"] = 1
                print(f"ftc-world: {exc}", file=sys.stderr, flush=True)
                t_go = runner.stored.info.t_go + runner.scenario_shift
        self.t_go = t_go
        with contextlib.ExitStack() as stack:
            out = stack.enter_context(open(self.plan.truth, "w", encoding="utf-8")) if self.plan.truth else None
            truth = TruthPlayer(runner, out)
            stack.callback(truth.close)
            while not truth.done:
                self._wait(0.05)
                truth.write_due()
        stored = runner.stored
        self.reply("done", {**self.counts, "samples": stored.samples, "contact": stored.contact,
                            "t": runner.now() - t_go, "preroll_s": t_go - runner.streams["joints"].t0,
                            "ahead_s": stored.compute_s})
        while True:
            self._wait(0.5)


def _main(conn: Any, plan: _Plan) -> None:
    """Entry point of the world process."""
    # Ctrl-C is its host's, which closes the world (quit on the pipe, or the pipe's end); the emulators
    # it starts inherit the ignored SIGINT (spawn keeps it across exec): the terminal's Ctrl-C reaches
    # every process of its group, and a world or an emulator cut short by it would leave no report
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    name_process("ftc-world")
    try:
        t0 = time.monotonic()
        kwargs = dict(duration=plan.duration or 1e12, seed=plan.seed, noise=plan.noise, devices=plan.devices,
                      options=plan.options, payload=plan.payload)
        runner = (AheadRunner(plan.scene, plan.scenario, preroll=plan.preroll, span=plan.ahead, **kwargs)
                  if plan.ahead is not None else SimRunner(plan.scene, plan.scenario, **kwargs))
        world_s = time.monotonic() - t0
        ahead_s = {}
        if isinstance(runner, AheadRunner):
            try:
                ahead_s["ahead"] = runner.compute(lambda done, of: conn.send(("progress", (done, of)))).compute_s
            except BaseException:
                runner.stop()
                raise
        endpoints = runner.start()
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which raises; start() cleaned up
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    child = _AheadChild(conn, plan, runner) if isinstance(runner, AheadRunner) else _Child(conn, plan, runner)
    try:
        child.reply("ready", {"endpoints": endpoints, "joint_ring": runner.link.joints.name,
                              "ft_ring": runner.link.info.ft_ring, "n_joints": plan.scene.n_joints,
                              "played": runner.link.info.played,
                              "sample_period_s": 1.0 / runner.world.sample_rate_hz,
                              "startup_s": {"world": world_s, **ahead_s, **{e.device.name: e.started_s
                                                                           for e in runner.emulators}}})
        child.serve()
    except (_Quit, EOFError, BrokenPipeError, KeyboardInterrupt):
        pass
    finally:
        runner.stop()
    end_process()  # the truth file closed, the report sent, the emulators ended and the rings unlinked


def _device_specs(scene: Scene, devices: Iterable[str | DeviceSpec] | None) -> tuple[DeviceSpec, ...]:
    """The devices to emulate: the scene's (None), or these names of the scene's and specs of one's own."""
    if devices is None:
        return tuple(scene.devices)
    by_name = {d.name: d for d in scene.devices}
    out = []
    for d in devices:
        if isinstance(d, DeviceSpec):
            out.append(d)
        elif d in by_name:
            out.append(by_name[d])
        else:
            raise ValueError(f"scene {scene.name!r} has no device {d!r} (it has: {', '.join(by_name) or 'none'})")
    return tuple(out)


class WorldHost:
    """``start()`` -> (connect clients; ``go()`` after a pre-roll) -> ``done`` -> ``close()``; or
    ``with WorldHost(scene, "hold", devices=["arm"]) as world:``.

    ``scene``: a scene, or a built-in name or scene file. ``devices``: what to emulate: None, every
    device the scene declares; else device names of the scene or :class:`DeviceSpec` s of one's own
    (another transport, a second sensor). ``options``: per device name, the emulator's options
    (faults, seed, paths...); a UR arm gets a free loopback address unless one is given.
    ``payload``: a payload the devices' clients are not told about (calibration). ``ahead``: the run
    (pre-roll, ``duration``, post-roll) is computed first, as fast as it goes, then played to the emulators
    on the wall clock (:mod:`ftc_hw.sim_devices.ahead`: commands are recorded and the played run goes on);
    an :class:`AheadSpan` says how long the pre-roll and post-roll computed around the scenario are.
    """

    def __init__(self, scene: Scene | str, scenario: str = "hold", *, devices: Iterable[str | DeviceSpec] | None = None,
                 options: dict[str, dict] | None = None, duration: float | None = None, seed: int = 0,
                 noise: bool = True, preroll: bool = False, realtime: bool = True, truth: Path | None = None,
                 payload: Payload | None = None, reality: Reality | str = Reality.IDEAL,
                 reality_seed: int | None = None, ahead: bool | AheadSpan = False) -> None:
        if ahead and (duration is None or not realtime):
            raise AheadError("a world computed ahead needs a duration, and plays in real time")
        scene = load_scene(scene) if isinstance(scene, str) else scene
        specs = _device_specs(scene, devices)
        # the world's arm: the scene's [world] and a draw of the reality (seeded by the run's seed unless
        # given); drawn and checked here, so a bad [world] table fails before any process starts
        true_scene = with_reality(scene, reality, seed if reality_seed is None else reality_seed)
        true_arm_spec(true_scene)
        options = {k: dict(v) for k, v in (options or {}).items()}
        for d in specs:
            if d.kind == "ur-rtde":
                options.setdefault(d.name, {}).setdefault("address", free_loopback())
        self.scene = scene
        self._plan = _Plan(true_scene, scenario, specs, options, duration, seed, noise, preroll, realtime,
                           str(truth) if truth else None, payload,
                           (ahead if isinstance(ahead, AheadSpan) else AheadSpan()) if ahead else None)
        self.on_progress: Any = None  # with ahead: called with (simulated s computed, of how many) while it computes
        self._proc: Any = None
        self._conn: Any = None
        self._rings: dict[str, Ring | PlayedRing] = {}
        self.endpoints: dict[str, dict[str, Any]] = {}
        self.sample_period_s = 1.0 / sample_rate_hz(scene)
        self.result: dict[str, Any] | None = None
        self._pipe_lock = threading.RLock()
        self.startup_s: dict[str, float] = {}  # seconds to build the world ("world"), to start each emulator
        self.up_since = math.nan  # time.monotonic() when it was up: its pre-roll runs from then

    # -- lifecycle ---------------------------------------------------------------------------------------
    def start(self, timeout: float = START_TIMEOUT_S) -> dict[str, dict[str, Any]]:
        """Start the world and its emulators; returns the endpoints by device name."""
        self.launch()
        return self.wait_started(timeout)

    def launch(self) -> None:
        """Start the world's process, which builds the world and starts the emulators, and return at once: the
        caller does its own set-up meanwhile (on another core), then :meth:`wait_started`."""
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        # not a daemon: it starts the emulator processes; it quits when our end of the pipe closes
        self._proc = ctx.Process(target=_main, args=(child, self._plan), name=f"ftc-world:{self.scene.name}")
        self._proc.start()
        child.close()

    def wait_started(self, timeout: float = START_TIMEOUT_S) -> dict[str, dict[str, Any]]:
        """Until the launched world is up (WorldHostError when it fails or ``timeout`` s pass without a word from
        it); the endpoints by device name."""
        try:
            kind, info = self._recv(timeout)
            while kind == "progress":  # a world computed ahead: the timeout runs from its last word
                if self.on_progress is not None:
                    self.on_progress(*info)
                kind, info = self._recv(timeout)
        except WorldHostError as exc:
            self.close()
            raise WorldHostError(f"the simulated world did not start: {exc}") from None
        if kind != "ready":
            self.close()
            raise WorldHostError(f"the simulated world failed to start: {info}")
        self.endpoints = {e["name"]: e for e in info["endpoints"]}
        n, played = info["n_joints"], info["played"]
        if played is not None:  # the stored run, as the emulators read it
            self._rings = {"joints": PlayedRing(played, ft=False)}
            if played.ft is not None:
                self._rings["ft"] = PlayedRing(played, ft=True)
        else:
            self._rings = {"joints": Ring(JointRecord.width(n), name=info["joint_ring"], create=False)}
            if info["ft_ring"] is not None:  # None: the scene has no F/T sensor
                self._rings["ft"] = Ring(FT_WIDTH, name=info["ft_ring"], create=False)
        self.sample_period_s = info["sample_period_s"]
        self.startup_s = info["startup_s"]
        self.up_since = time.monotonic()
        return self.endpoints

    def close(self) -> None:
        """Stop the world and its emulators (idempotent)."""
        if self._conn is not None:
            with contextlib.suppress(OSError, BrokenPipeError):
                self._conn.send(("quit", None))
        if self._proc is not None:
            self._proc.join(20.0)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join(5.0)
        self._drain()  # collect the final report if it came
        for ring in self._rings.values():
            ring.close()  # attached, not owned: closes without unlinking
        self._rings = {}
        if self._conn is not None:
            self._conn.close()
        self._conn = self._proc = None

    def __enter__(self) -> WorldHost:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the pipe ----------------------------------------------------------------------------------------
    def _take(self, msg: tuple[str, Any]) -> tuple[str, Any] | None:
        """A message for the caller, or None when it was the end-of-run report (kept in ``result``)."""
        if msg[0] == "done":
            self.result = msg[1]
            return None
        return msg

    def _recv(self, timeout: float) -> tuple[str, Any]:
        end = time.monotonic() + timeout
        while True:
            left = end - time.monotonic()
            try:
                if left <= 0 or not self._conn.poll(left):
                    raise WorldHostError(f"no answer from the world process within {timeout:g} s")
                msg = self._take(self._conn.recv())
            except (EOFError, OSError):
                code = self._proc.exitcode if self._proc is not None else None
                raise WorldHostError(f"the world process ended (exit code {code})") from None
            if msg is not None:
                return msg

    def _drain(self) -> None:
        """Take what the world sent unasked (its end-of-run report; a late answer is dropped)."""
        if self._conn is None:
            return
        with self._pipe_lock:
            self._drain_locked()

    def _drain_locked(self) -> None:
        try:
            while self._conn.poll():
                self._take(self._conn.recv())
        except (EOFError, OSError):
            if self.result is None:
                self.result = {"error": "the world process ended without a report"}

    def _send(self, op: str, arg: Any = None) -> None:
        if self._conn is None:
            raise WorldHostError("the world is not running (start() first)")
        with contextlib.suppress(OSError, BrokenPipeError):
            self._conn.send((op, arg))

    def _call(self, op: str, arg: Any = None, timeout: float = 30.0) -> Any:
        with self._pipe_lock:  # one question and its answer at a time (a fault plan calls from its thread)
            self._send(op, arg)
            kind, value = self._recv(timeout)
        if kind != "ok":
            raise WorldHostError(f"world process: {op} {arg if arg is not None else ''}: {value}")
        return value

    # -- the run ---------------------------------------------------------------------------------------------
    def go(self) -> None:
        """End the pre-roll: the scenario starts from its own t = 0."""
        self._send("go")

    @property
    def done(self) -> bool:
        """The scenario ran its ``duration`` (:attr:`result` holds the world's report)."""
        self._drain()
        return self.result is not None

    def wait_done(self, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while not self.done and time.monotonic() < end:
            time.sleep(0.05)
        return self.done

    def halt(self) -> None:
        """Stop the arm where it is (what a stop command does), for scenes without an arm device."""
        self._send("halt")

    def goal(self, q) -> None:
        """Set the world's joint targets (a hold at q, rad), applied like an emulator's goal command:
        how a simulated arm whose protocol has no motion command (UR RTDE receive) is moved."""
        self._call("goal", [float(x) for x in q])

    def sim_time(self) -> float:
        """The world's time, s (pre-roll included)."""
        return self._call("time")

    def scenario_time(self) -> float | None:
        """The scenario's time, s (0 at ``go()``); None before it starts."""
        return self._call("scenario_time")

    def applied(self, since: int = 0) -> list[AppliedCommand]:
        """The commands the world applied, from the ``since``-th on."""
        return self._call("applied", since)

    def applied_count(self) -> int:
        return self._call("applied_count")

    # -- the emulators ---------------------------------------------------------------------------------------
    def endpoint(self, name: str) -> dict[str, Any]:
        try:
            return self.endpoints[name]
        except KeyError:
            raise KeyError(f"no emulated device {name!r} (emulated: {', '.join(self.endpoints) or 'none'})") from None

    def kill(self, name: str) -> None:
        """SIGKILL the emulator of device ``name`` (a pulled plug)."""
        self._call("kill", name)

    def restart(self, name: str, options: dict | None = None) -> dict[str, Any]:
        """Start the emulator of ``name`` again (with new ``options`` if given); returns its endpoint once
        it is ready."""
        self.endpoints[name] = self._call("restart", (name, options), timeout=60.0)
        return self.endpoints[name]

    def suspend(self, name: str) -> None:
        """SIGSTOP the emulator (a hung device: sockets and ptys stay open, nothing answers)."""
        self._call("suspend", name)

    def resume(self, name: str) -> None:
        self._call("resume", name)

    # -- the world's samples -----------------------------------------------------------------------------------
    def joint_reader(self, from_start: bool = False) -> RingReader:
        """The joint ring's records, each read by ``JointRecord.from_row(record, scene.n_joints)``."""
        return RingReader(self._ring("joints"), from_start=from_start)

    def ft_reader(self, from_start: bool = False) -> RingReader:
        """Records ``[t, wrench (6, sensor frame, as the device reports it), saturated (6)]``; a
        :class:`NoFTRingError` when the scene has no F/T sensor."""
        if self._plan.scene.sensor is None:
            raise NoFTRingError(f"scene {self.scene.name!r} has no F/T sensor: its world has no F/T ring")
        return RingReader(self._ring("ft"), from_start=from_start)

    def _ring(self, which: str) -> Ring:
        if which not in self._rings:
            raise WorldHostError("the world is not running (start() first)")
        return self._rings[which]

    def latest_joints(self) -> JointRecord | None:
        """The world's newest joint sample (None before the first)."""
        rec = self.joint_reader().latest()
        return None if rec is None else JointRecord.from_row(rec, self.scene.n_joints)
