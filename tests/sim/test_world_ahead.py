"""A world's run computed ahead (``--world-ahead``): the same records as the live world's for the same seed,
and the played timeline (the pre-roll's loop, the cut at go) keeping both streams' grids and their pairing."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.ahead import AheadRunner, AheadSpan
from ftc_hw.sim_devices.link import RingReader
from ftc_hw.sim_devices.played import PlayControl, PlayedInfo, PlayedRing, StreamInfo, cut_at
from ftc_hw.sim_devices.runner import SimRunner
from ftc_hw.sim_devices.world.truth import truth_line

pytestmark = pytest.mark.compute
SPAN = AheadSpan(postroll_s=1.0)  # the post-roll computed after the scenario (short: CPU time)


def _live(scene, seconds: float, seed: int) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The live world's records (joint ring, F/T ring) and truth lines, stepped as fast as it goes."""
    runner = SimRunner(scene, "sweep-with-collision", duration=seconds, seed=seed)
    try:
        joints, ft = RingReader(runner.link.joints), RingReader(runner.link.ft)
        runner.publish_state()  # what start() publishes before the emulators start
        got_j, got_f, lines = joints.new(), ft.new(), []

        def on_sample(state) -> None:
            got_j.extend(joints.new())  # read as it goes: the rings hold 4096 records
            got_f.extend(ft.new())
            if state.t < seconds - 1e-9:
                lines.append(truth_line(state, {"t": round(state.t, 9)}))

        runner.duration = seconds + SPAN.postroll_s
        runner.run(realtime=False, on_sample=on_sample)
        got_j.extend(joints.new())
        got_f.extend(ft.new())
        assert joints.lost == ft.lost == 0
        return np.array(got_j), np.array(got_f), lines
    finally:
        runner.stop()


def test_the_computed_run_holds_the_live_worlds_readings_for_the_same_seed():
    """Every joint sample, F/T reading and truth line of the computed run (no pre-roll: the scenario from
    its first record, then the post-roll) is the live world's, bit for bit, for the same seed; another seed
    gives other readings (the comparison can fail)."""
    scene = load_scene("ur5e")  # a 2 kHz world with a 1 kHz sensor: an F/T reading every other step
    seconds, seed = 2.0, 7
    live_j, live_f, live_lines = _live(scene, seconds, seed)
    runner = AheadRunner(scene, "sweep-with-collision", duration=seconds, seed=seed, preroll=False, span=SPAN)
    try:
        stored = runner.compute()
        played_j, played_f = (np.load(s.path) for s in (stored.info.joints, stored.info.ft))
        assert played_j.shape == live_j.shape and played_f.shape == live_f.shape
        assert np.array_equal(played_j, live_j) and np.array_equal(played_f, live_f)
        assert stored.truth_lines.read_text().splitlines(keepends=True) == live_lines
        assert stored.samples == len(live_lines) == round(seconds * 1000) and stored.contact > 0
        assert runner.world.t == pytest.approx(seconds + SPAN.postroll_s, abs=1e-3)
    finally:
        runner.stop()
    _, other_f, _ = _live(scene, 0.2, seed + 1)
    assert not np.array_equal(other_f[:100], live_f[:100])  # the sensor's noise: another draw


def _stored(tmp_path, *, steps: int, per_sample: int, loop: tuple[int, int]) -> PlayedInfo:
    """A synthetic stored run: joint rows every 1 ms (payload: the row's index), an F/T row every
    ``per_sample`` steps from the second on (as the world's: the first reading at t = 0, then every
    ``per_sample``-th step), the pre-roll's loop window ``[loop[0], loop[1])`` in joint rows."""
    dt = 1e-3
    t = np.arange(steps) * dt
    joints = np.column_stack([t, np.arange(steps, dtype=float)])
    ft_rows = [0] + list(range(per_sample - 1, steps, per_sample))
    ft = np.column_stack([t[ft_rows], np.array(ft_rows, dtype=float)])
    np.save(tmp_path / "j.npy", joints)
    np.save(tmp_path / "f.npy", ft)
    a_f, b_f = (int(np.searchsorted(ft[:, 0], t[i] - 1e-9)) for i in loop)
    control = str(tmp_path / "control.f64")
    PlayControl(control, create=True)
    info = PlayedInfo(StreamInfo(str(tmp_path / "j.npy"), *loop), StreamInfo(str(tmp_path / "f.npy"), a_f, b_f),
                      control, float(t[loop[0]]), float(t[loop[1]]))
    return info


@pytest.mark.parametrize("go_at_s", [0.0123, 0.95, 3.3217])  # in the stored pre-roll, in its first loop, later
def test_the_played_timeline_loops_the_pre_roll_and_cuts_to_the_scenario_on_the_grid(tmp_path, go_at_s):
    """Before go the pre-roll, then its window over and over; from the cut the scenario's rows. Both streams'
    played times run on at their periods with no gap or repeat, each F/T record beside the joint record of
    its stored time, the scenario's first F/T reading on the cut, never ahead of ``go_at_s``."""
    info = _stored(tmp_path, steps=3000, per_sample=2, loop=(400, 1000))
    control = PlayControl(info.control, write=True)
    joints, ft = PlayedRing(info, ft=False, control=control), PlayedRing(info, ft=True, control=control)
    shift, k_j, k_f = cut_at(joints, ft, go_at_s)
    control.set_cut(shift, k_j, k_f)
    played_j = np.array([joints.read(k) for k in range(k_j + 1500)])
    played_f = np.array([ft.read(k) for k in range(k_f + 700)])
    assert np.allclose(np.diff(played_j[:, 0]), 1e-3, atol=1e-9)
    assert np.allclose(np.diff(played_f[1:, 0]), 2e-3, atol=1e-9)  # (the first reading's interval is the world's)
    assert played_f[k_f, 0] > go_at_s and played_f[k_f - 1, 0] <= go_at_s + 1e-9
    assert played_f[k_f, 1] == 1001  # the scenario's first reading (its second step's: joint row 1001)
    assert played_j[k_j, 1] == 1000 and played_j[k_j - 1, 1] < 1000  # the scenario's first joint row after the loop
    by_time = {round(r[0], 6): r[1] for r in played_j}
    assert all(by_time[round(r[0], 6)] == r[1] for r in played_f)  # each reading beside its own joint row
    if go_at_s > 1.0:  # the loop repeated: its rows over again, shifted by the window's length
        assert set(played_j[1000:k_j, 1]) <= set(range(400, 1000)) and k_j > 1600
    # the counts the emulators read by the clock: every record at or before a played time, none after
    for now in (0.0, 0.5, go_at_s, played_f[k_f, 0], min(played_j[-1, 0], played_f[-1, 0])):
        assert joints.count(now) == int(np.sum(played_j[:, 0] <= now + 1e-9))
        assert ft.count(now) == int(np.sum(played_f[:, 0] <= now + 1e-9))
    assert joints.read(joints.stored + 10 + k_j) is None  # past the stored run: the stream has ended
