"""The joint state of a simulated world that has no arm device (leng2016): read from the world's
shared-memory joint ring and published like an arm adapter would."""
from __future__ import annotations

import time

import numpy as np

from ftc_hw.bus import Bus, JointFrame, joints_topic
from ftc_hw.devices.base import Adapter
from ftc_hw.sim_devices.host import WorldHost
from ftc_hw.sim_devices.link import JointRecord, RingReader


class SimJointSource(Adapter):
    """The world's joint state on ``joints/<name>`` at ``rate_hz``, with the world's time as device
    time: the arm of a scene that declares no arm device. ``stop()`` halts the world's arm."""

    kind = "sim-joints"
    role = "arm"

    def __init__(self, name: str, bus: Bus, world: WorldHost, *, rate_hz: float = 500.0) -> None:
        super().__init__(name, bus, poll_timeout=0.001)
        self.world = world
        self.n = world.scene.n_joints
        self.period = 1.0 / rate_hz
        self.topic = joints_topic(name)
        self._reader: RingReader | None = None
        self._next_t = 0.0
        self._seq = 0

    def _connect(self) -> None:
        self._reader = self.world.joint_reader()

    def _read_once(self) -> None:
        recs = self._reader.new()
        n = self.n
        for rec in recs:
            j = JointRecord.from_row(rec, n)
            t = j.t
            if t + 1e-9 < self._next_t:
                continue
            self._next_t = (np.floor(t / self.period + 1e-6) + 1) * self.period
            self.bus.publish(self.topic, JointFrame.make(time.monotonic_ns(), j.q, j.qd, j.current, j.tau,
                                                         source=self.name, seq=self._seq,
                                                         t_device_ns=round(t * 1e9)))
            self._seq += 1
        if not recs:
            time.sleep(self.poll_timeout)

    def _disconnect(self) -> None:
        self._reader = None

    def stop(self) -> None:
        self.world.halt()
        self.counters["stops"] += 1
