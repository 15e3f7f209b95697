"""The devices a calibration talks to: the scene's F/T sensor and arm adapters on a bus, real or
emulated (``sim=True``: the world in its own process with one emulator process per device, and an
optional payload the clients are not told about).

How the arm gets to a pose depends on what its protocol can do:
- DYNAMIXEL: Goal Position, streamed along a minimum-jerk path (the servos run without profiles).
- UR (RTDE receive only: no motion commands): a person jogs it there; with ``sim=True`` the world's
  joint targets are set directly through the world process (:meth:`WorldHost.goal`), which the
  wizard says on screen.
"""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ftc_hw.app.setup.rig import Rig, RigError, build_rig, require_device
from ftc_hw.bus import Bus, joints_topic, wrench_topic
from ftc_hw.calibration.samples import Window
from ftc_hw.codecs.dxl_table import MODELS
from ftc_hw.devices.dynamixel import DEFAULT_MODEL as DEFAULT_DXL_MODEL
from ftc_hw.model import Payload
from ftc_hw.scene import Scene
from ftc_hw.sim_devices.host import WorldHost


class SessionError(RuntimeError):
    """The wizard cannot do what it asked of the devices (move the arm, reach them)."""


class DeviceSession:
    def __init__(self, scene: Scene, *, sim: bool = False, sim_payload: Payload | None = None, seed: int = 0,
                 noise: bool = True, reality: str = "ideal") -> None:
        self.scene = scene
        self.reality = reality
        self.sim = sim
        self.sim_payload = sim_payload
        self.seed = seed
        self.noise = noise
        try:
            self.ft_spec = require_device(scene, "ft")
            self.arm_spec = require_device(scene, "arm")
        except RigError as exc:
            raise SessionError(str(exc)) from None
        self.bus = Bus()
        self.world: WorldHost | None = None
        self.rig: Rig | None = None
        self.ft = None
        self.arm = None
        self._wrench = None
        self._joints = None
        self.goal_retries = 0  # goals sent again after the arm's link dropped

    # -- lifecycle ---------------------------------------------------------------------------------------
    def start(self, timeout: float = 20.0) -> None:
        """The devices (with ``sim``, the world holding still, emulating both), connected and streaming."""
        try:
            if self.sim:
                self.world = WorldHost(self.scene, "hold", devices=[self.ft_spec.name, self.arm_spec.name],
                                       seed=self.seed, noise=self.noise, payload=self.sim_payload,
                                       reality=self.reality)
                self.world.start()
            self._wrench = self.bus.subscribe(wrench_topic(self.ft_spec.name), maxsize=200_000)
            self._joints = self.bus.subscribe(joints_topic(self.arm_spec.name), maxsize=200_000)
            self.rig = build_rig(self.scene, bus=self.bus, devices=[self.ft_spec, self.arm_spec],
                                 endpoints=self.world.endpoints if self.world is not None else None)
            self.ft, self.arm = self.rig.ft, self.rig.arm
            self.rig.open().wait(timeout, data=True)
        except Exception:
            self.close()
            raise

    def close(self) -> None:
        if self.rig is not None:
            self.rig.close()
        self.rig = self.arm = self.ft = None
        if self.world is not None:
            self.world.close()
            self.world = None

    def __enter__(self) -> DeviceSession:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- state ---------------------------------------------------------------------------------------------
    @property
    def sensor_serial(self) -> str | None:
        ident = getattr(self.ft, "identity", {}) or {}
        return ident.get("serial") or None

    @property
    def can_command(self) -> bool:
        """True when the wizard can move the arm itself: over its protocol (DYNAMIXEL), or in simulation
        through the world (UR RTDE receive has no motion command)."""
        return self.arm.moves_on_goals or self.sim

    @property
    def q_resolution(self) -> float:
        """Joint encoder resolution (rad): DYNAMIXEL ticks; UR reports doubles (taken as 1e-5 rad).
        Known from the scene before the devices start."""
        if self.arm_spec.kind == "dynamixel":
            return float(MODELS[str(self.arm_spec.params.get("model", DEFAULT_DXL_MODEL))].rad_per_tick)
        return 1e-5

    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        f = self.bus.latest(self.arm.topic)
        return np.array(f.q), np.array(f.qd)

    def truth_bias(self, t_sim: float) -> np.ndarray:
        s = self.scene.sensor
        return np.asarray(s.bias, dtype=float) + np.asarray(s.drift_per_s, dtype=float) * t_sim

    # -- motion --------------------------------------------------------------------------------------------
    def torque_on(self) -> None:
        if self.arm.moves_on_goals:
            self.arm.set_torque(True)

    def move_to(self, q_goal: np.ndarray, speed: float = 0.6, rate_hz: float = 50.0,
                progress: Callable[[float], None] | None = None) -> None:
        """Move along a minimum-jerk path at about ``speed`` rad/s on the joint that moves most."""
        if not self.can_command:
            raise SessionError("this arm cannot be commanded: jog it to the pose")
        q0, _ = self.joint_state()
        q_goal = np.asarray(q_goal, dtype=float)
        duration = max(1.0, 1.875 * float(np.abs(q_goal - q0).max()) / speed)  # peak speed of min-jerk
        t0 = time.monotonic()
        while True:
            s = min(1.0, (time.monotonic() - t0) / duration)
            blend = 10 * s**3 - 15 * s**4 + 6 * s**5
            self._send_goal(q0 + blend * (q_goal - q0))
            if progress is not None:
                progress(s)
            if s >= 1.0:
                break
            time.sleep(1.0 / rate_hz)

    def follow(self, reference: Callable[[float], np.ndarray], duration: float, rate_hz: float = 50.0,
               progress: Callable[[float], None] | None = None) -> tuple[list, list]:
        """Stream ``reference(t)`` as goals for ``duration`` s (t from 0); every F/T and joint frame
        meanwhile."""
        if not self.can_command:
            raise SessionError("this arm cannot be commanded: play the motion on its controller")
        self.flush()
        ws: list = []
        js: list = []
        t0 = time.monotonic()
        while (t := time.monotonic() - t0) < duration:
            self._send_goal(reference(t))
            ws += self._wrench.drain()
            js += self._joints.drain()
            if progress is not None:
                progress(t / duration)
            time.sleep(max(0.0, t0 + t + 1.0 / rate_hz - time.monotonic()))
        return ws + self._wrench.drain(), js + self._joints.drain()

    def _send_goal(self, q: np.ndarray, timeout: float = 5.0) -> None:
        """One goal; if the adapter's link drops meanwhile (it reconnects by itself), wait for it and
        send again. The adapter's reader may close the port under a concurrent write, which the SDK
        reports with whatever its serial call raises, hence the broad except."""
        if not self.arm.moves_on_goals:
            self.world.goal(q)
            return
        end = time.monotonic() + timeout
        while True:
            try:
                self.arm.set_goal(q)
                return
            except Exception as exc:  # noqa: BLE001 - see above; a persistent failure is raised
                self.goal_retries += 1
                if time.monotonic() > end:
                    raise SessionError(f"cannot send goal positions to {self.arm.describe()}: {exc}") from exc
                self.arm.wait_connected(max(0.0, end - time.monotonic()))
                time.sleep(0.05)

    # -- sampling ------------------------------------------------------------------------------------------
    def flush(self) -> None:
        self._wrench.drain()
        self._joints.drain()

    def collect(self, duration: float, progress: Callable[[float], None] | None = None) -> Window:
        """Every F/T and joint frame over the next ``duration`` s."""
        self.flush()
        sim0 = self.world.sim_time() if self.world is not None else None
        t0 = time.monotonic()
        ws: list = []
        js: list = []
        while time.monotonic() - t0 < duration:
            time.sleep(0.02)
            ws += self._wrench.drain()
            js += self._joints.drain()
            if progress is not None:
                progress(min(1.0, (time.monotonic() - t0) / duration))
        ws += self._wrench.drain()
        js += self._joints.drain()
        sim1 = self.world.sim_time() if self.world is not None else None
        n = self.scene.n_joints
        return Window(wrench=np.array([f.wrench for f in ws]).reshape(-1, 6),
                      t=np.array([f.t_host_ns for f in ws], dtype=float) / 1e9,
                      q=np.array([f.q for f in js]).reshape(-1, n), qd=np.array([f.qd for f in js]).reshape(-1, n),
                      sim_t=None if sim0 is None else (sim0, sim1), duration=duration)
