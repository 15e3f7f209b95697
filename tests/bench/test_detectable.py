"""The bench's detectability criterion (ftc_hw/bench/detectable.py): a contact's true tested vector and its
chi-square against a measured floor, checked against the model's own joint torques and sensor wrench."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.bench.detectable import Floor, TruthVector, d2_against, probe_d2
from ftc_hw.model import ArmModel, Contact
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world import ContactTruth


def _contact(model: ArmModel, q: np.ndarray, link: str, force: np.ndarray, at: str | None = None) -> ContactTruth:
    """A contact on ``link`` at the origin of the frame ``at`` (default: its own) at q, base coordinates."""
    origin = model.kinematics(q)[at or link][:3, 3]
    return ContactTruth(link, origin, force, "probe")


def test_the_joint_part_is_the_torque_the_contact_takes_off_the_motors():
    scene = load_scene("ur10e").with_sensing(["currents"])
    truth = TruthVector(scene, joints=True, ft=False)
    model = ArmModel(scene)
    q = np.asarray(scene.robot.home) + 0.2
    c = _contact(model, q, "forearm", np.array([10.0, -20.0, 30.0]))
    tau = truth(q, [c])
    free = model.joint_torques(q, level="gravity")
    pushed = model.joint_torques(q, level="gravity", contacts=[Contact(c.link, c.point, c.force)])
    assert tau.shape == (6,)
    assert np.allclose(tau, free - pushed, atol=1e-9)
    # the base: no joint moves it, no joint torque
    assert np.allclose(truth(q, [_contact(model, q, "base", np.array([0.0, 50.0, 0.0]))]), 0.0)


def test_the_flange_part_sees_only_the_tool():
    scene = load_scene("ur10e").with_sensing(["currents", "flange_ft"])
    truth = TruthVector(scene, joints=True, ft=True)
    model = ArmModel(scene)
    q = np.asarray(scene.robot.home, dtype=float)
    f = np.array([0.0, 0.0, -40.0])
    on_tool = truth(q, [_contact(model, q, "tool", f)])
    on_arm = truth(q, [_contact(model, q, "upper_arm", f, at="forearm")])  # at the elbow
    assert on_tool.shape == on_arm.shape == (12,)
    assert np.linalg.norm(on_tool[6:9]) == pytest.approx(40.0, rel=1e-6)
    assert np.allclose(on_arm[6:], 0.0, atol=1e-9) and np.linalg.norm(on_arm[:6]) > 1.0


def test_floor_by_joint_speed_and_window():
    rng = np.random.default_rng(0)
    floor = Floor(3, 2)  # two joints' residuals and one wrench component
    # joint 0 spreads 2.0 at rest and 0.5 while sliding; joint 1 0.1 throughout; the wrench component 1.0
    for k in range(20000):
        qd = np.array([0.0 if k % 4 == 0 else 0.15, 0.15])
        sigma = np.array([2.0 if qd[0] == 0.0 else 0.5, 0.1, 1.0])
        floor.add(rng.normal(0.0, sigma), qd)
    floor.add(np.array([np.nan, 0.0, 0.0]), np.zeros(2))  # refused, not counted
    assert floor.frames == 20000
    assert floor.std(np.array([0.15, 0.15])) == pytest.approx([0.5, 0.1, 1.0], rel=0.03)
    assert floor.std(np.array([0.0, 0.15])) == pytest.approx([2.0, 0.1, 1.0], rel=0.03)
    # a bin the free run never reached: the component's spread over every bin
    assert floor.std(np.array([0.03, 0.0]))[0] == pytest.approx(np.sqrt(0.25 * 4.0 + 0.75 * 0.25), rel=0.03)
    s = floor.std(np.array([0.15, 0.15]))
    # 1 N m on the quiet joint counts 25 times as much as on the sliding noisy one
    assert d2_against(np.array([0.0, 1.0, 0.0]), s) == pytest.approx(25 * d2_against(np.array([1.0, 0.0, 0.0]), s),
                                                                     rel=0.06)
    moving = np.array([0.15, 0.15])
    truth = [(1.000, np.array([0.0, 0.5, 0.0]), moving), (1.010, np.array([0.0, 1.0, 0.0]), moving),
             (1.025, np.array([0.0, 9.0, 0.0]), moving)]
    # the frame at 25 ms lies past the 20 ms window: the largest inside is the 10 ms frame's
    assert probe_d2(truth, floor, 1.0) == pytest.approx(d2_against(truth[1][1], s))
    assert probe_d2(truth, floor, 2.0) == 0.0
