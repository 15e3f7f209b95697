"""Fixtures of the core tests (solver, compensation, detection, tracking, pipeline, monitor): the sensor
reading of a contact, and a world fed straight onto a bus (``world_feeder``)."""
from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np
import pytest

from ftc_hw.bus import Bus, DeviceEvent, JointFrame, WrenchFlag, WrenchFrame, joints_topic, wrench_topic
from ftc_hw.model import ArmModel, Contact
from ftc_hw.model.sampling import SurfacePoint
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world import World, WorldState


def _reading(model: ArmModel, q, sp: SurfacePoint, force) -> np.ndarray:
    """The compensated sensor reading (sensor frame, scene convention) of one contact."""
    return model.predicted_wrench(q, level="bias", contacts=[Contact(sp.link, sp.point, force)])


@pytest.fixture(scope="session")
def reading():
    """``reading(model, q, sp, force)``: the compensated sensor reading of one contact."""
    return _reading


class WorldFeeder:
    """Runs a world in real time on a thread and publishes its signals straight onto a bus: the
    in-process path of the core tests (no emulator, no wire protocol; the product hosts a world with
    :class:`~ftc_hw.sim_devices.host.WorldHost`). ``wrench/<ft_source>`` at the sensor rate,
    ``joints/<arm_source>`` at ``joint_rate_hz``; device timestamps are the world's time in ns."""

    def __init__(self, world: World, bus: Bus, *, ft_source: str = "ft", arm_source: str = "arm",
                 joint_rate_hz: float = 500.0, duration: float | None = None,
                 on_state: Callable[[WorldState], None] | None = None) -> None:
        self.world = world
        self.bus = bus
        self.ft_topic = wrench_topic(ft_source)
        self.joint_topic = joints_topic(arm_source)
        self.ft_source, self.arm_source = ft_source, arm_source
        self.joint_every = max(1, round(1.0 / (joint_rate_hz * world.dt)))
        self.duration = duration
        self.on_state = on_state
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None

    def start(self) -> WorldFeeder:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="world-feeder", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    @property
    def done(self) -> bool:
        return self._thread is not None and not self._thread.is_alive()

    def __enter__(self) -> WorldFeeder:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        w, bus = self.world, self.bus
        wall0 = time.monotonic()
        t0 = w.t
        ft_seq = joint_seq = 0
        bus.publish("events/device", DeviceEvent.make(time.monotonic_ns(), self.ft_source, "connect", "world"))
        try:
            while not self._stop.is_set():
                state = w.step()
                if self.duration is not None and state.t - t0 >= self.duration:
                    break
                now = time.monotonic_ns()
                dev_ns = int(round(state.t * 1e9))
                if w.steps % w.steps_per_sample == 0:
                    reading = w.read_sensor(state)
                    flags = WrenchFlag.SATURATED if reading.saturated.any() else WrenchFlag.NONE
                    bus.publish(self.ft_topic, WrenchFrame.make(now, reading.wrench, source=self.ft_source,
                                                                seq=ft_seq, t_device_ns=dev_ns, flags=flags))
                    ft_seq += 1
                if w.steps % self.joint_every == 0:
                    bus.publish(self.joint_topic, JointFrame.make(now, state.q, state.qd, w.read_current(state),
                                                                  source=self.arm_source, seq=joint_seq,
                                                                  t_device_ns=dev_ns))
                    joint_seq += 1
                if self.on_state is not None:
                    self.on_state(state)
                ahead = (state.t - t0) - (time.monotonic() - wall0)
                if ahead > 0.0005:
                    time.sleep(ahead)
        except BaseException as exc:  # the reader never dies silently
            self.error = exc
            bus.publish("events/device", DeviceEvent.make(time.monotonic_ns(), self.ft_source, "error", repr(exc)))
        finally:
            bus.publish("events/device", DeviceEvent.make(time.monotonic_ns(), self.ft_source, "disconnect",
                                                          "world stopped"))


@pytest.fixture
def world_feeder():
    """``world_feeder(world, bus, **options)``: a :class:`WorldFeeder`, not started; stopped at teardown."""
    feeders: list[WorldFeeder] = []

    def make(world: World, bus: Bus, **options) -> WorldFeeder:
        feeders.append(WorldFeeder(world, bus, **options))
        return feeders[-1]

    yield make
    for feeder in feeders:
        feeder.stop()


@pytest.fixture(scope="module")
def link3_push():
    """leng2016 at home, a point on link3's top face and its outward normal (base frame):
    ``(scene, model, q, point, normal)``."""
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    q = np.array(scene.robot.home, dtype=float)
    b_T = model.kinematics(q)["link3"]
    point = b_T[:3, :3] @ np.array([0.1, 0.0, 0.04]) + b_T[:3, 3]
    normal = b_T[:3, :3] @ np.array([0.0, 0.0, 1.0])
    return scene, model, q, point, normal
