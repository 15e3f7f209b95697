"""Runs a world in real time on a thread and publishes its signals straight onto a bus.

This is the in-process path (no wire protocol): the protocol emulators replace it for device
tests and the demo once they exist. Device timestamps are the world's time in ns.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable

from ftc_hw.bus import Bus, DeviceEvent, JointFrame, WrenchFlag, WrenchFrame, joints_topic, wrench_topic

from .world import World, WorldState


class WorldFeeder:
    """Publishes ``wrench/<ft_source>`` at the sensor rate and ``joints/<arm_source>`` at ``joint_rate_hz``."""

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
