"""The ftc command as a user runs it."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ftc_hw import __version__
from ftc_hw.cli import app

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

runner = CliRunner()


def _ftc() -> list[str]:
    exe = shutil.which("ftc", path=str(Path(sys.executable).parent))
    return [exe] if exe else [sys.executable, "-m", "ftc_hw"]


def test_version_through_the_console_script():
    out = subprocess.run([*_ftc(), "--version"], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == f"ftc-hw {__version__}"


def test_scenes_lists_the_builtins_one_line_each():
    result = runner.invoke(app, ["scenes"])
    assert result.exit_code == 0, result.output
    lines = result.output.strip().splitlines()
    names = [line.split()[0] for line in lines]
    assert {"leng2016", "ur5e", "dxl-arm", "ur10e", "panda"} <= set(names)
    said = {line.split()[0]: line for line in lines}
    assert "sensing flange_ft + currents, F/T 500 Hz at the flange" in said["ur10e"]
    assert "sensing joint_torques," in said["panda"] and "F/T" not in said["panda"].split(" - ")[0]


def test_sim_list():
    result = runner.invoke(app, ["sim", "--list"])
    assert result.exit_code == 0
    for name in ("static-pokes", "sweep-with-collision", "payload-poses"):
        assert name in result.output


def test_sim_writes_truth_one_line_per_sample(tmp_path):
    truth = tmp_path / "t.jsonl"
    proc = subprocess.run([*_ftc(), "sim", "leng2016", "--scenario", "static-pokes", "--duration", "2",
                           "--truth", str(truth), "--fast"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    first = json.loads(proc.stdout.splitlines()[0])
    assert first["scene"] == "leng2016" and isinstance(first["devices"], list)
    lines = truth.read_text().splitlines()
    assert len(lines) == 2000  # 2 s at the leng2016 sensor's 1 kHz
    records = [json.loads(line) for line in lines]
    assert all({"t", "contact", "link", "point", "force"} <= r.keys() for r in records)
    touched = [r for r in records if r["contact"]]
    assert touched, "static-pokes poked nothing in 2 s"
    for r in touched:
        assert r["link"] in ("link1", "link2", "link3")
        assert len(r["point"]) == 3 and len(r["force"]) == 3
    ts = [r["t"] for r in records]
    assert ts == sorted(ts) and ts[1] - ts[0] == pytest.approx(1e-3)


def test_sim_same_seed_same_truth(tmp_path):
    outs = []
    for i in range(2):
        path = tmp_path / f"t{i}.jsonl"
        r = runner.invoke(app, ["sim", "leng2016", "--scenario", "static-pokes", "--duration", "0.5", "--seed",
                                "4", "--truth", str(path), "--fast"])
        assert r.exit_code == 0, r.output
        outs.append(path.read_text())
    assert outs[0] == outs[1]


def test_sim_errors_are_clear(tmp_path):
    r = runner.invoke(app, ["sim", "nowhere"])
    assert r.exit_code == 2 and "no built-in scene" in r.output
    r = runner.invoke(app, ["sim", "leng2016", "--scenario", "dance"])
    assert r.exit_code == 2 and "unknown scenario" in r.output
    bad = tmp_path / "bad.toml"
    bad.write_text("schema = 1\nname = 'x'\n")
    r = runner.invoke(app, ["sim", str(bad)])
    assert r.exit_code == 2 and "bad.toml: robot: missing table" in r.output


def test_bench_bus_writes_json(tmp_path):
    out = tmp_path / "bus.json"
    r = runner.invoke(app, ["bench", "bus", "--json", str(out), "--frames", "20000"])
    assert r.exit_code == 0, r.output
    figures = json.loads(out.read_text())
    assert figures["publish_deliver_fps"]["1_sub_callback"] > 0


def test_bench_pipeline_prints_its_tables_and_writes_json(tmp_path):
    out = tmp_path / "pipeline.json"
    r = runner.invoke(app, ["bench", "pipeline", "--scene", "ur5e", "--seconds", "1", "--realtime", "0",
                            "--json", str(out)])
    assert r.exit_code == 0, r.output
    assert "cost per F/T frame" in r.output and "localization" in r.output and "keeping up" in r.output
    figures = json.loads(out.read_text())["ur5e@1000"]
    assert "realtime" not in figures and figures["offline"]["frames"] == 1000
    assert figures["offline"]["stages_us"]["reader"]["frames"] == 1000


def test_bench_geometry_prints_a_table_and_writes_json(tmp_path):
    out = tmp_path / "geometry.json"
    r = runner.invoke(app, ["bench", "geometry", "--json", str(out), "--lines", "2000"])
    assert r.exit_code == 0, r.output
    assert "geometry engine" in r.output and "ellipsoid" in r.output
    figures = json.loads(out.read_text())
    assert figures["lines"] == 2000 and set(figures["kinds"]) >= {"sphere", "capsule", "cylinder", "box"}
    assert all(k["crossings"] > 0 and 0.0 < k["hit_fraction"] <= 1.0 for k in figures["kinds"].values())


def test_bench_solver_scores_both_methods_on_the_same_cases(tmp_path):
    out = tmp_path / "solver.json"
    r = runner.invoke(app, ["bench", "solver", "--cases", "100", "--scene", "leng2016", "--json", str(out)])
    assert r.exit_code == 0, r.output
    figures = json.loads(out.read_text())
    keys = {"pos_err_mm_median", "pos_err_mm_p95", "pos_err_mm_max", "dir_err_deg_median", "mag_err_pct_median",
            "crlb_pos_mm_rms", "pos_err_mm_rms", "coverage95", "latency_us_median", "latency_us_p99",
            "batch_frames_per_s", "crlb_mag_pct_median", "force_only_mag_pct_median"}
    for label in ("noise_free", "noisy"):
        ours, leng = figures[label]["leng2016"]["ours"], figures[label]["leng2016"]["leng2016"]
        assert keys <= ours.keys() and keys <= leng.keys()
        assert ours["cases"] == leng["cases"] > 50
        assert ours["own_cases"]["cases"] >= ours["cases"]
    noisy = figures["noisy"]["leng2016"]
    for col, d in noisy["leng2016"]["ours_minus_this"].items():
        assert d["ci95"][0] <= d["diff"] <= d["ci95"][1], col
        assert d["diff"] == pytest.approx(noisy["ours"][col] - noisy["leng2016"][col])
        assert d["verdict"] == ("better" if d["ci95"][1] < 0 else "worse" if d["ci95"][0] > 0 else "tie")
    # leng2016's force noise is isotropic: the moment adds nothing on the magnitude's scale
    assert noisy["ours"]["crlb_mag_pct_median"] == pytest.approx(noisy["ours"]["force_only_mag_pct_median"])
    assert 0 < noisy["ours"]["crlb_mag_pct_median"] < 1
    assert noisy["ours"]["coverage95"] > 0.8 and noisy["leng2016"]["coverage95"] == 0.0  # the paper gives no covariance
    assert noisy["ours"]["pos_err_mm_median"] > 0 and figures["noise_free"]["leng2016"]["ours"]["pos_err_mm_max"] < 1e-6


def test_bench_solver_compares_the_magnitude_with_the_force_reading_on_many_cases(tmp_path):
    out = tmp_path / "solver.json"
    r = runner.invoke(app, ["bench", "solver", "--cases", "100", "--scene", "leng2016", "--method", "ours",
                            "--magnitude-cases", "4000", "--json", str(out)])
    assert r.exit_code == 0, r.output
    assert "|f_measured|" in r.output
    d = json.loads(out.read_text())["magnitude_vs_force_reading"]["leng2016"]
    assert d["cases"] > 3000
    assert d["diff"] == pytest.approx(d["ours_pct_median"] - d["force_reading_pct_median"])
    assert d["ci95"][0] <= d["diff"] <= d["ci95"][1]
    assert d["verdict"] == ("better" if d["ci95"][1] < 0 else "worse" if d["ci95"][0] > 0 else "tie")
    # both at the force noise's limit (0.05 N on 5-200 N: a few hundredths of a per cent)
    assert 0.01 < d["force_reading_pct_median"] < 0.1 and abs(d["diff"]) < 0.01
    bad = runner.invoke(app, ["bench", "solver", "--magnitude-cases", "10"])
    assert bad.exit_code != 0 and "magnitude-cases" in bad.output


def test_devices_probe_says_what_it_tried():
    r = runner.invoke(app, ["devices", "probe", "--address", "127.0.0.98", "--timeout", "0.2"])
    assert r.exit_code == 1, r.output
    assert "UR controller at 127.0.0.98: RTDE at 127.0.0.98:30004 does not answer" in r.output, r.output
    assert "nothing answered" in r.output
    r = runner.invoke(app, ["devices", "probe", "--device", "ft.address=/dev/ttyUSB0"])
    assert r.exit_code == 2 and "give --scene too" in r.output


def test_sim_addresses_are_checked_before_anything_starts():
    r = runner.invoke(app, ["sim", "ur5e", "--address", "arm=192.0.2.7"])
    assert r.exit_code == 2 and "loopback addresses only" in r.output, r.output
    r = runner.invoke(app, ["calibrate", "--scene", "ur5e", "--device", "arm.adress=192.0.2.7"])
    assert r.exit_code == 2 and "did you mean 'address'" in r.output, r.output


def test_plot_is_on_by_default_and_no_plot_reaches_calibrate_and_identify(monkeypatch, tmp_path):
    import ftc_hw.app.calibration.calibrate as calibrate_app
    import ftc_hw.cli.identify as identify_cli

    seen = []
    monkeypatch.setattr(calibrate_app, "run_calibrate", lambda scene, options: seen.append(options.plot) or 0)
    monkeypatch.setattr(identify_cli, "run_identify", lambda scene, rec, opts, **kw: seen.append(opts.plot) or 0)
    calibrate, identify = ["calibrate", "--scene", "dxl-arm"], ["identify", str(tmp_path / "run.mcap"), "--scene",
                                                                 "dxl-arm"]
    for args in (calibrate, [*calibrate, "--no-plot"], identify, [*identify, "--no-plot"]):
        r = runner.invoke(app, args)
        assert r.exit_code == 0, r.output
    assert seen == [True, False, True, False]


def test_resume_after_needs_the_simulated_world_and_a_ur_controller():
    r = runner.invoke(app, ["monitor", "--scene", "ur5e", "--resume-after", "0.5", "--view", "none"])
    assert r.exit_code == 2 and "--resume-after needs --sim" in r.output, r.output
    r = runner.invoke(app, ["monitor", "--scene", "dxl-arm", "--sim", "--resume-after", "0.5", "--view", "none",
                            "--duration", "1"])
    assert r.exit_code == 1 and "only an emulated UR controller resumes" in r.output, r.output


def test_the_world_ahead_needs_a_simulated_run_of_a_given_length_and_no_retreat():
    base = ["monitor", "--scene", "ur5e", "--world-ahead", "--view", "none"]
    for extra, said in (([], "--world-ahead needs --sim"), (["--sim"], "--world-ahead needs --duration"),
                        (["--sim", "--duration", "1", "--reflex", "retreat"], "the arm cannot retreat in it")):
        r = runner.invoke(app, [*base, *extra])
        assert r.exit_code == 2 and said in r.output, r.output
    r = runner.invoke(app, ["sim", "ur5e", "--world-ahead", "--fast"])
    assert r.exit_code == 2 and "computed ahead is played" in r.output, r.output


@pytest.mark.parametrize("command", [[], ["monitor"], ["calibrate"], ["identify"], ["sim"], ["serve"],
                                     ["bench", "reality"]])
def test_help_shows_no_type_after_a_flag(command):
    r = runner.invoke(app, [*command, "--help"], env={"COLUMNS": "200"})
    assert r.exit_code == 0 and "--help" in r.output
    assert "<bool>" not in r.output, [line for line in r.output.splitlines() if "<bool>" in line]


def test_sensing_a_scene_does_not_have_is_refused_by_name():
    proc = subprocess.run([*_ftc(), "monitor", "--scene", "ur5e", "--sim", "--sensing", "joint_torques",
                           "--duration", "1", "--no-view"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1
    assert "scene 'ur5e' has no joint_torques (it has: base_ft + currents)" in proc.stderr
