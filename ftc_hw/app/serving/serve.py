"""``ftc serve``: each of a scene's device readers in its own process, supervised, publishing to Zenoh.

The serve process is a Zenoh router listening on ``listen`` (loopback unless the user names other
endpoints); each reader process is a Zenoh client of it that opens one device's adapter on its own bus
and forwards the bus to Zenoh (``ftc/<rig>/wrench/<device>``, ``joints/<device>``, ``events/device``:
docs/bus.md). A reader's computing is its own: nothing another process does can make it miss a packet.

Supervision: a reader process that exits (crashed, killed) is restarted, at once the first time and
then with a backoff doubling to ``max_backoff_s`` while it keeps dying; each exit and restart is a
``DeviceEvent`` on ``events/device`` (``error``, then ``reconnecting``), so every subscriber knows.
Reader processes are forked from a fork server that has imported the adapters already (a restart
takes tens of milliseconds, not the seconds of a fresh interpreter).

With ``sim``, the scene's world and emulators run first, as ``ftc sim`` starts them, holding the
scenario's start pose for ``hold_s`` after the readers' first frames (a monitor connecting then can tare
at rest), then playing it.
"""
from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh

from ftc_hw.app.setup.rig import RigError, build_rig, check_located
from ftc_hw.bus import EVENTS_DEVICE, Bus, DeviceEvent
from ftc_hw.bus.remote import RemotePublisher, open_session, stop_key
from ftc_hw.bus.wire import decode
from ftc_hw.devices.registry import role_of
from ftc_hw.priority import READER_NICE, name_process, prefer_cpu
from ftc_hw.scene import DeviceSpec, Scene, SceneError, load_rig_scene

DEFAULT_LISTEN = "tcp/127.0.0.1:7447"
COUNTERS_PERIOD_S = 1.0  # how often a reader process says its adapter's counters
# A reader process's threads (poll loop, Zenoh's callbacks) are light: a stop command waits at most this
# long for the interpreter (at the monitor's 0.5 ms the reflex's median crossing was 1.1-1.3 ms, here 0.8)
READER_PROCESS_SWITCH_S = 0.0001
_PRELOAD = ["numpy", "zenoh", "ftc_hw.bus.remote", "ftc_hw.devices.registry", "ftc_hw.app.setup.rig",
            "ftc_hw.scene"]


class ServeError(RuntimeError):
    """The devices cannot be served: no such device, an endpoint in use, a world that does not start."""


@dataclass
class ServeConfig:
    scene: str
    devices: tuple[str, ...] = ()  # device names (default: every device of the scene with an adapter)
    rig: str | None = None  # the key chunk in ftc/<rig>/... (default: the scene's name)
    listen: tuple[str, ...] = (DEFAULT_LISTEN,)
    device_overrides: tuple[str, ...] = ()
    rig_file: Path | None = None
    sim: bool = False
    scenario: str = "sweep-with-collision"
    seed: int = 0
    reality: str = "ideal"
    hold_s: float = 2.0
    duration: float | None = None  # seconds (with sim: of the scenario), None: until stopped
    max_backoff_s: float = 5.0
    zenoh_config: Path | None = None  # a Zenoh JSON5 file (TLS, user-password, access control): docs/bus.md


def reader_main(scene_ref: str, overrides: tuple[str, ...], rig_file: Path | None, device: str, rig: str,
                router: str, endpoint: Any, zenoh_config: Path | None = None, owner_pid: int = 0) -> None:
    """One device's reader (a process): its adapter on a local bus, the bus forwarded to Zenoh, until
    SIGTERM or until ``owner_pid`` (the process that started it: ftc serve, a monitor) is gone. Its adapter
    reconnects by itself; an exception ends the process (the supervisor restarts it)."""
    name_process(f"ftc-reader-{device}")
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    sys.setswitchinterval(READER_PROCESS_SWITCH_S)
    # ahead of ordinary processes, behind the devices (ftc_hw.priority), Zenoh's threads too: frames and
    # stop commands must not wait for a core. (The FIFO real-time class, tried for an arm's poll loop,
    # kept RTDE on a saturated 2-core host but starved the F/T reader and the monitor: docs/measurements/bus.md)
    prefer_cpu(READER_NICE, exact=True)
    scene = load_rig_scene(scene_ref, overrides, rig_file)
    spec = next(d for d in scene.devices if d.name == device)
    session = open_session(connect=[router], mode="client", config_file=zenoh_config)
    bus = Bus(history=2000)
    with RemotePublisher(session, bus, rig):
        the_rig = build_rig(scene, bus=bus, devices=[spec], endpoints={device: endpoint} if endpoint else None)
        with the_rig.open():
            adapter = the_rig.adapter(device)
            command = _StopCommands(session, rig, adapter, bus) if role_of(spec.kind) == "arm" else None
            while not stop.wait(COUNTERS_PERIOD_S) and _alive(owner_pid):  # orphaned: its owner was killed
                _say_counters(bus, adapter)
            if command is not None:
                command.close()
        _say_counters(bus, adapter, final=True)  # closed: its last word, sent before the session closes
    session.close()


class _StopCommands:
    """The arm's side of the reflex across processes: a remote monitor's onset (on the arm's stop key)
    stops the arm at once, in Zenoh's thread (a hand-over to another thread cost a wake-up); a
    ``stopped`` event says when, from the onset sample (one host's clock), and how long the call took."""

    def __init__(self, session: Any, rig: str, adapter: Any, bus: Bus) -> None:
        self.adapter, self.bus = adapter, bus
        self._sub = session.declare_subscriber(stop_key(rig, adapter.name),
                                               lambda sample: self._stop(sample.payload.to_bytes()))

    def _stop(self, payload: bytes) -> None:
        t0 = time.monotonic_ns()
        name = self.adapter.name
        try:
            onset = decode(payload)
            self.adapter.stop()
            t1 = time.monotonic_ns()
            self.bus.publish(EVENTS_DEVICE, DeviceEvent.make(
                t1, name, "stopped", f"stopped on a remote monitor's command (contact {onset.contact_id})",
                {"sent_after_onset_ms": (t0 - onset.t_host_ns) / 1e6, "stop_call_ms": (t1 - t0) / 1e6,
                 "contact_id": float(onset.contact_id)}))
        except Exception as exc:  # noqa: BLE001 - said on the bus; the reader goes on
            self.bus.publish(EVENTS_DEVICE, DeviceEvent.make(time.monotonic_ns(), name, "error",
                                                             f"stop command failed: {exc!r}"))

    def close(self) -> None:
        with contextlib.suppress(zenoh.ZError):
            self._sub.undeclare()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except (ProcessLookupError, PermissionError):  # gone, or the pid reused by someone else's process
        return False
    return True


def _say_counters(bus: Bus, adapter: Any, final: bool = False) -> None:
    """The adapter's counters as a ``counters`` device event (the message: its kind), for the monitor."""
    counters = {k: float(v) for k, v in adapter.counters.items()} | ({"final": 1.0} if final else {})
    bus.publish(EVENTS_DEVICE, DeviceEvent.make(time.monotonic_ns(), adapter.name, "counters", adapter.kind,
                                                counters))


@dataclass
class _Child:
    spec: DeviceSpec
    proc: Any = None
    started: float = 0.0
    restarts: int = 0
    backoff: float = 0.0
    due: float | None = None  # when a dead reader is to be started again


@dataclass
class Supervisor:
    """Starts a reader process per device and restarts the ones that exit, saying so on ``bus``."""

    start: Callable[[DeviceSpec], Any]  # -> a started process (``pid``, ``exitcode``, ``is_alive``)
    specs: Sequence[DeviceSpec]
    bus: Bus
    max_backoff_s: float = 5.0
    stable_s: float = 10.0  # a reader that ran this long starts over with no backoff
    children: dict[str, _Child] = field(default_factory=dict)

    def start_all(self) -> None:
        for spec in self.specs:
            self.children[spec.name] = _Child(spec, self.start(spec), time.monotonic())

    def poll(self) -> None:
        """Restart what died (at its due time); call it often (every 10 ms or so)."""
        now = time.monotonic()
        for name, c in self.children.items():
            if c.due is None and c.proc is not None and not c.proc.is_alive():
                ran = now - c.started
                c.backoff = 0.0 if ran >= self.stable_s else min(max(2 * c.backoff, 0.2), self.max_backoff_s)
                c.due = now + (0.0 if c.restarts == 0 or ran >= self.stable_s else c.backoff)
                self._say(name, "error", f"reader process of {name} (pid {c.proc.pid}) exited with code "
                                         f"{c.proc.exitcode} after {ran:.1f} s; restarting in {c.due - now:.1f} s")
            if c.due is not None and now >= c.due:
                c.proc, c.started, c.due = self.start(c.spec), now, None
                c.restarts += 1
                self._say(name, "reconnecting", f"reader process of {name} restarted (pid {c.proc.pid}, restart "
                                                f"{c.restarts})")

    def _say(self, name: str, kind: str, message: str) -> None:
        c = self.children[name]
        self.bus.publish(EVENTS_DEVICE, DeviceEvent.make(time.monotonic_ns(), name, kind, message,  # type: ignore[arg-type]
                                                         {"restarts": c.restarts}))

    def stop_all(self, timeout: float = 3.0) -> None:
        for c in self.children.values():
            if c.proc is not None and c.proc.is_alive():
                c.proc.terminate()
        end = time.monotonic() + timeout
        for c in self.children.values():
            if c.proc is not None:
                c.proc.join(max(0.0, end - time.monotonic()))
                if c.proc.is_alive():
                    c.proc.kill()


def served_devices(scene: Scene, names: Sequence[str]) -> list[DeviceSpec]:
    """The named devices (default: each with an adapter role); ServeError names an unknown one."""
    known = {d.name: d for d in scene.devices}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ServeError(f"no device {', '.join(unknown)} in scene {scene.name} (it has "
                         f"{', '.join(known) or 'none'})")
    specs = [known[n] for n in names] if names else [d for d in scene.devices if role_of(d.kind) is not None]
    if not specs:
        raise ServeError(f"scene {scene.name} has no device with an adapter to serve")
    return specs


class ServedReaders:
    """A Zenoh router on ``listen`` and a supervised reader process per device, publishing there; the
    supervisor polled in its own thread. ``start()``, ``stop()`` (idempotent; readers say their final
    counters first), a context manager. ``endpoints``: where each device's emulator is (sim), else None."""

    def __init__(self, scene: Scene, specs: Sequence[DeviceSpec], rig: str, listen: Sequence[str], *,
                 endpoints: dict[str, Any] | None = None, device_overrides: tuple[str, ...] = (),
                 rig_file: Path | None = None, zenoh_config: Path | None = None, max_backoff_s: float = 5.0) -> None:
        self.scene, self.specs, self.rig, self.listen = scene, list(specs), rig, list(listen)
        self.endpoints = endpoints or {}
        self.device_overrides, self.rig_file, self.zenoh_config = device_overrides, rig_file, zenoh_config
        self.bus = Bus(history=1000)
        self._ctx = mp.get_context("forkserver")
        self._ctx.set_forkserver_preload(_PRELOAD)
        self.supervisor = Supervisor(self._start_reader, self.specs, self.bus, max_backoff_s=max_backoff_s)
        self._stack = contextlib.ExitStack()
        self._quit = threading.Event()
        self._thread: threading.Thread | None = None
        self.session: Any = None  # the router's Zenoh session, once started

    def _start_reader(self, spec: DeviceSpec) -> Any:
        p = self._ctx.Process(target=reader_main, name=f"ftc-reader-{spec.name}", daemon=True,
                        args=(str(self.scene.path), self.device_overrides, self.rig_file, spec.name, self.rig,
                              self.listen[0], self.endpoints.get(spec.name), self.zenoh_config, os.getpid()))
        p.start()
        return p

    def start(self) -> ServedReaders:
        if self._thread is not None:
            return self
        session = self._stack.enter_context(contextlib.closing(open_session(
            listen=self.listen, mode="router", config_file=self.zenoh_config)))
        self.session = session
        self._stack.enter_context(RemotePublisher(session, self.bus, self.rig, prefixes=(EVENTS_DEVICE,)))
        self._stack.callback(self.supervisor.stop_all)
        self.supervisor.start_all()
        self._thread = threading.Thread(target=self._poll, name="ftc-reader-supervisor", daemon=True)
        self._thread.start()
        return self

    def _poll(self) -> None:
        while not self._quit.wait(0.01):
            self.supervisor.poll()

    @property
    def restarts(self) -> int:
        return sum(c.restarts for c in self.supervisor.children.values())

    def describe(self) -> str:
        return ", ".join(f"{s.name} ({s.kind}, pid {self.supervisor.children[s.name].proc.pid})" for s in self.specs)

    def stop_readers(self) -> None:
        """The supervisor stops restarting and every reader process is stopped (each says its final
        counters first); the router stays up until ``stop()`` so that they arrive."""
        self._quit.set()
        if self._thread is not None:
            self._thread.join(2.0)
        self.supervisor.stop_all()

    def stop(self) -> None:
        self.stop_readers()
        self._stack.close()

    def __enter__(self) -> ServedReaders:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def run_serve(cfg: ServeConfig, say: Callable[[str], None] = print) -> int:
    """Serve until ``cfg.duration`` is up or SIGINT/SIGTERM; 0 when every reader ran to the end."""
    try:
        scene = load_rig_scene(cfg.scene, cfg.device_overrides, cfg.rig_file)
    except SceneError as exc:
        raise ServeError(str(exc)) from None
    specs = served_devices(scene, cfg.devices)
    if not cfg.sim:
        try:  # said before any process starts: each device must say where it is
            check_located(specs)
        except RigError as exc:
            raise ServeError(str(exc)) from None
    rig = cfg.rig or scene.name
    stop = threading.Event()
    with contextlib.ExitStack() as stack:
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, lambda *_: stop.set())
        world = _start_world(cfg, scene, stack, say) if cfg.sim else None
        readers = stack.enter_context(ServedReaders(
            scene, specs, rig, cfg.listen, endpoints=world.endpoints if world is not None else None,
            device_overrides=cfg.device_overrides, rig_file=cfg.rig_file, zenoh_config=cfg.zenoh_config,
            max_backoff_s=cfg.max_backoff_s))
        say(f"serving {readers.describe()} as ftc/{rig}/... on {', '.join(cfg.listen)}")
        t_go = time.monotonic() + cfg.hold_s if world is not None else None
        end = None if cfg.duration is None else time.monotonic() + cfg.duration + (cfg.hold_s if world else 0.0)
        while not stop.is_set() and (end is None or time.monotonic() < end):
            if t_go is not None and time.monotonic() >= t_go:
                world.go()
                say(f"the world plays {cfg.scenario}")
                t_go = None
            stop.wait(0.01)
        restarts = readers.restarts
    say(f"stopped; reader restarts: {restarts}")
    return 0 if restarts == 0 else 3


def _start_world(cfg: ServeConfig, scene: Scene, stack: contextlib.ExitStack, say: Callable[[str], None]) -> Any:
    from ftc_hw.sim_devices.host import WorldHost  # lazy: the world only with sim

    world = WorldHost(scene, cfg.scenario, duration=cfg.duration, seed=cfg.seed, preroll=True, reality=cfg.reality)
    try:
        world.start()
    except Exception as exc:  # noqa: BLE001 - emulator start failures carry their reason
        raise ServeError(f"the world did not start: {exc}") from None
    stack.callback(world.close)
    say(f"world and emulators of {scene.name} up (reality {cfg.reality}); holding the start pose {cfg.hold_s:g} s")
    return world

