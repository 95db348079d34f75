"""End to end on a short synthetic drive (a seed no training scene used): offline replay and
live replay through the node processes give the same cones, with the right stamps, frame and
classes; the shipped model and calibration find and place the cones.

This is the CI bag replay of issue 6 (well under a minute).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cone_perception.classes import NUM_CLASSES
from cone_perception.data import bagio
from cone_perception.data.bags import read_ground_truth
from cone_perception.detector import RUNTIME_THREADS, Detector, default_model_path
from cone_perception.evaluation import LocalisationReport
from cone_perception.geometry.calib import load_calibration
from cone_perception.mapping import expected_truth
from cone_perception.rostools.live_replay import live_replay, write_result_bag
from cone_perception.pipeline import Pipeline
from cone_perception.replay import offline_replay
from cone_perception.resources import calib_dir
from cone_perception.synth.config import SynthConfig
from cone_perception.synth.writers import write_scene_bag

SEED = 90210  # not a training seed (training data: seed 1)


@pytest.fixture(scope="module")
def drive(tmp_path_factory) -> Path:
    bag = tmp_path_factory.mktemp("e2e") / "drive"
    write_scene_bag(SynthConfig(seed=SEED, jitter=False), 1.5, 10.0, bag, speed_mps=8.0, progress=False)
    return bag


@pytest.fixture(scope="module")
def offline(drive):
    det = Detector.load(default_model_path(), threads=RUNTIME_THREADS)  # as the nodes: the same boxes to the last bit
    det.warmup()
    return offline_replay(drive, Pipeline(load_calibration("example_mainhoop"), det, "fixed"), gt_topic="/cones_gt")


def _params() -> dict:
    # attitude fixed: the live chain first processes a primer frame (live_replay), which would give the attitude
    # filter one fit more than the offline replay; with the calibrated H the two must agree exactly
    return {"calibration": str(calib_dir() / "example_mainhoop.yaml"), "model": str(default_model_path()),
            "attitude": "fixed"}


@pytest.mark.parametrize("mode", ["fused", "separate"])
def test_live_equals_offline(drive, offline, mode, tmp_path) -> None:
    # the offline pipeline here is the band alone: the fused node's default far strip off (its own test: test_farband)
    live = live_replay(drive, mode=mode, params={**_params(), **({"far_rows": "none"} if mode == "fused" else {})})
    assert live.sent == 15 and not live.lost, live.node_output
    assert sorted(live.cones) == sorted(offline.cones)  # every frame, by its capture stamp
    assert live.frame_id == "rear_axle"
    for stamp, cones in offline.cones.items():
        got = live.cones[stamp]
        assert len(got) == len(cones), f"frame {stamp}: {len(got)} live vs {len(cones)} offline cones"
        order_a, order_b = np.lexsort((cones["y"], cones["x"])), np.lexsort((got["y"], got["x"]))
        np.testing.assert_allclose(got["x"][order_b], cones["x"][order_a], atol=1e-3)
        np.testing.assert_allclose(got["y"][order_b], cones["y"][order_a], atol=1e-3)
        assert got["class_id"][order_b].tolist() == cones["class_id"][order_a].tolist()
        assert np.all(got["class_id"] < NUM_CLASSES)
    # boxes came back for each frame too, in full-image pixels
    assert sorted(live.boxes) == sorted(offline.boxes)
    out = tmp_path / "live.mcap"
    write_result_bag(live, out)
    topics = bagio.bag_topics(out)
    assert topics["/cones"][1] == 15 and topics["/cone_boxes"][1] == 15


def test_offline_replay_writes_bag_with_original_stamps(drive, tmp_path) -> None:
    det = Detector.load(default_model_path())
    out = tmp_path / "offline_out"
    res = offline_replay(drive, Pipeline(load_calibration("example_mainhoop"), det), out=out)
    stamps = [bagio.stamp_ns(m.msg.header) for m in bagio.read_messages(out, "/cones")]
    assert stamps == sorted(res.cones) and len(stamps) == 15
    assert {m.msg.header.frame_id for m in bagio.read_messages(out, "/cones")} == {"rear_axle"}
    assert {m.msg.header.frame_id for m in bagio.read_messages(out, "/cone_boxes")} == {"camera"}


def test_shipped_model_finds_and_places_cones(drive, offline) -> None:
    """The accuracy of the shipped model + calibration on a drive it never saw (jitter off)."""
    calib = load_calibration("example_mainhoop")
    truth = read_ground_truth(drive, "/cones_gt")
    rep = LocalisationReport(max_range_m=15.0)
    for stamp, cones in offline.cones.items():
        rep.add_frame(cones, expected_truth(truth[stamp], calib))
    s = rep.summary()
    print(s)
    g = s["groups"]
    assert s["all"]["n_true"] > 50
    assert s["all"]["recall"] >= MIN_RECALL_15M
    assert g["near 0-4 m"]["median_err_m"] <= 0.10 and g["mid 4-7 m"]["median_err_m"] <= 0.10
    assert g["far 7-15 m"]["median_err_m"] <= 0.30


MIN_RECALL_15M = 0.9


def _children_running(name: str) -> list[int]:
    """Pids of this process's children whose command line contains ``name``."""
    import os

    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except (OSError, IndexError, ValueError):
            continue
        if ppid == os.getpid() and name in cmd:
            out.append(int(d.name))
    return out


def test_live_replay_names_a_node_that_died(drive, tmp_path, capsys, monkeypatch) -> None:
    """Issue 20: a node that died left `replay --live` at exit 0 with '3 /cones received, 9 lost'."""
    import os
    import signal

    from cone_perception.cli import main

    real = live_replay

    def killing_progress(frames, total):
        for i, f in enumerate(frames):
            if i == 3:
                for pid in _children_running("bin/pipeline"):
                    os.kill(pid, signal.SIGKILL)
            yield f

    def live_with_a_kill(*a, **k):
        k["progress"] = killing_progress
        return real(*a, **k)

    monkeypatch.setattr("cone_perception.rostools.live_replay.live_replay", live_with_a_kill)
    rc = main(replay_cmd_args(drive))
    err = capsys.readouterr().err
    assert rc == 1 and "node pipeline died during the replay (exit code -9)" in err


def replay_cmd_args(bag) -> list[str]:
    """The ``cone-perception`` command line of a live fused replay of ``bag``."""
    return ["replay", str(bag), "--live", "fused", "--no-progress", "--model", str(default_model_path())]
