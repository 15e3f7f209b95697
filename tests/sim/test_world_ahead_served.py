"""A run computed ahead, served by the emulators in their own processes on the wall clock through the real
clients: the Net F/T's RDT stream read by our adapter, UR's RTDE and dashboard through ur_rtde."""
from __future__ import annotations

import time

import numpy as np
import pytest

from ftc_hw.bus import Bus
from ftc_hw.devices.registry import make_adapter
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.ahead import AheadSpan
from ftc_hw.sim_devices.host import WorldHost
from ftc_hw.sim_devices.link import JointRecord

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(120)]


def test_the_emulators_serve_the_computed_run_and_record_a_stop_without_obeying_it():
    """Every F/T frame is the stored reading of its sample (to the counts' resolution), every RTDE packet the
    stored joint sample of its timestamp, bit for bit; a dashboard stop reaches the emulator (its receive
    time recorded) and the played arm goes on moving (what the world would have done cannot be played)."""
    scene = load_scene("ur5e-netft")
    ft_spec, arm_spec = (next(d for d in scene.devices if d.name == n) for n in ("ft", "arm"))
    # with the pre-roll, played over and over until go: the clients connect however long it takes
    span = AheadSpan(preroll_s=1.0, loop_from_s=0.5, postroll_s=2.0)  # short: what is computed takes CPU time
    with WorldHost(scene, "sweep", duration=1.0, preroll=True, ahead=span) as world:
        played_ft, played_j = world.ft_reader(from_start=True), world.joint_reader(from_start=True)
        bus = Bus()
        wrenches, joints = bus.subscribe("wrench/ft", maxsize=None), bus.subscribe("joints/arm", maxsize=None)
        with make_adapter(ft_spec, bus, world.endpoint("ft"), scene=scene) as ft, \
                make_adapter(arm_spec, bus, world.endpoint("arm"), scene=scene) as arm:
            assert ft.wait_connected(10.0) and arm.wait_connected(10.0)
            world.go()
            time.sleep(0.5)  # the sweep moves from 0.3 s on
            arm.stop()
            t_stopped = time.monotonic_ns()
            time.sleep(0.4)
        applied = world.applied()
        ring_f, ring_j = played_ft.new(), played_j.new()
    got_f, got_j = wrenches.drain(), joints.drain()
    # 0.9 s at 7 kHz and 500 Hz: what two readers in this one (test) process take in on a loaded host
    assert len(got_f) > 1000 and len(got_j) > 15

    # the frames' sample numbers against the played records: one alignment fits them all (the pre-roll's
    # loop repeats its readings, so the first frame alone matches several)
    stored_f = np.array([r[1:7] for r in ring_f])
    seqs = np.array([f.seq for f in got_f]) - got_f[0].seq
    wrench = np.array([f.wrench for f in got_f])

    def fits(m0: int) -> bool:
        return m0 + seqs[-1] < len(stored_f) and np.allclose(stored_f[m0 + seqs], wrench, atol=1e-5)

    assert sum(fits(m) for m in np.nonzero(np.all(np.abs(stored_f - wrench[0]) <= 1e-5, axis=1))[0]) == 1

    stored = {round(r[0] * 1e9): JointRecord.from_row(r, scene.n_joints) for r in ring_j}
    for f in got_j:
        assert np.array_equal(f.q, stored[f.t_device_ns].q) and np.array_equal(f.current, stored[f.t_device_ns].current)

    stops = [a for a in applied if a.kind == "stop"]
    assert len(stops) == 1 and t_stopped - 1e9 < stops[0].t_rx_ns <= t_stopped
    after = [f for f in got_j if f.t_host_ns > stops[0].t_rx_ns]
    assert len(after) > 5 and after[-1].t_device_ns - after[0].t_device_ns > 0.2e9  # the stream goes on
    assert np.ptp([f.q[0] for f in after]) > 0.02  # and so does the arm (halted, it would hold within 1e-3 rad)
