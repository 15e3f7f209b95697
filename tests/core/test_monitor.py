"""The live monitor on the bus: world -> bus -> compensation, detection, localization -> events."""
from __future__ import annotations

import time

import numpy as np
import pytest

from ftc_hw.bus import EVENTS_CONTACT, Bus
from ftc_hw.model import ArmModel
from ftc_hw.monitor import LiveMonitor
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world import World, build_scenario

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others


def test_monitor_detects_the_collision_and_nothing_else(world_feeder):
    scene = load_scene("ur5e")
    world = World(scene, build_scenario("sweep-with-collision", scene, ArmModel(scene), 0, 4.0), seed=0)
    bus = Bus()
    events = bus.subscribe(EVENTS_CONTACT, maxsize=10_000)
    truth = []

    def on_state(state):
        if world.steps % world.steps_per_sample == 0:
            truth.append((int(round(state.t * 1e9)), bool(state.contacts),
                          (state.contacts[0].link, state.contacts[0].point.copy()) if state.contacts else None))

    feeder = world_feeder(world, bus, duration=4.0, on_state=on_state)
    with LiveMonitor(bus, scene, keep_frames=True) as monitor, feeder:
        while not feeder.done:
            time.sleep(0.05)
        time.sleep(0.3)
    assert feeder.error is None
    got = events.drain()
    onsets = [e for e in got if e.kind == "onset"]
    first_touch = next(t for t, c, _ in truth if c)
    assert len(onsets) == 1, [(e.kind, e.link) for e in got[:10]]
    frames = {f.t_device_ns: f for f in monitor.frames}
    onset_frame = next(f for f in monitor.frames if any(e.kind == "onset" for e in f.result.events))
    assert 0 <= onset_frame.t_device_ns - first_touch <= 2e6  # within 2 samples at 1 kHz
    # the events (what the monitor answers: on UR's meshes, where the world's obstacle meets wrist 3's
    # flange). Its line of action also crosses wrist 2, so events alternate between the two links, about
    # half and half: those on the right link are localized; those on the other one say so (ambiguous)
    at = {t: p for t, c, p in truth if c}
    events = [(e, *at[t]) for t, f in frames.items() if t in at
              for e in f.result.events if e.kind in ("onset", "update") and "no_estimate" not in e.flags]
    errs = [np.linalg.norm(e.point - point) for e, link, point in events if e.link == link]
    assert errs and np.median(errs) < 0.03
    assert all("ambiguous" in e.flags for e, link, _ in events if e.link != link)
    assert monitor.counters["errors"] == 0
