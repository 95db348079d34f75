"""eval as people use it: a warning for cut predictions, bag frames in worst_frames.jpg without OpenCV
noise, the range cut named in every table."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from test_evaluation_report import CONES, box_rows, scene_boxes, write_gt_jsonl, write_pred

from cone_perception.cli import main
from cone_perception.geometry.calib import load_calibration


@pytest.fixture(scope="module")
def frames():
    calib = load_calibration("example_mainhoop")
    boxes = scene_boxes(calib)
    return boxes, np.array([c for c, _, _ in CONES])


def test_cut_predictions_warn_what_map_then_means(tmp_path, frames, capsys):
    boxes, cls = frames
    gt = write_gt_jsonl(tmp_path / "gt.jsonl", {"a.jpg": (boxes, cls)})
    scores = np.linspace(0.3, 0.9, len(cls))
    cut = write_pred(tmp_path / "cut.jsonl", {"a.jpg": box_rows(boxes[:-3], cls[:-3], scores[:-3])})
    assert main(["eval", "--pred", str(cut), "--gt", str(gt), "--out", str(tmp_path / "r1"), "--no-progress",
                 "--calib", "example_mainhoop"]) == 0
    cap = capsys.readouterr()
    assert "warning: the predictions' lowest score is 0.300 (> 0.01)" in cap.err and "--conf 0.001" in cap.err
    report = (tmp_path / "r1" / "report.md").read_text()
    assert "lowest score is 0.300" in report
    assert json.loads((tmp_path / "r1" / "metrics.json").read_text())["inputs"]["min_score"] == pytest.approx(0.3)
    # the range cut is named in every table: none for the image tables, max_range_m for the metres ones
    assert report.count("Range cut: none (scored in the image") == 3  # detection, box height, distance groups
    r = load_calibration("example_mainhoop").max_range_m
    assert report.count(f"Range cut: max_range_m = {r:g} m") == 2  # localisation, pair distance
    assert "(no range cut)" in cap.out and f"(within max_range_m {r:g} m)" in cap.out
    # full-curve predictions: no warning
    full = write_pred(tmp_path / "full.jsonl", {"a.jpg": box_rows(boxes, cls, np.r_[scores[:-1], 0.001])})
    assert main(["eval", "--pred", str(full), "--gt", str(gt), "--out", str(tmp_path / "r2"), "--no-progress"]) == 0
    assert "lowest score" not in capsys.readouterr().err


def test_bag_frames_get_worst_frames_without_opencv_noise(tmp_path, capfd):
    bag = tmp_path / "drive"
    assert main(["synth", "bag", "--seconds", "0.3", "--fps", "10", "--out", str(bag), "--seed", "1",
                 "--size", "320x180", "--no-progress"]) == 0
    gt = tmp_path / "drive_gt.jsonl"
    lines = [json.loads(l) for l in gt.read_text().splitlines()]
    # predictions named as `detect BAG` names them (stamp ns); none found: every cone missed
    pred = write_pred(tmp_path / "p.jsonl", {str(d["stamp_ns"]): [] for d in lines}, size=(320, 180))
    capfd.readouterr()
    assert main(["eval", "--pred", str(pred), "--gt", str(gt), "--out", str(tmp_path / "r"), "--no-progress",
                 "--worst", "2"]) == 0
    cap = capfd.readouterr()
    assert "imread" not in cap.err and "can't open" not in cap.err, cap.err
    img = cv2.imread(str(tmp_path / "r" / "worst_frames.jpg"))
    assert img is not None and img.shape[1] == 2 * 960
    # the tile is the bag's frame (a synthetic scene: not a flat colour)
    assert img[:, :960].std() > 10
    report = (tmp_path / "r" / "report.md").read_text()
    assert "worst_frames.jpg" in report and any(str(d["stamp_ns"]) in report for d in lines)
