"""``ftc bench proprio``: its columns are the issue's, and a short run of one column through the real
pipeline gives the figures the table shows (a run of a drawn ur10e sensed by its currents alone)."""
from __future__ import annotations

import pytest

from ftc_hw.bench.proprio import COLUMNS, Job, combine, run_job, select
from ftc_hw.detection.joint import chi2_isf


def test_the_columns_are_the_sensings_the_issue_names():
    sensings = {tuple(sorted(c.sensing)) for c in COLUMNS}
    for wanted in (("currents",), ("joint_torques",), ("base_ft",), ("base_ft", "currents"),
                   ("currents", "flange_ft")):
        assert wanted in sensings, wanted
    assert select(["panda*"]) == tuple(c for c in COLUMNS if c.scene == "panda")
    with pytest.raises(ValueError, match="no column matches 'kuka'"):
        select(["kuka"])


def test_a_short_column_runs_the_pipeline_and_sums_its_draws():
    column = select(["ur10e: currents"])[0]
    out = run_job(Job(column, draw=0, free_s=6.0, n_probes=4, identify_s=0.0))
    assert out["column"] == "ur10e: currents" and out["rate_hz"] == 500.0
    assert out["free_minutes"] == pytest.approx(0.1, abs=0.01)  # 6 s of joint samples at 500 Hz
    assert out["false_alarms"] == 0  # a drawn arm on the nominal model: no alarm in a free sweep
    assert sum(b["n"] for b in out["detection"].values()) == 4  # one probe in each force band
    assert out["detection"]["50-100 N"]["detected"] == 1.0
    row = combine([out, out])
    assert row["free_minutes"] == pytest.approx(2 * out["free_minutes"]) and row["false_alarms"] == 0
    assert row["detection"]["50-100 N"]["n"] == 2
    # the issue's "10 N and more": the bands from 10 N up as one (3 probes a draw)
    big = [p for p in out["probes"] if p["force_n"] >= 10.0 and p["link"] != "base"]
    every = [p for p in out["probes"] if p["force_n"] >= 10.0]  # the base's too
    assert row["at_least_10n"]["n"] == 2 * len(big) and row["at_least_10n"]["n_all"] == 2 * len(every)
    assert row["at_least_10n"]["detected"] == pytest.approx(sum(p["detected"] for p in big) / len(big))
    assert row["at_least_10n"]["detected_all"] == pytest.approx(sum(p["detected"] for p in every) / len(every))
    assert out["events"] > 0 and 0.0 <= row["ambiguous_share"] <= 1.0  # events in contact, shares of them
    # detectability: each probe's true d2 against the free run's floor and the ideal test's threshold (the
    # chi-square at p 1e-9 with the touched link's joints as degrees of freedom: 37.3 for 1, 53.3 for 6)
    dof = {"shoulder": 1, "upper_arm": 2, "forearm": 3, "wrist_1": 4, "wrist_2": 5, "wrist_3": 6, "tool": 6}
    for p in out["probes"]:
        if p["link"] == "base":
            assert p["d2_true"] == 0.0 and not p["detectable"]  # no joint moves it
        else:
            assert p["threshold"] == pytest.approx(chi2_isf(1e-9, dof[p["link"]]))
    floor = out["noise_floor_std_by_speed"]["std"]
    assert len(floor) == 6 and all(v is None or v > 0.0 for row in floor for v in row)
    for p in out["probes"]:
        assert p["detectable"] == (p["d2_true"] > p["threshold"])
    for band, b in out["detection"].items():
        every = [p for p in out["probes"] if p["band"] == band]
        able = [p for p in every if p["detectable"] and p["link"] != "base"]
        assert b["n_detectable"] == len(able)
        if able:
            assert b["detected_detectable"] == pytest.approx(sum(p["detected"] for p in able) / len(able))
        # every probe counted in the first tier (the base's too), the undetectable ones said, none dropped
        assert b["n_all"] == len(every) and b["n"] == sum(p["link"] != "base" for p in every)
        assert b["detected_all"] == pytest.approx(sum(p["detected"] for p in every) / len(every))
        assert b["n_undetectable"] == sum(not p["detectable"] for p in every)
    assert row["detection"]["50-100 N"]["n_all"] == 2 * out["detection"]["50-100 N"]["n_all"]
    assert sum(v["undetectable"] for v in row["undetectable_per_link"].values()) == \
        2 * sum(not p["detectable"] for p in out["probes"])
