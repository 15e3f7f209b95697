"""The world host: its pre-roll (what the monitor runs: nothing scripted happens in it, however long it
lasts), its end-of-run report, its samples and clock, its emulators killed and restarted."""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from ftc_hw.record.events import read_truth
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.host import WorldHost, WorldHostError
from ftc_hw.sim_devices.link import NoFTRingError

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others


def test_a_long_pre_roll_does_not_use_up_the_scenario(tmp_path):
    # the obstacle is due to go at 4.3 s of a 3 s run: a pre-roll longer than that (a first run
    # compiling its kernels) must not withdraw it before the scenario has started
    truth = tmp_path / "truth.jsonl"
    with WorldHost(load_scene("leng2016"), "sweep-with-collision", duration=3.0, truth=truth, preroll=True) as world:
        time.sleep(5.0)
        world.go()
        deadline = time.monotonic() + 30.0
        while not world.done and time.monotonic() < deadline:
            time.sleep(0.1)
        assert world.done, "the world did not report the end of the run"
    rows = read_truth(truth)
    touched = [r["t"] for r in rows if r["contact"]]
    assert touched, "no contact in the run"
    assert 1.7 < touched[0] < 1.9, touched[0]  # the first swing's, at scenario time


def test_the_host_reports_its_end_and_serves_its_samples_and_time():
    """Without a pre-roll the scenario starts at once; the report counts its samples; the rings hold
    the world's F/T and joint samples; the world's time advances in real time."""
    with WorldHost("leng2016", "static-pokes", devices=[], duration=0.5, noise=False) as world:
        assert world.endpoints == {}
        assert world.wait_done(20.0), world.result
        report = world.result
        assert report["samples"] == 500 and 0 < report["contact"] < 500  # 0.5 s at 1 kHz, pokes from 0.2 s
        ft = world.ft_reader(from_start=True).new()
        assert len(ft) >= 500 and all(r.shape == (13,) for r in ft[:3])  # [t, wrench (6), saturated (6)]
        joints = world.latest_joints()
        assert joints is not None and joints.q.shape == (3,)
        t0 = world.sim_time()
        time.sleep(0.3)
        assert 0.2 < world.sim_time() - t0 < 0.5  # the post-roll goes on in real time


def test_a_device_the_scene_lacks_is_a_clear_error():
    with pytest.raises(ValueError, match="has no device 'nope'"):
        WorldHost("ur5e", devices=["nope"])
    world = WorldHost("leng2016", devices=[])
    with pytest.raises(WorldHostError, match="not running"):
        world.joint_reader()
    world.close()  # never started: closing is harmless


def test_a_killed_emulator_restarts_at_its_endpoint(tmp_path):
    with WorldHost("leng2016", devices=["ft"], noise=False,
                   options={"ft": {"path": str(tmp_path / "ft.tty")}}) as world:
        first = world.endpoint("ft")
        world.kill("ft")
        again = world.restart("ft")
        assert again["endpoint"] == first["endpoint"] and again["ready_ns"] > first["ready_ns"]
        assert world.endpoints["ft"] == again
        with pytest.raises(KeyError, match="no emulated device 'arm'"):
            world.endpoint("arm")


def test_a_world_without_an_f_t_sensor_serves_joints_at_their_rate_and_no_f_t_ring():
    scene = dataclasses.replace(load_scene("ur5e"), sensor=None)
    with WorldHost(scene, "hold", devices=[], duration=0.2, noise=False, realtime=False) as world:
        assert world.sample_period_s == pytest.approx(1 / 500)  # the UR arm's RTDE rate
        assert world.wait_done(20.0), world.result
        assert world.result["samples"] == 100
        with pytest.raises(NoFTRingError, match="no F/T sensor"):
            world.ft_reader()
        joints = world.latest_joints()
        assert joints is not None and np.array_equal(joints.tau_j, np.zeros(6))  # no joint torque sensors
