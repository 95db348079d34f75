"""``cone-perception soak``: the accounting and targets from the node's counts (ROS-free), and one
short soak through a live pipeline node."""

from __future__ import annotations

import json

import pytest

from cone_perception.bench.soak import SoakWindow, format_report, summarize

TOPIC = "/camera/image_raw"


def _values(ok, replaced, missing=0, queued=0, dropped=None) -> dict[str, str]:
    v = {f"{TOPIC}:ok": ok, f"{TOPIC}:replaced": replaced, f"{TOPIC}:missing": missing, f"{TOPIC}:queued": queued,
         f"{TOPIC}:received": ok + sum((dropped or {}).values())}
    v.update({f"dropped_{k}": n for k, n in (dropped or {}).items()})
    return {k: str(x) for k, x in v.items()}


def _windows(rss, p99):
    return [SoakWindow(t_s=10.0 * (i + 1), sent=300, rss_mb=r, latencies_ms=[p / 2] * 98 + [p] * 2)
            for i, (r, p) in enumerate(zip(rss, p99))]


def test_a_soak_never_shares_a_domain_with_a_test_run() -> None:
    """A soak started while a test run is on (or by a test) picks a ROS_DOMAIN_ID no test run uses."""
    from conftest import TEST_DOMAINS

    from cone_perception.replay.soak import SOAK_DOMAINS, default_domain_id

    ids = {default_domain_id(pid) for pid in range(1, 5000)}
    assert ids == set(SOAK_DOMAINS) and max(ids) <= 232  # every one used, and all valid for DDS
    assert not ids & set(TEST_DOMAINS)


def test_the_soak_counts_the_frames_of_the_run_only() -> None:
    base = _values(ok=3, replaced=1)  # the primer
    final = _values(ok=3 + 500, replaced=1 + 480, missing=10, queued=0, dropped={"too_large": 10})
    r = summarize(1000, base, final, TOPIC, _windows([500] * 8, [90] * 8), 10.0, 30, 80, 80.0, 500)
    assert (r["processed"], r["replaced"], r["missing"], r["dropped"], r["uncounted"]) == (500, 480, 10, {"too_large": 10}, 0)
    assert r["passed"] and "| **uncounted** | 0 |" in format_report(r)
    json.dumps(r)


def test_the_targets_are_checked() -> None:
    base, final = _values(0, 0), _values(ok=400, replaced=500)
    grown = summarize(1000, base, final, TOPIC, _windows([500, 500, 520, 540, 560, 580], [80] * 6), 10.0, 30, 60,
                      60.0, 400)
    assert grown["uncounted"] == 100 and not grown["targets"]["uncounted_0"]
    assert not grown["targets"]["rss_flat_5pct"] and grown["targets"]["latency_p99_last_le_first"]
    slower = summarize(900, base, final, TOPIC, _windows([500] * 6, [80, 80, 90, 100, 120, 150]), 10.0, 30, 60, 60.0, 400)
    assert slower["targets"]["uncounted_0"] and not slower["targets"]["latency_p99_last_le_first"]
    assert not slower["passed"] and "NO" in format_report(slower)


def test_a_short_soak_through_a_live_node_accounts_for_every_frame(tmp_path) -> None:
    from cone_perception.cli import main

    out = tmp_path / "soak.json"
    code = main(["soak", "--rate", "40", "--seconds", "6", "--window", "2", "--drive-seconds", "0.5", "--no-progress",
                 "--json", str(out)])
    r = json.loads(out.read_text())
    assert r["sent"] == 240 and r["uncounted"] == 0 and r["processed"] > 0
    assert r["processed"] + sum(r["dropped"].values()) + r["replaced"] + r["missing"] + r["queued"] == 240
    assert code in (0, 1)  # RSS and latency targets are a machine's; the accounting is not
