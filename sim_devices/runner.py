"""The world's loop: the physics world stepped (in real time, or as fast as it goes), its samples
published to the emulators over the :class:`~ftc_hw.sim_devices.link.WorldLink`, the emulators'
commands applied; one emulator process per device. It runs inside the world process that
:class:`~ftc_hw.sim_devices.host.WorldHost` starts."""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ftc_hw.model import ArmModel, Payload
from ftc_hw.priority import WORLD_NICE, prefer_cpu
from ftc_hw.scene import DeviceSpec, Scene

from .launch import EmulatorProcess
from .link import Command, WorldLink
from .world import World, WorldState, build_scenario

STEP_LATE_S = 0.15e-3  # how late a step may be computed, to share the next one's wake-up (real time)


@dataclass(frozen=True)
class AppliedCommand:
    t_host_ns: int  # time.monotonic_ns() in the world process when the world applied it
    t_sim: float  # world time (s) at that step
    kind: str
    q: tuple[float, ...] | None
    on: bool | None = None
    t_sent_ns: int = 0  # when the emulator sent it (time.monotonic_ns() in its process)
    t_due_ns: int = 0  # host time at which t_sim is due in the real-time run: the arm's own clock
    t_rx_ns: int = 0  # when the emulator read the request that caused it (0: not recorded)


def _velocity(qd: Any, n: int) -> np.ndarray | None:
    """A goal command's joint velocities, or None when it carries none or not n finite numbers (then held)."""
    try:
        v = np.asarray(qd, dtype=float)
    except (TypeError, ValueError):
        return None
    return v if v.shape == (n,) and np.all(np.isfinite(v)) else None


class SimRunner:
    """The world and the emulators of ``devices``. ``start()``, then ``step()``/``run()``; ``stop()``
    cleans up. ``applied`` lists every command the world applied, with when."""

    def __init__(self, scene: Scene, scenario: str, *, duration: float, seed: int = 0, noise: bool = True,
                 devices: Sequence[DeviceSpec] = (), options: dict[str, dict] | None = None,
                 payload: Payload | None = None) -> None:
        self.scene = scene
        self.scenario = scenario
        self.duration = duration
        setup = build_scenario(scenario, scene, ArmModel(scene), seed, duration)
        if payload is not None:  # a payload the devices' clients do not know about (calibration tests)
            setup = dataclasses.replace(setup, payload=payload)
        self.world = World(scene, setup, seed=seed, noise=noise)
        self.link = WorldLink(scene.n_joints, ft=scene.sensor is not None)
        self.out: Any = self.link  # where the samples go: the link's rings (a run computed ahead: its store)
        self.devices = tuple(devices)
        self.options = options or {}
        self.emulators: list[EmulatorProcess] = []
        self.applied: list[AppliedCommand] = []
        self._clock: tuple[int, float] | None = None  # (host ns, world s) at the start of run()

    def start(self) -> list[dict[str, Any]]:
        # joint state first, so emulators that answer at once have something to serve
        self.publish_state()
        # launched together, waited for together: their start-ups (imports, binding) overlap
        launched = []
        try:
            for d in self.devices:
                launched.append(EmulatorProcess.launch(d, self.scene, self.link.info, self.options.get(d.name)))
            for pending in launched:
                self.emulators.append(pending.wait())
        except Exception:
            for pending in launched[len(self.emulators):]:
                pending.cancel()
            self.stop()
            raise
        # after the emulators started (they take their own tier, below the world's): the world's
        # steps stand in for the arm controllers' cycles
        prefer_cpu(WORLD_NICE)
        return [e.endpoint for e in self.emulators]

    def publish_state(self) -> None:
        """The world's current state, its joint sample and F/T reading: what comes before its first step."""
        self._publish(self.world.state, with_ft=True)

    def _publish(self, state: WorldState, with_ft: bool) -> None:
        """The joint sample (every step) and, ``with_ft`` and where the scene has an F/T sensor, its reading."""
        w, out = self.world, self.out
        if with_ft and w.sensor is not None:
            reading = w.read_sensor(state)
            out.publish_ft(state.t, reading.wrench, reading.saturated)
        out.publish_joints(state.t, state.q, state.qd, state.qdd, w.read_current(state), state.tau,
                                 w.read_joint_torques(state))

    def emulator(self, name: str) -> EmulatorProcess:
        for e in self.emulators:
            if e.device.name == name:
                return e
        raise KeyError(f"no emulator of device {name!r}")

    def restart_emulator(self, name: str, options: dict | None = None) -> dict[str, Any]:
        """Stop the emulator of ``name`` and start it again (with new ``options`` if given): its endpoint."""
        old = self.emulator(name)
        old.stop()
        if options is not None:
            self.options[name] = options
        new = EmulatorProcess.start(old.device, self.scene, self.link.info, self.options.get(name))
        self.emulators[self.emulators.index(old)] = new
        return new.endpoint

    def record(self, cmd: Command, t: float) -> None:
        """Keep ``cmd`` among the commands applied, at world time ``t``."""
        self.applied.append(AppliedCommand(time.monotonic_ns(), t, cmd.kind, cmd.q, cmd.on, cmd.t_sent_ns,
                                           self.due_ns(t) or 0, int(cmd.extra.get("t_rx_ns", 0))))

    def apply(self, cmd: Command) -> None:
        self.record(cmd, self.world.t)
        if cmd.kind == "goal" and cmd.q is not None:
            qd = _velocity(cmd.extra.get("qd"), len(cmd.q))  # a servo stream's feed-forward (the UR program's servoj)
            self.world.set_goal(np.asarray(cmd.q, dtype=float), qd, float(cmd.extra.get("horizon_s", 0.0)))
        elif cmd.kind == "stop":
            self.world.halt()
        elif cmd.kind == "resume":
            self.world.resume()
        elif cmd.kind == "torque":
            self.world.set_torque(bool(cmd.on))

    def apply_pending(self) -> None:
        """Apply every command that has arrived (from the world's current time on)."""
        for cmd in self.link.drain_commands():
            self.apply(cmd)

    def step(self, drain: bool = True) -> WorldState:
        """One physics step, its samples published; first the commands that arrived (``drain``; False: the
        caller has just seen that none did)."""
        if drain:
            self.apply_pending()
        state = self.world.step()
        self._publish(state, with_ft=self.world.steps % self.world.steps_per_sample == 0)
        return state

    def due_ns(self, t: float) -> int | None:
        """The host time (``time.monotonic_ns``) at which world time ``t`` is due in a real-time run."""
        if self._clock is None:
            return None
        wall0_ns, t0 = self._clock
        return wall0_ns + round((t - t0) * 1e9)

    def run(self, realtime: bool = True, on_sample=None) -> None:
        """Until ``duration`` simulated seconds; ``on_sample(state)`` at each sample (the world's sample rate).

        Real time: a step is computed when the host clock reaches its start time (states are never
        published ahead of their time), and while waiting for it the world wakes on every command
        and applies it at once, so a stop takes effect within the transport's latency, not the
        world's step pacing. Steps shorter than ``STEP_LATE_S`` go in groups, one wake-up each: the
        world waits until the group's last step is due, then computes them all (at 7 kHz two steps
        a wake-up, the first published up to one step late; a wake-up costs ~25-35 us of CPU here)."""
        w = self.world
        t0, step0 = w.t, w.steps
        self._clock = (time.monotonic_ns(), t0) if realtime else None
        group = 1 + int(STEP_LATE_S / w.dt + 1e-9)  # steps computed per wake-up
        quiet = False  # the wait before this step ended by its timeout: no command came (no need to look again)
        while w.t - t0 < self.duration - 1e-12:
            state = self.step(drain=not quiet)
            if on_sample is not None and w.steps % w.steps_per_sample == 0:
                on_sample(state)
            quiet = False
            if realtime and (w.steps - step0) % group == 0:  # until the last step of the next group is due
                due = self.due_ns(w.t + (group - 1) * w.dt)
                while (left := due - time.monotonic_ns()) > 0:
                    quiet = not self.link.wait_commands(left / 1e9)
                    if not quiet:
                        self.apply_pending()

    def stop(self) -> None:
        for e in self.emulators:  # all asked first: each takes a few 0.1 s to end, and they end together
            e.ask_to_stop()
        for e in self.emulators:
            e.stop()
        self.emulators = []
        self.link.close()

    def __enter__(self) -> SimRunner:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
