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
