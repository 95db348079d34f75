"""``bench pipeline --repeat``: the spread across runs, each in its own process."""

from __future__ import annotations

import json

import pytest

from cone_perception.timing import format_runs, summarize_runs
from cone_perception.cli import main


def _run(median_ms: float, p99_ms: float, forward_ms: float, rss: float) -> dict:
    return {"stages": {"end_to_end": {"median_ms": median_ms, "p99_ms": p99_ms}, "forward": {"median_ms": forward_ms}},
            "fps": 1e3 / median_ms, "peak_rss_mb": rss}


def test_summarize_runs_counts_the_runs_within_the_tail_limit() -> None:
    runs = [_run(10.0, 11.0, 8.0, 600), _run(8.0, 16.0, 6.5, 640), _run(9.0, 13.5, 7.0, 610)]
    s = summarize_runs(runs)
    assert s["runs"] == 3
    assert s["median_ms"] == {"min": 8.0, "median": 9.0, "max": 10.0}
    assert s["fps"] == {"min": 100.0, "max": 125.0}
    assert s["p99_over_median"] == [1.1, 2.0, 1.5]
    assert s["runs_within_tail_limit"] == 2  # 1.5x exactly is within; 2.0x is not
    assert s["p99_over_median_median"] == 1.5
    assert s["forward_median_ms"] == {"min": 6.5, "max": 8.0} and s["peak_rss_mb_max"] == 640
    assert summarize_runs(runs, tail_limit=1.2)["runs_within_tail_limit"] == 1
    text = format_runs(s)
    assert "2 of 3" in text and "1.10, 1.50, 2.00" in text
    with pytest.raises(ValueError):
        summarize_runs([])


def test_repeat_runs_separate_processes_and_reports_each(capsys) -> None:
    assert main(["bench", "pipeline", "--repeat", "2", "--frames", "5", "--warmup", "1", "--scenes", "1", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["runs"]) == 2 and doc["summary"]["runs"] == 2
    assert all(r["stages"]["end_to_end"]["n"] == 5 and r["threads"] == 1 for r in doc["runs"])
    ratios = [r["stages"]["end_to_end"]["p99_ms"] / r["stages"]["end_to_end"]["median_ms"] for r in doc["runs"]]
    assert doc["summary"]["p99_over_median"] == [round(x, 3) for x in ratios]


def test_repeat_is_for_the_pipeline_only(capsys) -> None:
    assert main(["bench", "adapter", "--repeat", "2"]) == 2
    assert "--repeat" in capsys.readouterr().err
