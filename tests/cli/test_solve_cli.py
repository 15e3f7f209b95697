"""``ftc solve``: one output line per input line, in order; bad lines get error lines."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ftc_hw.model import ArmModel, Contact
from ftc_hw.scene import load_scene

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

FTC = [str(Path(sys.executable).parent / "ftc")]


def _raw_line(model, q, link, point, force, **extra):
    raw = model.predicted_wrench(q, level="gravity", contacts=[Contact(link, point, force)])
    return json.dumps({"q": list(q), "wrench": list(raw), **extra})


def test_raw_and_compensated_lines_and_errors(tmp_path):
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    q = np.array(scene.robot.home)
    b_T = model.kinematics(q)["link3"]
    point = b_T[:3, :3] @ np.array([0.1, 0.0, 0.04]) + b_T[:3, 3]
    normal = b_T[:3, :3] @ np.array([0.0, 0.0, 1.0])
    force = -30.0 * normal + 5.0 * (b_T[:3, :3] @ np.array([1.0, 0, 0]))
    ext = model.predicted_wrench(q, level="bias", contacts=[Contact("link3", point, force)])
    lines = [
        _raw_line(model, q, "link3", point, force),
        json.dumps({"q": list(q), "wrench": list(ext), "compensated": True}),
        "this is not json",
        json.dumps({"q": [0.0, 0.0], "wrench": [0, 0, 0, 0, 0, 0]}),
        json.dumps({"q": list(q)}),
        '{"q": [0, 0, 0], "wrench": [1, 2, NaN, 0, 0, 0]}',
        json.dumps({"q": list(q), "wrench": list(ext), "compensated": "yes"}),
        json.dumps([1, 2, 3]),
        _raw_line(model, q, "link3", point, force, qd=[0, 0, 0], qdd=[0, 0, 0], tau_ext=[0.1, 0.2, 0.3]),
    ]
    src = tmp_path / "in.jsonl"
    src.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out.jsonl"
    proc = subprocess.run([*FTC, "solve", "--scene", "leng2016", "--input", str(src), "--output", str(out)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    records = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(records) == len(lines)
    for r in (records[0], records[1], records[8]):
        assert r["contact"] and r["link"] == "link3"
        np.testing.assert_allclose(r["point"], point, atol=1e-9)
        np.testing.assert_allclose(r["force"], force, atol=1e-7)
        assert set(r) >= {"normal", "point_std", "force_std", "residual", "flags", "candidates"}
        assert r["candidates"][0]["link"] == "link3" and "score" in r["candidates"][0]
    errors = {i: records[i] for i in (2, 3, 4, 5, 6, 7)}
    for i, r in errors.items():
        assert r["line"] == i + 1 and r["error"], r
    assert "not JSON" in errors[2]["error"]
    assert "'q' must be a list of 3" in errors[3]["error"]
    assert "missing 'wrench'" in errors[4]["error"]
    assert "NaN" in errors[5]["error"]


def test_stdin_stdout_and_method_choice():
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    q = np.array(scene.robot.home)
    b_T = model.kinematics(q)["link2"]
    point = b_T[:3, :3] @ np.array([0.1, 0.04, 0.0]) + b_T[:3, 3]
    force = -20.0 * (b_T[:3, :3] @ np.array([0.0, 1.0, 0.0]))
    line = _raw_line(model, q, "link2", point, force)
    for method in ("ours", "leng2016"):
        proc = subprocess.run([*FTC, "solve", "--scene", "leng2016", "--method", method], input=line + "\n",
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        r = json.loads(proc.stdout)
        np.testing.assert_allclose(r["point"], point, atol=1e-6)


def _strict(line: str):
    def refuse(c):
        raise AssertionError(f"non-standard JSON constant {c} in {line}")
    return json.loads(line, parse_constant=refuse)


def test_out_of_range_input_is_an_error_line_and_output_is_standard_json(tmp_path):
    scene = load_scene("leng2016")
    q = list(scene.robot.home)
    lo, hi = ArmModel(scene).joint_limits(unlimited=np.inf)
    limited = int(np.flatnonzero(np.isfinite(hi))[0])
    beyond = list(q)
    beyond[limited] = float(hi[limited]) + 0.5
    lines = [
        json.dumps({"q": q, "wrench": [0, 0, 1e308, 0, 0, 0]}),  # beyond the sensor's range
        "",  # a blank line still gets its line
        json.dumps({"q": q, "wrench": [0, 0, 1e308, 0, 0, 0], "compensated": True}),
        json.dumps({"q": beyond, "wrench": [0, 0, 1, 0, 0, 0]}),
        "   ",
    ]
    src = tmp_path / "in.jsonl"
    src.write_text("\n".join(lines) + "\n")
    proc = subprocess.run([*FTC, "solve", "--scene", "leng2016", "--input", str(src)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    records = [_strict(line) for line in proc.stdout.splitlines()]
    assert len(records) == len(lines)
    assert "fz = 1e+308 N is beyond the sensor's range" in records[0]["error"] and records[0]["line"] == 1
    assert records[1] == {"error": "blank line", "line": 2}
    flagged = records[2]  # an already-compensated wrench is the caller's: solved, never a NaN contact
    assert not flagged["contact"] and "non_finite" in flagged["flags"] and None in flagged["force"]
    assert "RuntimeWarning" not in proc.stderr
    assert f"q[{limited}] = " in records[3]["error"] and "outside joint" in records[3]["error"]
    assert records[4] == {"error": "blank line", "line": 5}


def test_file_errors_are_one_line_messages(tmp_path):
    no_dir = str(tmp_path / "no-dir" / "out.jsonl")
    for args, says in ((["--input", str(tmp_path / "missing.jsonl")], "cannot open input file"),
                       (["--input", "-", "--output", no_dir], "cannot open output file")):
        proc = subprocess.run([*FTC, "solve", "--scene", "leng2016", *args], input="",
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode != 0
        assert proc.stderr.strip().count("\n") == 0 and says in proc.stderr, proc.stderr
        assert "Traceback" not in proc.stderr


def test_leng2016_takes_base_moments_of_the_papers_experiment(tmp_path):
    """Forces of a few hundred newtons at the paper's test pose make base moments above 100 N m: the
    scene's sensor range must take them (it is sized from the arm and its loads, not refuse them)."""
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    q = np.array(scene.robot.home)
    b_T = model.kinematics(q)["link3"]
    point = b_T[:3, :3] @ np.array([0.18, 0.0, 0.04]) + b_T[:3, 3]
    lines = []
    for magnitude in (100.0, 250.0, 400.0):
        force = -magnitude * (b_T[:3, :3] @ np.array([0.0, 0.0, 1.0]))
        lines.append(_raw_line(model, q, "link3", point, force))
    moments = [np.abs(json.loads(line)["wrench"][3:]).max() for line in lines]
    assert max(moments) > 100.0  # the case the old +-50 N m range refused
    src, out = tmp_path / "in.jsonl", tmp_path / "out.jsonl"
    src.write_text("\n".join(lines) + "\n")
    proc = subprocess.run([*FTC, "solve", "--scene", "leng2016", "--input", str(src), "--output", str(out)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    for record in map(json.loads, out.read_text().splitlines()):
        assert "error" not in record, record
        assert record["contact"] and record["link"] == "link3"
        np.testing.assert_allclose(record["point"], point, atol=1e-6)


def test_a_scene_sensed_through_its_joints_takes_external_joint_torques(tmp_path):
    """panda (joint torque sensors): a push on link 7 from the torques it exerts about the joints."""
    scene = load_scene("panda")
    model = ArmModel(scene)
    q = np.array(scene.robot.home)
    surf = next(s for s in model.surfaces if s.link == "link7")
    b_T = model.kinematics(q)["link7"]
    radial = b_T[:3, :3] @ surf.link_T_geom[:3, :3] @ np.array([1.0, 0.0, 0.0])
    point = b_T[:3, :3] @ (surf.link_T_geom[:3, 3] + surf.size[0] * surf.link_T_geom[:3, :3] @ [1.0, 0, 0]) \
        + b_T[:3, 3]
    force = -20.0 * radial
    tau = model.jacobian(q, "link7", point).T @ force
    lines = [json.dumps({"q": list(q), "tau_ext": list(tau), "tau_ext_std": [0.02] * 7}),
             json.dumps({"q": list(q), "wrench": [0.0] * 6}),  # a wrench is no joint torque
             json.dumps({"q": list(q), "tau_ext": list(tau), "tau_ext_std": [0.0] * 7})]
    src, out = tmp_path / "in.jsonl", tmp_path / "out.jsonl"
    src.write_text("\n".join(lines) + "\n")
    proc = subprocess.run([*FTC, "solve", "--scene", "panda", "--input", str(src), "--output", str(out)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    good, no_tau, zero_std = map(json.loads, out.read_text().splitlines())
    assert good["contact"] and good["link"] == "link7", good
    assert np.linalg.norm(np.array(good["point"]) - point) < 0.01
    assert np.linalg.norm(np.array(good["force"]) - force) < 2.0
    assert no_tau == {"error": "missing 'tau_ext'", "line": 2}
    assert zero_std["error"] == "'tau_ext_std' must be > 0"
    bad = subprocess.run([*FTC, "solve", "--scene", "panda", "--method", "leng2016", "--input", str(src)],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode != 0 and "sensed through its joints" in bad.stderr
