"""The bus bench runs and reports every figure (no speed assertions: speed is the bench's job)."""

import json

from ftc_hw.bench.bus import run


def test_bench_writes_json_with_all_figures(tmp_path, capsys):
    out = tmp_path / "bench.json"
    result = run(out, frames=2000, repeat=1)
    assert json.loads(out.read_text()) == result
    assert set(result["publish_deliver_fps"]) == {
        "1_sub_callback",
        "1_sub_queue",
        "4_sub_callback",
        "4_sub_queue",
    }
    assert all(v > 0 for v in result["publish_deliver_fps"].values())
    assert 0 < result["sample_at_us"]["median"] <= result["sample_at_us"]["p99"]
    assert result["python"] and result["machine"]
    assert "sample_at" in capsys.readouterr().out


def test_pipeline_bench_times_every_stage_and_its_clock_changes_nothing(tmp_path):
    """The offline leg on the 7 kHz RDT scene: every record through a real UDP socket, every stage timed,
    and the staged pass (a clock that reads every stage's end) judges exactly as the plain one."""
    from ftc_hw.bench.compensation import record
    from ftc_hw.bench.pipeline import ROWS, monitor_pass, offline, reader_costs, scene_at

    scene = scene_at("ur5e-netft", None)
    rec = record(scene, "sweep-with-collision", 0.5, 1.0, 0)
    costs, what = reader_costs(scene, rec)
    assert costs.shape == (len(rec.t),) and (costs > 0).all() and "UDP" in what
    staged, plain = monitor_pass(scene, rec, staged=True), monitor_pass(scene, rec, staged=False)
    assert staged["counters"] == plain["counters"] and staged["onsets"] == plain["onsets"]
    assert (staged["index"] == plain["index"]).all() and plain["index"].size > 0.7 * len(rec.t)
    assert (staged["stages"][:, 0] > 0).all()  # compensation on every judged frame
    out = offline(scene, 0.5, 0, 1.0)
    assert set(out["stages_us"]) == set(ROWS) and out["frames"] == len(rec.t)
    assert out["stages_us"]["total"]["median"] > out["stages_us"]["pipeline"]["median"] > 0
