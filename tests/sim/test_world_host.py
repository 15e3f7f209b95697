"""The world host's pre-roll (what the monitor runs): nothing scripted happens in it, however long it lasts."""
from __future__ import annotations

import time

from ftc_hw.record.events import read_truth
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.host import WorldHost


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
