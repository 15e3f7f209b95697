"""``ftc identify`` for an arm sensed through its joints: a recording's joint frames cut where it was not
free, the fit written into the calibration file, ``--sensing`` choosing the path."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console
from typer.testing import CliRunner

import ftc_hw.cli.identify as identify_cli
from ftc_hw.app.calibration.identify import _spans
from ftc_hw.app.calibration.identify_joints import identify_joints, joint_segments, report_joints, uses_joints
from ftc_hw.bus import EVENTS_CONTACT, ContactEvent, JointFrame
from ftc_hw.calibration.file import load_calibration, save_calibration
from ftc_hw.cli import app
from ftc_hw.model import ArmModel
from ftc_hw.record.reader import RecordedMessage, Recording
from ftc_hw.scene import load_scene
from tests.calibration.test_joint_ident import DELTA, _motion

pytestmark = pytest.mark.compute  # computes only (nothing timed)

SCENE = load_scene("ur5e").with_sensing(["currents"])


def _recording(seconds: float = 40.0, rate: float = 100.0) -> tuple[Recording, np.ndarray]:
    """ur5e's joint frames (currents of a heavier upper arm and 3 % stronger motors), a contact at 10-11 s."""
    kt = np.asarray(SCENE.robot.torque_constant) * 1.03
    data = _motion(ArmModel(SCENE, inertials=DELTA), kt, np.asarray(SCENE.robot.friction_viscous),
                   np.asarray(SCENE.robot.friction_coulomb), 0.0, seconds=seconds, rate=rate)
    rec = Recording(Path("joints.mcap"), complete=True)
    for k, tk in enumerate(data.t):
        ns = int(tk * 1e9)
        frame = JointFrame.make(ns, data.q[k], data.qd[k], data.current[k], source="arm", seq=k, t_device_ns=ns)
        rec.messages.append(RecordedMessage("joints/arm", ns, ns, frame))
        for at, ev in ((10.0, "onset"), (11.0, "offset")):
            if abs(tk - at) < 0.5 / rate:
                rec.messages.append(RecordedMessage(EVENTS_CONTACT, ns, ns, ContactEvent.make(
                    ns, ev, "forearm", np.zeros(3), np.ones(3), contact_id=1)))
    return rec, kt


def test_a_scene_without_a_base_sensor_in_its_sensing_is_identified_from_its_joints(tmp_path):
    assert uses_joints(SCENE) and not uses_joints(load_scene("ur5e"))
    rec, kt = _recording()
    segments, counts = joint_segments(rec, SCENE, _spans(rec, "contact"))
    assert counts["cut"] == pytest.approx(160, abs=2)  # 1 s of contact and 0.3 s either side, at 100 Hz
    assert len(segments) == 2 and segments[0].tau_j is None and segments[1].t[0] == pytest.approx(0.0)
    cal, fit = identify_joints(SCENE, segments, None, "test")
    back = load_calibration(save_calibration(cal, tmp_path / "cal.toml"), scene=SCENE)
    c = back.corrections(SCENE)
    ratio = c.joints["torque_constant"] / kt
    assert np.ptp(ratio[:5]) < 0.01  # the common scale is the priors'; the joints' ratios are the data's
    assert set(c.joint_residual_std) == {"currents"} and np.all(c.joint_residual_std["currents"] < 0.05)
    assert "rotor_inertia" in c.joints and "torque_offset" not in c.joints
    assert back.identification.sensing == "currents"
    out = io.StringIO()
    report_joints(Console(file=out, width=200), SCENE, fit, counts, segments, tmp_path / "cal.toml", False)
    assert "torque constant" in out.getvalue() and "common scale" in out.getvalue()


def test_sensing_option_narrows_the_scene_or_says_what_it_lacks(monkeypatch, tmp_path):
    seen = []
    monkeypatch.setattr(identify_cli, "run_planned_identify",
                        lambda scene, opts, **kw: seen.append(scene.sensing.label()) or 0)
    runner = CliRunner()
    ok = runner.invoke(app, ["identify", "--sim", "--plan", "--scene", "ur5e", "--sensing", "currents"])
    assert ok.exit_code == 0, ok.output
    assert seen == ["currents"]
    bad = runner.invoke(app, ["identify", "--sim", "--plan", "--scene", "ur5e", "--sensing", "joint_torques"])
    assert bad.exit_code == 2 and "no joint_torques" in bad.output
