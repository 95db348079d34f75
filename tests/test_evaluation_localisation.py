"""Localisation evaluation: greedy gated matching, recall and errors per distance group."""

from __future__ import annotations

import numpy as np

from cone_perception.evaluation import DISTANCE_GROUPS, LocalisationReport, distance_group, format_localisation, match_cones
from cone_perception.records import CONE_DTYPE


def _cones(xy, cls=None) -> np.ndarray:
    xy = np.asarray(xy, float).reshape(-1, 2)
    c = np.zeros(len(xy), CONE_DTYPE)
    c["x"], c["y"] = xy[:, 0], xy[:, 1]
    c["class_id"] = 0 if cls is None else cls
    return c


def test_distance_groups_edges() -> None:
    assert distance_group(np.array([0.0, 3.99, 4.0, 6.9, 7.0, 14.9, 15.0, 40.0])).tolist() == [0, 0, 1, 1, 2, 2, 3, 3]
    assert len(DISTANCE_GROUPS) == 4


def test_matching_is_nearest_first_one_to_one_and_gated() -> None:
    truth = np.array([[5.0, 1.0], [5.0, -1.0], [20.0, 0.0]])
    pred = np.array([[5.1, 0.9], [5.05, 0.95], [5.0, -3.0], [21.5, 0.4]])
    pairs = match_cones(pred, truth)
    d = {(i, j) for i, j, _ in pairs}
    assert (1, 0) in d  # the nearer of two candidates wins
    assert (0, 0) not in d and all(j != 0 or i == 1 for i, j, _ in pairs)
    assert not any(i == 2 for i, _, _ in pairs)  # 2 m off at 5 m: outside the 1.0 m gate
    assert (3, 2) in d  # 1.55 m off at 20 m: inside the 2.5 m gate


def test_report_recall_errors_and_false_positives() -> None:
    rep = LocalisationReport()
    truth = _cones([[3.0, 1.5], [6.0, -1.5], [10.0, 2.0], [18.0, -2.0]], [0, 1, 0, 1])
    pred = _cones([[3.1, 1.5], [10.0, 2.4], [30.0, 0.0]], [0, 1, 0])
    rep.add_frame(pred, truth)
    s = rep.summary()
    g = s["groups"]
    assert g["near 0-4 m"]["recall"] == 1.0 and np.isclose(g["near 0-4 m"]["median_err_m"], 0.1)
    assert g["mid 4-7 m"]["recall"] == 0.0 and g["mid 4-7 m"]["n_matched"] == 0
    assert g["far 7-15 m"]["recall"] == 1.0 and np.isclose(g["far 7-15 m"]["median_err_m"], 0.4)
    assert g["far 7-15 m"]["class_accuracy"] == 0.0  # predicted yellow where a blue stands
    assert g["very far >15 m"]["recall"] == 0.0
    assert s["all"]["recall"] == 0.5 and s["false_positives"] == 1 and s["frames"] == 1


def test_detections_beyond_the_range_are_not_false_positives() -> None:
    """With ``max_range_m`` the true cones beyond it are ignored; so are the detections there."""
    rep = LocalisationReport(max_range_m=15.0)
    truth = _cones([[5.0, 1.5], [20.0, -2.0]], [0, 1])
    pred = _cones([[5.1, 1.5], [20.2, -2.0], [12.0, 0.0], [25.0, 3.0]], [0, 1, 0, 1])
    rep.add_frame(pred, truth)
    s = rep.summary()
    assert s["all"]["n_true"] == 1 and s["all"]["recall"] == 1.0
    assert s["false_positives"] == 1  # the one at 12 m; those at 20 and 25 m are beyond the range


def test_the_15_25_m_band_beside_the_groups() -> None:
    """The issue's 15-25 m target: a band reported beside the groups, leaving out what the >15 m group
    holds beyond 25 m."""
    rep = LocalisationReport()
    truth = _cones([[16.0, 1.0], [24.0, -1.0], [28.0, 0.0], [10.0, 0.0]])
    pred = _cones([[16.3, 1.0], [24.5, -1.0], [29.5, 0.0], [10.1, 0.0]])
    rep.add_frame(pred, truth)
    s = rep.summary()
    band, far = s["extra_groups"]["15-25 m"], s["groups"]["very far >15 m"]
    assert band["n_true"] == 2 and band["n_matched"] == 2 and np.isclose(band["median_err_m"], 0.4)
    assert far["n_matched"] == 3 and np.isclose(far["median_err_m"], 0.5)


def test_range_bands_to_40_m_count_half_visible_cones_and_false_cones_by_range():
    """Issue 26's look-ahead bands: out to 40 m whatever the calibration's range (a cone beyond it is a
    miss in its band), only cones at least ``min_visible`` count for recall (a detection on a less
    visible one is no false cone), false cones by the detection's own range."""
    rep = LocalisationReport(max_range_m=30.0, min_visible=0.5)
    truth = _cones([[10.0, 0.0], [20.0, 1.0], [28.0, 0.0], [35.0, 2.0], [38.0, -2.0]])
    truth["score"] = [1.0, 1.0, 0.3, 1.0, 0.8]
    pred = _cones([[10.1, 0.0], [20.3, 1.0], [28.2, 0.0], [32.0, 12.0], [3.0, 1.0]])
    rep.add_frame(pred, truth)
    rep.add_frame(pred[:0], truth[:0])
    s = rep.summary()
    b = s["extra_groups"]
    assert list(b) == ["0-7 m", "7-15 m", "15-25 m", "25-40 m"]
    assert (b["25-40 m"]["n_true"], b["25-40 m"]["recall"]) == (2, 0.0)  # the 28 m cone is 30 % visible
    assert b["25-40 m"]["false_cones"] == 1 and b["25-40 m"]["false_per_frame"] == 0.5  # the one at 34 m
    assert b["0-7 m"]["false_cones"] == 1 and b["7-15 m"]["recall"] == 1.0
    assert s["bands"]["false_cones"] == 2 and s["bands"]["false_per_frame"] == 1.0
    far = s["groups"]["very far >15 m"]  # the groups keep the 30 m cut and every visible cone
    assert far["n_true"] == 2 and far["recall"] == 1.0
    assert s["false_positives"] == 1  # within 30 m: the one at 3.2 m
    assert "25-40 m" in format_localisation(s)
