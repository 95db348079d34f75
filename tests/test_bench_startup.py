"""``cone-perception bench startup`` (bench/startup.py, rostools/startup.py): the figures per phase and the targets, and
one short live run of the pipeline node (a priming start, one warm start, one restart after ``kill -9``)."""

from __future__ import annotations

import json
import math

from cone_perception.bench.startup import Start, format_summary, summarize
from cone_perception.cli import main


def test_the_summary_gives_each_phases_spread_and_judges_the_targets():
    starts = [Start("cold", 9.0, 14.0, 600.0), Start("warm", 1.0, 1.5, 300.0), Start("warm", 1.2, 2.5, 310.0),
              Start("warm", 1.1, 1.8, 305.0), Start("kill", 1.3, 2.2, 320.0),
              Start("kill", math.nan, math.nan, 100.0, "no /cones within 120 s")]
    s = summarize(starts)
    assert s["phases"]["warm"]["first_cones_s"] == {"n": 3, "median": 1.8, "min": 1.5, "max": 2.5, "missing": 0}
    assert s["phases"]["kill"]["first_cones_s"]["missing"] == 1 and s["phases"]["kill"]["failed"] == [
        "1: no /cones within 120 s"]
    t = s["targets"]
    assert t["warm exec->first /cones median <= 2 s"] == (1.8, True)
    assert t["kill exec->first /cones median <= 2 s"][1] is False  # a start that never came back misses it
    assert t["peak RSS (warm, kill) <= 400 MiB"] == (320.0, True)  # the cold start's torch is not the ONNX path's
    text = format_summary(s)
    assert "warm        3  1.10 (1.00-1.20)" in text and "MISSED" in text


def test_a_short_live_run_times_the_node_to_its_first_cones(capsys):
    rc = main(["bench", "startup", "--starts", "1", "--cold-starts", "0", "--json"])
    s = json.loads(capsys.readouterr().out)
    assert rc in (0, 1)
    assert set(s["phases"]) == {"warm", "kill"}
    for phase in ("warm", "kill"):
        p = s["phases"][phase]
        assert p["failed"] == [] and p["first_cones_s"]["n"] == 1
        assert 0 < p["ready_s"]["median"] <= p["first_cones_s"]["median"] < 120
        assert 50 < p["peak_rss_mb"] < 2000
    assert "pipeline --ros-args -p calibration:=" in s["node"]
