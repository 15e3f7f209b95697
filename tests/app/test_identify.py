"""``ftc identify``: free motion cut from a recording (contacts, lost streams, long joint gaps), the fit
written into the calibration file on top of what it had, its figure (the fit's own residuals and
parameters against their prior, the PNG beside the file), and the planned excitation within its limits."""
from __future__ import annotations

import io
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from ftc_hw.app.calibration import identify_plot
from ftc_hw.app.calibration.identify import IdentifyOptions, identify, motion_segments, run_identify
from ftc_hw.app.calibration.identify_plot import draw_identification
from ftc_hw.bus import EVENTS_CONTACT, EVENTS_DEVICE, Bus, ContactEvent, DeviceEvent
from ftc_hw.calibration.excitation import SelfCollision, plan_excitation
from ftc_hw.calibration.file import Calibration, load_calibration, save_calibration
from ftc_hw.calibration.free_motion import IdentificationError
from ftc_hw.calibration.joint_friction import V_EPS
from ftc_hw.model import ArmModel, Payload
from ftc_hw.monitor import MONITOR_INPUT, PipelineInput
from ftc_hw.record.reader import RecordedMessage, Recording
from ftc_hw.record.writer import McapRecorder
from ftc_hw.scene import load_scene
from tests.app.test_fit_plots import IDENTIFY_PX, axes_titled, check_png, error_bars, flagged_ticks

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others

SCENE = load_scene("dxl-arm")


def _recording(seconds: float = 40.0, rate: float = 100.0, true_arm: ArmModel | None = None,
               currents: bool = False) -> Recording:
    """A dxl-arm recording of every joint moving, read through ``true_arm``: a contact at 10-11 s, the
    sensor lost at 20-21 s, a 50 ms joint gap at 30 s. ``currents``: the motor currents of the scene's
    torque constants and friction (else zero)."""
    arm = true_arm or ArmModel(SCENE)
    r = SCENE.robot
    t = np.arange(0.0, seconds, 1.0 / rate)
    home = np.asarray(SCENE.robot.home)
    w = 2 * np.pi * np.array([0.13, 0.21, 0.17, 0.29, 0.0])
    amp = np.array([0.8, 0.5, 0.5, 0.6, 0.0])
    rec = Recording(Path("synthetic.mcap"), complete=True)
    for k, tk in enumerate(t):
        q = home + amp * np.sin(w * tk)
        qd, qdd = amp * w * np.cos(w * tk), -amp * w * w * np.sin(w * tk)
        wrench = arm.predicted_wrench(q, qd, qdd) + np.array([0.2, -0.1, 0.3, 0.01, 0.02, -0.01])
        ns = int(tk * 1e9)
        gap = 50_000_000 if 30.0 <= tk < 30.05 else 0
        current = np.zeros(5)
        if currents:
            tau = arm.joint_torques(q, qd, qdd) + r.friction_viscous * qd + r.friction_coulomb * np.tanh(qd / V_EPS)
            current = tau / r.torque_constant
        frame = PipelineInput(ns, ns, k, "ft", wrench, q, qd, current, joint_gap_ns=gap)
        rec.messages.append(RecordedMessage(MONITOR_INPUT, ns, ns, frame))
        for at, topic, ev in ((10.0, EVENTS_CONTACT, "onset"), (11.0, EVENTS_CONTACT, "offset"),
                              (20.0, EVENTS_DEVICE, "sensor_lost"), (21.0, EVENTS_DEVICE, "sensor_back")):
            if abs(tk - at) < 0.5 / rate:
                frame = (ContactEvent.make(ns, ev, "link4", np.zeros(3), np.ones(3), contact_id=1)
                         if topic == EVENTS_CONTACT else DeviceEvent(ns, "ft", ev, ""))
                rec.messages.append(RecordedMessage(topic, ns, ns, frame))
    return rec


def test_free_motion_is_cut_where_the_recording_says_it_was_not_free():
    segments, counts = motion_segments(_recording())
    assert counts["contact"] == pytest.approx(160, abs=2)  # 1 s of contact plus 0.3 s either side, at 100 Hz
    assert counts["stream_lost"] == pytest.approx(160, abs=2)
    assert counts["joint_gap"] == 5
    assert len(segments) == 4
    starts = sorted(s.t[0] for s in segments)
    assert starts[1] == pytest.approx(11.31, abs=0.02) and starts[2] == pytest.approx(21.31, abs=0.02)
    kept, counts = motion_segments(_recording(), keep_contacts=True)
    assert counts["contact"] == 0 and len(kept) == 3


def test_identification_goes_into_the_calibration_file_on_top_of_its_payload(tmp_path):
    payload = Payload(0.2, (0.0, 0.0, 0.03))
    delta = {"link4": np.array([0.02, 0.001, 0.0, 0.0005, 0, 0, 0, 0, 0, 0])}
    rec = _recording(true_arm=ArmModel(SCENE, payload, delta))
    base = Calibration(scene=SCENE.name, sensor_serial=None, date="2026-11-26T00:00:00Z", bias=np.zeros(6),
                       payload=payload)
    segments, _ = motion_segments(rec)
    cal, fit = identify(SCENE, segments, base, "synthetic.mcap")
    assert fit.residual_rms_before[3:].max() > 3 * fit.residual_rms[3:].max()
    assert cal.payload == payload and cal.identification is not None
    np.testing.assert_allclose(cal.bias[:3], [0.2, -0.1, 0.3], atol=0.05)
    back = load_calibration(save_calibration(cal, tmp_path / "cal.toml"), scene=SCENE)
    assert back.identification.source == "synthetic.mcap" and back.rezero  # the old bias kept in the history
    corrections = back.corrections(SCENE)
    assert corrections.inertials is not None and corrections.gain is not None


def test_too_little_free_motion_is_a_clear_error():
    with pytest.raises(IdentificationError, match="usable samples"):
        identify(SCENE, motion_segments(_recording(seconds=3.0))[0], None, "short.mcap")
    assert IdentifyOptions().out is None


@pytest.mark.parametrize("name", ["ur5e", "dxl-arm"])
def test_planned_excitation_stays_within_limits_and_tells_more_than_the_sweep(name):
    scene = load_scene(name)
    plan = plan_excitation(scene, 60.0, candidates=4, seed=1)
    t, q, qd, _ = plan.excitation.samples(50.0)
    lo, hi = ArmModel(scene).joint_limits()
    assert np.all(q >= lo - 1e-9) and np.all(q <= hi + 1e-9)
    assert np.abs(qd).max() <= 1.0 + 1e-6
    np.testing.assert_allclose(q[0], scene.robot.home, atol=1e-12)  # starts and ends at rest at home
    np.testing.assert_allclose(q[-1], scene.robot.home, atol=1e-3)
    assert np.abs(qd[-1]).max() < 1e-2
    assert not SelfCollision(scene).any(q[::25])
    assert plan.told > (20 if name == "ur5e" else 10)


def test_repeated_time_stamps_are_dropped_not_divided_by():
    rec = _recording(seconds=30.0)
    frames = [m for m in rec.messages if m.topic == MONITOR_INPUT]
    for m in frames[100:3000:7]:  # every 7th frame stamped like the one before it
        prev = frames[frames.index(m) - 1]
        object.__setattr__(m.frame, "t_host_ns", prev.frame.t_host_ns)
    segments, _ = motion_segments(rec)
    assert all(np.all(np.diff(s.t) > 0) for s in segments)
    cal, fit = identify(SCENE, segments, None, "stamped.mcap")
    assert np.all(np.isfinite(fit.residual_rms)) and cal.identification is not None


def test_the_identification_figure_draws_the_fits_residuals_and_parameters_against_the_prior():
    """Read back from the figure's artists (its PNG on disk: the command's run below)."""
    delta = {"link4": np.array([0.02, 0.001, 0.0, 0.0005, 0, 0, 0, 0, 0, 0])}
    segments, _ = motion_segments(_recording(seconds=18.0, true_arm=ArmModel(SCENE, None, delta), currents=True))
    cal, fit = identify(SCENE, segments, None, "synthetic.mcap")
    ident = cal.identification
    assert fit.untold and ident.joints  # what the figure must show
    fig = draw_identification(fit, ident, SCENE)
    assert f"verdict {fit.verdict}" in fig.get_suptitle()
    for title, axes in (("force", range(3)), ("moment", range(3, 6))):
        dots = [line for line in axes_titled(fig, f"{title}:").lines if line.get_linestyle() == "None"]
        for line, k in zip(dots, axes, strict=True):
            np.testing.assert_array_equal(line.get_xdata(), fit.t - fit.t[0])
            np.testing.assert_array_equal(line.get_ydata(), fit.residuals[:, k])
    n = 10 * len(fit.bodies)
    for title, part in (("inertial corrections", slice(6, 6 + n)), ("sensor's linear error", slice(6 + n, 42 + n))):
        ax = axes_titled(fig, title)
        y, half = error_bars(ax)
        prior = fit.prior_std[part]
        np.testing.assert_allclose(y, fit.estimate[part] / prior, rtol=1e-12)
        np.testing.assert_allclose(half, fit.std[part] / prior, rtol=1e-9)
        assert flagged_ticks(ax) == [lab in fit.untold for lab in fit.labels[part]]
    assert any(flagged_ticks(axes_titled(fig, "inertial corrections")))
    for title, part in (("force bias", slice(0, 3)), ("torque bias", slice(3, 6))):
        y, half = error_bars(axes_titled(fig, title))
        np.testing.assert_allclose(y, fit.bias[part], rtol=1e-12)
        np.testing.assert_allclose(half, fit.std[part], rtol=1e-9)
    fitted = ident.figures["joints_fitted"]
    assert any(fitted) and not all(fitted)  # the gripper does not move: the scene's values kept
    for k, (title, key, _unit) in enumerate(identify_plot.JOINT_TERMS):
        ax = axes_titled(fig, title)
        y, half = error_bars(ax)  # the fitted joints, with their bars
        np.testing.assert_allclose(y, ident.joints[key][fitted], rtol=1e-12)
        np.testing.assert_allclose(half, np.array(ident.figures["joint_std"])[fitted, k], rtol=1e-9)
        np.testing.assert_array_equal(ax.lines[0].get_ydata(), getattr(SCENE.robot, key))  # the prior
        assert flagged_ticks(ax) == [not f for f in fitted]


def test_identify_on_a_recording_writes_the_file_then_its_figure(tmp_path):
    """``ftc identify FILE.mcap``'s run: the calibration file, then its PNG beside it; with the PNG's
    place taken, a warning with the reason and the same calibration and exit code."""
    rec = _recording(seconds=18.0, currents=True)
    path = tmp_path / "run.mcap"
    recorder = McapRecorder(Bus(), path, metadata={"scene": {"name": SCENE.name}})
    recorder.start()
    for m in rec.messages:
        recorder.write(m.frame)
    recorder.stop()
    codes = []
    for name in ("cal", "blocked"):
        out = io.StringIO()
        if name == "blocked":
            (tmp_path / "blocked.png").mkdir()
        codes.append(run_identify(SCENE, path, IdentifyOptions(out=tmp_path / f"{name}.toml"),
                                  console=Console(file=out, width=300)))
        assert load_calibration(tmp_path / f"{name}.toml", scene=SCENE).identification is not None
        said = out.getvalue()
    assert codes[0] in (0, 4) and codes[1] == codes[0]
    check_png(tmp_path / "cal.png", IDENTIFY_PX)
    assert "warning: no plot of the fit" in said and "IsADirectoryError" in said, said
    (tmp_path / "a-file").write_text("")  # no folder for the calibration file: said, exit 1, no traceback
    out = io.StringIO()
    assert run_identify(SCENE, path, IdentifyOptions(out=tmp_path / "a-file" / "cal.toml"),
                        console=Console(file=out, width=300)) == 1
    assert "cannot save" in out.getvalue(), out.getvalue()


def test_the_plan_is_driven_through_a_dynamixel_arms_protocol(tmp_path):
    """``ftc identify --plan`` on an arm that takes goal positions streams the plan to it through its
    protocol (the emulated servos here, the world only physics behind them) while the monitor pairs the
    frames; an arm that takes none (UR RTDE receive) is told to play the written plan instead."""
    out = tmp_path / "dxl.toml"
    proc = subprocess.run([sys.executable, "-m", "ftc_hw", "identify", "--scene", "dxl-arm", "--sim", "--plan",
                           "--duration", "15", "--reality", "ideal", "--out", str(out)],
                          capture_output=True, text=True, timeout=240)
    text = proc.stdout + proc.stderr
    assert proc.returncode in (0, 4), text[-3000:]  # a 15 s plan leaves parameters untold: 4 is honest
    assert "through the arm's protocol" in text, text[-3000:]
    seconds = float(re.search(r"free motion: ([0-9.]+) s", text).group(1))
    assert seconds >= 10.0, text[-3000:]
    cal = load_calibration(out, scene=SCENE)
    assert "driven through the arm's protocol" in cal.identification.source
    assert f"plotted the fit: {out.with_suffix('.png')}" in " ".join(proc.stdout.split()), text[-3000:]
    check_png(out.with_suffix(".png"), IDENTIFY_PX)
    proc = subprocess.run([sys.executable, "-m", "ftc_hw", "identify", "--scene", "ur5e", "--plan"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "--plan-file" in proc.stdout + proc.stderr


def test_an_arm_sensed_through_its_currents_is_identified_from_its_emulated_joints_alone(tmp_path):
    """``ftc identify --sim --plan --sensing currents`` on ur5e: the emulated UR controller's joint frames
    (no F/T sensor read), the planned excitation played by the world, the joint model in the file."""
    out = tmp_path / "ur5e.toml"
    proc = subprocess.run([sys.executable, "-m", "ftc_hw", "identify", "--scene", "ur5e", "--sim", "--plan",
                           "--sensing", "currents", "--duration", "13", "--reality", "typical", "--out", str(out)],
                          capture_output=True, text=True, timeout=240)
    text = proc.stdout + proc.stderr
    assert proc.returncode in (0, 4), text[-3000:]
    assert "free motion from the joints (currents)" in " ".join(text.split()), text[-3000:]
    ident = load_calibration(out, scene="ur5e").identification
    assert ident.sensing == "currents" and "joints" in ident.source
    scene = load_scene("ur5e")
    ratio = ident.joints["torque_constant"] / np.asarray(scene.robot.torque_constant)
    assert np.all(np.abs(ratio - 1) < 0.15), ratio  # the typical world's are within 5 % of the scene's
    before = np.asarray(ident.figures["joint_residual_std_before_Nm"]["currents"])
    after = ident.joint_residual_std["currents"]
    assert np.linalg.norm(after) < 0.2 * np.linalg.norm(before), (before, after)  # measured: 1.4 -> 0.05 N m
