"""COCO mAP wrapper: perfect, wrong class, missing, and empty predictions."""

from __future__ import annotations

import numpy as np
import pytest

from cone_perception.evaluation.metrics import ImageDetections, coco_map

GT = np.array([[10, 10, 30, 50], [100, 20, 120, 60], [200, 20, 215, 50]], float)
GT_CLS = np.array([0, 1, 1])


def test_perfect_predictions_score_one():
    m = coco_map([ImageDetections(GT, GT_CLS, GT.copy(), np.array([0.9, 0.8, 0.7]), GT_CLS)])
    assert m.map50 == pytest.approx(1.0) and m.map50_95 == pytest.approx(1.0)
    assert set(m.ap50_per_class) == {"blue", "yellow"} and m.num_gt == 3


def test_wrong_class_and_missing_box_lower_the_map():
    wrong = coco_map([ImageDetections(GT, GT_CLS, GT.copy(), np.array([0.9, 0.8, 0.7]), np.array([0, 0, 1]))])
    assert wrong.ap50_per_class["blue"] < 1.0 and wrong.ap50_per_class["yellow"] == pytest.approx(0.5, abs=0.02)
    shifted = GT.copy()
    shifted[:, [0, 2]] += 4  # IoU 0.58-0.67: counts at 0.5, not at 0.7+
    m = coco_map([ImageDetections(GT, GT_CLS, shifted, np.array([0.9, 0.8, 0.7]), GT_CLS)])
    assert m.map50 == pytest.approx(1.0) and m.map50_95 < 0.5


def test_no_predictions_and_no_ground_truth():
    m = coco_map([ImageDetections(GT, GT_CLS, np.zeros((0, 4)), np.zeros(0), np.zeros(0, int))])
    assert m.map50 == 0.0 and m.ap50_per_class == {"blue": 0.0, "yellow": 0.0}
    m = coco_map([ImageDetections(np.zeros((0, 4)), np.zeros(0, int), GT, np.ones(3), GT_CLS)])
    assert m.num_gt == 0 and m.map50 == 0.0
