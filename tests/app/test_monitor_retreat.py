"""``ftc monitor --sim --reflex retreat`` end to end, per arm through its own protocol: ur5e over its
emulated UR controller (ur_rtde's IO interface writing the control-loop program's RTDE registers,
sim_devices/ur_program.py) and dxl-arm over DYNAMIXEL (Sync Writes of Goal Position), each emulator in its
own process, the world in another. Ideal world (the pipeline's own model): the reflex is the subject.

``sweep-with-collision``: the sweep meets its obstacle at about 1.74-1.80 s; 2.6 simulated seconds leave
the retreat and 0.6 s after it. Judged by the world's truth: the contact force below 5 N within 150 ms of
the onset sample, the true touched point (the truth's, on its link; the onset's estimate is centimetres off)
moved back at least the configured distance along the retreat, and no contact the retreat caused (only the
one obstacle, on the touched link, and it touching again after a gap only lightly: it springs back after the arm).
"""
from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest

from ftc_hw.model import ArmModel
from ftc_hw.record.events import read_events, read_truth
from ftc_hw.scene import load_scene

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(240)]

DISTANCE_M, TIME_LIMIT_S = 0.03, 0.5  # the reflex's defaults
FORCE_N, WITHIN_MS = 5.0, 150.0


def _run(tmp_path, scene: str) -> tuple[subprocess.CompletedProcess, list[dict], list[dict]]:
    events, truth = tmp_path / "events.jsonl", tmp_path / "truth.jsonl"
    proc = subprocess.run([sys.executable, "-m", "ftc_hw", "monitor", "--scene", scene, "--sim", "--scenario",
                           "sweep-with-collision", "--duration", "2.6", "--events", str(events), "--truth",
                           str(truth), "--no-view", "--reflex", "retreat", "--retreat-distance", str(DISTANCE_M)],
                          capture_output=True, text=True, timeout=200)
    return proc, read_events(events), read_truth(truth)


def _force(rec: dict) -> float:
    return max((float(np.linalg.norm(c["force"])) for c in rec["contacts"]), default=0.0)


def _point_motion(scene: str, truth: list[dict], i_on: int, first: int, direction: np.ndarray) -> float:
    """How far the truth's touched point (its first contact sample's, fixed on its link) moved along
    ``direction`` from the onset to the end of the run (m)."""
    model = ArmModel(load_scene(scene))
    c = truth[first]["contacts"][0]
    b_T_l = model.kinematics(np.array(truth[first]["q"]))[c["link"]]
    point_link = b_T_l[:3, :3].T @ (np.array(c["point"]) - b_T_l[:3, 3])

    def at(q) -> np.ndarray:
        b_T_l = model.kinematics(np.array(q))[c["link"]]
        return b_T_l[:3, :3] @ point_link + b_T_l[:3, 3]

    return float((at(truth[-1]["q"]) - at(truth[i_on]["q"])) @ direction)


@pytest.mark.parametrize("scene", ["ur5e", "dxl-arm"])
def test_retreat_frees_the_contact_through_the_arms_protocol(tmp_path, scene, clean_or_loaded):
    proc, events, truth = _run(tmp_path, scene)
    clean_or_loaded(proc.returncode, proc.stdout + proc.stderr)
    flat = " ".join(proc.stdout.split())
    m = re.search(r"reflex retreat: contact \d+ on \S+: first setpoint ([0-9.]+) ms after the onset sample \(planned "
                  r"[0-9.]+ ms after taking it, [0-9.]+ of them planning\), at the "
                  r"arm's interface ([0-9.]+) ms; (\d+) setpoints over ([0-9.]+) s, the point moved back ([0-9.]+) mm "
                  r"\(model\), every point it may be at \(\d+\) at least ([0-9.]+) mm, along "
                  r"\(([-0-9.]+), ([-0-9.]+), ([-0-9.]+)\)",
                  flat)
    assert m, flat[-3000:]
    onset = next(e for e in events if e["kind"] == "onset")
    th = np.array([r["t_host_ns"] for r in truth])
    # the world's state when the onset's F/T sample left it: the last truth line published before the onset
    # sample reached the monitor (truth lines carry the world's publication times)
    i_on = int(np.searchsorted(th, onset["t_host_ns"])) - 1
    first = next(i for i, r in enumerate(truth) if r["contacts"])
    last = max(i for i, r in enumerate(truth) if r["contacts"])
    # from when on the force stays below FORCE_N (the sample after the last one at or above it)
    pressed = [i for i in range(i_on, len(truth)) if _force(truth[i]) >= FORCE_N]
    th = np.append(th, np.inf)  # a contact that lasts to the run's end: never freed
    freed_ms = (th[pressed[-1] + 1] - onset["t_host_ns"]) / 1e6 if pressed else 0.0
    retreat = np.array([float(m.group(k)) for k in (7, 8, 9)])  # the reflex's direction: the estimated force's
    true_force = np.array(truth[max(first, i_on)]["contacts"][0]["force"])  # on the arm: away from the obstacle
    moved = _point_motion(scene, truth, i_on, first, retreat)
    moved_true = _point_motion(scene, truth, i_on, first, true_force / np.linalg.norm(true_force))
    peak = max(_force(r) for r in truth[i_on:])
    ended_ms = (th[last + 1] - onset["t_host_ns"]) / 1e6
    report = (f"{scene}: onset -> first setpoint sent {m.group(1)} ms, at the arm's interface {m.group(2)} ms, "
              f"the estimate moved {m.group(5)} mm, the region's least {m.group(6)} mm (model), "
              f"force < {FORCE_N} N after {freed_ms:.0f} ms (peak after the onset {peak:.1f} N), no contact after "
              f"{ended_ms:.0f} ms; the true point moved {moved * 1e3:.1f} mm along the "
              f"retreat, {moved_true * 1e3:.1f} mm along the true force at the onset; contact samples "
              f"{first}-{last} of {len(truth)}")
    print(report)
    assert freed_ms <= WITHIN_MS and ended_ms <= 1e3 * TIME_LIMIT_S, report
    # every point the contact may be at goes back DISTANCE_M (the model's figure), so the true one does, within
    # the emulated arm's tracking of the last setpoint (ESTIMATE: 0.5 mm); or the plan was cut to the time limit
    # and said so before the retreat began (retracing, a point of the region near the moving joints' axes comes
    # back slowly: dxl-arm's region, when it reaches around the gripper, needs 0.57 s of the 0.5)
    short = [e for e in events if e["kind"] == "retreat_short"]
    if float(m.group(6)) < DISTANCE_M * 1e3 - 0.5:
        assert len(short) == 1 and "cut to the 0.5 s limit" in short[0]["message"], (short, report)
        assert f"at least {m.group(6)} mm of {DISTANCE_M * 1e3:.1f}" in short[0]["message"], (short, report)
    else:
        assert not short, (short, report)
    assert moved >= DISTANCE_M - 5e-4, report
    assert moved_true >= 0.7 * DISTANCE_M, report  # along the true force: the retreat's direction is an estimate
    # one contact, ended well before the run's end (and within the time limit, above), and none the retreat caused:
    # on one link, with one obstacle. It may break and touch again while the obstacle -- a sphere on a critically
    # damped spring, pushed in while the reflex took over -- springs back after the arm (seen when the hold came
    # 39 ms after the onset, the arm 17 mm further in: free 52 ms, then 2.5 N for 8 ms); that touch stays light
    touched = truth[first]["contacts"][0]
    assert {(c["link"], c["source"]) for r in truth for c in r["contacts"]} == {(touched["link"], touched["source"])}, \
        report
    gap = next((i for i in range(first, last + 1) if not truth[i]["contacts"]), None)
    if gap is not None:
        again = max(_force(r) for r in truth[gap:last + 1])
        print(f"the obstacle touched again after {gap - first} samples, at most {again:.1f} N")
        assert again < FORCE_N, report
    assert truth[last]["t"] < truth[-1]["t"] - 0.4, report
    assert not proc.stderr.count("Traceback"), proc.stderr[-2000:]


def test_a_hand_guiding_the_arm_is_not_retreated_from(tmp_path, clean_or_loaded):
    """``guidance`` (typical world): a hand leads the resting arm by a distal point and the arm yields. The reflex
    leaves the arm free while the classifier decides, and lets the hand lead it: no retreat, the contacts named
    guidance. (Held at the onset, the arm fought the hand: its force built as a clamp's and it was retreated from.)"""
    events = tmp_path / "events.jsonl"
    proc = subprocess.run([sys.executable, "-m", "ftc_hw", "monitor", "--scene", "dxl-arm", "--sim", "--scenario",
                           "guidance", "--reality", "typical", "--duration", "6", "--events", str(events),
                           "--no-view", "--reflex", "retreat"], capture_output=True, text=True, timeout=200)
    clean_or_loaded(proc.returncode, proc.stdout + proc.stderr)
    said = " ".join(proc.stdout.split())
    got = read_events(events)
    onsets, offsets = [e for e in got if e["kind"] == "onset"], [e for e in got if e["kind"] == "offset"]
    assert len(onsets) == len(offsets) >= 1, said[-3000:]  # the hand at 0.5 s (the scenario spreads its hands)
    assert "reflex retreat: contact" not in said, said[-3000:]
    assert f"reflex retreat: {len(onsets)} guided contact(s) not retreated from" in said, said[-3000:]
    assert all(e["intent"] == "guidance" for e in offsets), [(e["contact_class"], e["intent"]) for e in offsets]
