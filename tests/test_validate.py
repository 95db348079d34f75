"""The validation suite (``cone-perception validate``, issue 41): its list, its distribution maths, and its machinery
on a tiny set (one tiny rendered drive, one that fails, a real set made of two rendered frames, one that is missing)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cone_perception.cli import main
from cone_perception.errors import ConfigError
from cone_perception.evaluation.spread import FAILED, FIGURES, MISSING, OK, distribution, spread
from cone_perception.replay.suite import Settings, run_suite, select
from cone_perception.replay.suite_drives import (
    DRIVES, JUDGING_SEEDS, LOW_SUN_DEG, QUICK, REAL_SETS, TUNING_SEEDS, DriveSpec, RealSet, drive_seed, sun_elevation_deg,
    tuning_drives,
)
from cone_perception.synth.writers import write_dataset


def test_the_list_spans_the_generator_on_judging_seeds_and_tuning_never_meets_them() -> None:
    assert len(DRIVES) >= 24 and len({d.name for d in DRIVES}) == len(DRIVES)
    assert len({d.seed for d in DRIVES}) == len(DRIVES) and all(d.seed in JUDGING_SEEDS for d in DRIVES)
    tune = tuning_drives()
    assert all(d.seed in TUNING_SEEDS for d in tune) and not set(JUDGING_SEEDS) & set(TUNING_SEEDS)
    assert [replace(t, name=d.name, seed=d.seed) for t, d in zip(tune, DRIVES)] == list(DRIVES)  # the same variety
    hfov = [d.hfov_deg for d in DRIVES]
    assert min(hfov) <= 60 and max(hfov) >= 100
    assert {(1280, 720), (2048, 1536)} <= {d.size for d in DRIVES}
    for what in ("low_sun", "car_motion", "k1", "compressed"):
        assert any(getattr(d, what) for d in DRIVES), what
    assert not all(d.jitter for d in DRIVES)
    assert {"yellow", "white"} <= {d.paint_lines for d in DRIVES}
    assert {"autocross", "skidpad", "acceleration"} == {d.track for d in DRIVES}
    assert any(d.size == (2048, 1536) and d.hfov_deg == 59 and d.height_m == 1.03 and d.pitch_deg == 15
               and d.k1 == -0.126 for d in DRIVES)  # the held-out camera's look-alike
    for d in DRIVES:
        d.config().validate()  # every camera sees the ground


def test_selection_quick_named_and_refused() -> None:
    drives, real = select(None, True, False)
    assert [d.name for d in drives] == [d.name for d in DRIVES if d.name in QUICK] and real == REAL_SETS
    drives, real = select("1080-skidpad,real_val_1080", False, True)
    assert [d.name for d in drives] == ["tune-1080-skidpad"] and [r.name for r in real] == ["real_val_1080"]
    with pytest.raises(ConfigError, match="no-such-drive"):
        select("base-a,no-such-drive", False, False)


def test_a_low_sun_seed_is_the_first_with_the_sun_low() -> None:
    tiny = DriveSpec("tiny-low-sun", 7, "", size=(320, 180), low_sun=True)
    seed = drive_seed(tiny)
    assert sun_elevation_deg(tiny, seed) <= LOW_SUN_DEG
    assert all(sun_elevation_deg(tiny, s) > LOW_SUN_DEG for s in range(7, seed))
    heldout = next(d for d in DRIVES if d.name == "heldout-cam-lowsun")
    assert drive_seed(heldout) == heldout.seed  # the list holds the seed its search finds


def test_spread_median_worst_tenth_and_worst() -> None:
    up = [0.9, 0.5, float("nan"), 0.7, 1.0, 0.8, 0.6, 0.95, 0.85, 0.75, 0.65]  # 10 finite values
    s = spread(up, higher_better=True)
    finite = np.array([v for v in up if not math.isnan(v)])
    assert s["n"] == 10 and s["median"] == pytest.approx(0.775)
    assert s["worst_tenth"] == pytest.approx(0.5 + 0.9 * (0.6 - 0.5))  # the 10th percentile, linear between drives
    assert s["worst"] == 0.5 and s["worst_index"] == 1
    down = spread(list(finite), higher_better=False)  # false cones, errors: the 90th percentile, the largest
    assert down["worst"] == 1.0 and down["worst_tenth"] == pytest.approx(np.percentile(finite, 90))
    assert spread([float("nan")], True)["n"] == 0


def test_distribution_leaves_out_failed_rows_and_names_the_worst_drive() -> None:
    rows = [{"drive": "a", "status": OK, "recall_25_40": 0.9, "false_per_frame": 0.1},
            {"drive": "b", "status": OK, "recall_25_40": 0.7, "false_per_frame": 0.5},
            {"drive": "c", "status": FAILED, "error": "boom"},
            {"drive": "d", "status": OK, "recall_25_40": 0.8, "false_per_frame": float("nan")}]
    d = distribution(rows)
    assert d["recall_25_40"]["n"] == 3 and d["recall_25_40"]["median"] == pytest.approx(0.8)
    assert d["recall_25_40"]["worst"] == 0.7 and d["recall_25_40"]["worst_drive"] == "b"
    assert d["false_per_frame"]["n"] == 2 and d["false_per_frame"]["worst_drive"] == "b"
    assert d["recall_0_7"]["n"] == 0 and d["recall_0_7"]["worst_drive"] is None
    assert set(d) == {f.key for f in FIGURES}


TINY = DriveSpec("tiny", 410_001, "a tiny drive", size=(640, 360))


@pytest.fixture(scope="module")
def tiny_suite(tmp_path_factory):
    """One suite run: the tiny drive (1 s at 3 fps), a drive that cannot render, a real set of two rendered frames and
    a missing one."""
    tmp = tmp_path_factory.mktemp("suite")
    write_dataset(TINY.config(), 2, tmp / "realish", frames_per_track=2, val_frac=0.0, progress=False)
    real = (RealSet("realish", str(tmp / "realish"), None, (120, 360), 2, "120,180", "never"),
            RealSet("gone", str(tmp / "gone"), None, (0, 360), 2, "0,60", "cone-perception data restore-aspect ..."))
    bad = DriveSpec("bad-hfov", 410_002, "an impossible camera", size=(640, 360), hfov_deg=5.0)
    code = run_suite((TINY, bad), real, Settings(), tmp / "out", tmp / "cache", seconds=1.0, fps=3.0, progress=False)
    return tmp, code, json.loads((tmp / "out" / "suite.json").read_text())


def test_failed_and_missing_entries_are_rows_and_the_run_ends_non_zero(tiny_suite) -> None:
    tmp, code, rep = tiny_suite
    assert code == 1 and rep["failed"] == ["bad-hfov"] and rep["missing"] == ["gone"]
    rows = {r["drive"]: r for r in rep["drives"] + rep["real_sets"]}
    assert rows["bad-hfov"]["status"] == FAILED and "--hfov" in rows["bad-hfov"]["error"]
    assert rows["gone"]["status"] == MISSING and "gone" in rows["gone"]["error"] and "restore-aspect" in rows["gone"]["error"]
    assert "Traceback" in (tmp / "out" / "logs" / "bad-hfov.log").read_text()
    assert rows["tiny"]["status"] == OK and rows["tiny"]["frames"] == 3 and rows["tiny"]["seed"] == TINY.seed
    # the distribution holds the one drive that ran
    assert rep["distribution"]["recall_7_15"]["n"] == 1
    assert rep["distribution"]["recall_7_15"]["median"] == rows["tiny"]["recall_7_15"]
    assert rep["distribution"]["err_fixed_7_15"]["worst_drive"] == "tiny"
    csv_lines = (tmp / "out" / "drives.csv").read_text().splitlines()
    assert len(csv_lines) == 3 and csv_lines[1].startswith("tiny,ok,") and "bad-hfov,failed" in csv_lines[2]
    assert (tmp / "out" / "spread.png").stat().st_size > 10_000


def test_a_drive_is_scored_as_replay_scores_it(tiny_suite) -> None:
    """The suite's row of a drive holds what ``replay --gt-topic --track`` (image attitude, the bag's odometry) prints."""
    tmp, _, rep = tiny_suite
    row = next(r for r in rep["drives"] if r["drive"] == "tiny")
    out = tmp / "replay.json"
    assert main(["replay", str(tmp / "cache" / "tiny"), "--calib", str(tmp / "cache" / "tiny_calib.yaml"), "--gt-topic",
                 "/cones_gt", "--track", "--attitude", "image", "--odom-topic", "/odom", "--no-progress",
                 "--json", str(out)]) == 0
    s = json.loads(out.read_text())
    n_true = 0
    for band, key in (("0-7 m", "0_7"), ("7-15 m", "7_15"), ("15-25 m", "15_25"), ("25-40 m", "25_40")):
        b = s["localisation"]["extra_groups"][band]
        n_true += b["n_true"]
        assert row[f"recall_{key}"] == pytest.approx(b["recall"], nan_ok=True)
        assert row[f"err_att_{key}"] == pytest.approx(b["median_err_m"], nan_ok=True)
        assert row[f"tracked_recall_{key}"] == pytest.approx(s["tracking"]["tracked"]["bands"][band]["recall"], nan_ok=True)
    assert n_true > 10  # the tiny drive shows cones in its bands
    assert row["false_per_frame"] == pytest.approx(s["localisation"]["bands"]["false_per_frame"])
    # the same boxes through the fixed H: the same cones matched, other errors
    assert row["err_fixed_7_15"] > 0 and math.isfinite(row["err_fixed_7_15"])


def test_a_rerun_replays_the_cached_drive(tiny_suite) -> None:
    tmp, _, rep = tiny_suite
    bag = tmp / "cache" / "tiny" / "metadata.yaml"
    before = bag.stat().st_mtime_ns
    assert run_suite((TINY,), (), Settings(), tmp / "again", tmp / "cache", seconds=1.0, fps=3.0, progress=False) == 0
    assert bag.stat().st_mtime_ns == before  # not rendered again
    again = json.loads((tmp / "again" / "suite.json").read_text())["drives"][0]
    first = next(r for r in rep["drives"] if r["drive"] == "tiny")
    assert {k: again[k] for k in again if k != "wall_s"} == {k: first[k] for k in first if k != "wall_s"}


def test_a_real_set_is_scored_as_eval_scores_it(tiny_suite) -> None:
    tmp, _, rep = tiny_suite
    row = next(r for r in rep["real_sets"] if r["drive"] == "realish")
    assert row["status"] == OK and row["images"] == 2
    m = json.loads((tmp / "out" / "realish" / "metrics.json").read_text())
    assert row["map50"] == pytest.approx(m["detection"]["map50"])
    assert row["recall_ge_12px"] == pytest.approx(m["by_box_height"]["at_least_min_height"]["recall"], nan_ok=True)
    assert 0.0 <= row["recall"] <= 1.0


def test_the_docs_list_every_drive_with_its_seed() -> None:
    text = (Path(__file__).resolve().parents[1] / "docs" / "validation.md").read_text(encoding="utf-8")
    for d in DRIVES:
        assert f"| `{d.name}`" in text and f"| {d.seed} |" in text, d.name


def test_the_targets_are_read_off_the_distribution_met_or_missed_with_the_deciding_drive():
    from cone_perception.evaluation.spread import TARGETS, check_targets, distribution, format_targets

    def row(name, r25, false, att):
        return {"drive": name, "status": "ok", "recall_15_25": 0.99, "recall_25_40": r25, "false_per_frame": false,
                "err_att_7_15": att}

    rows = [row("a", 0.90, 0.10, 0.08), row("b", 0.85, 0.25, 0.09), row("c", 0.79, 0.15, 0.12)]
    checks = {(c["key"], c["stat"]): c for c in check_targets(distribution(rows))}
    assert len(checks) == len(TARGETS)
    assert checks[("recall_15_25", "worst")]["met"]
    miss = checks[("recall_25_40", "worst")]
    assert not miss["met"] and miss["drive"] == "c" and miss["value"] == pytest.approx(0.79) and miss["at_least"]
    assert checks[("false_per_frame", "worst")]["met"] and checks[("false_per_frame", "worst")]["drive"] == "b"
    assert checks[("false_per_frame", "median")]["met"] and checks[("false_per_frame", "median")]["drive"] is None
    assert checks[("err_att_7_15", "median")]["met"]  # median 0.09 <= 0.10
    text = format_targets(list(checks.values()))
    assert "0.790 (c) >= 0.8 MISSED" in text and "0.250 (b) <= 0.3 met" in text
    # a figure no drive has (every band empty) is not met
    none = check_targets(distribution([{"drive": "x", "status": "ok"}]))
    assert not any(c["met"] for c in none)
