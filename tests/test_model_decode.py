"""Class-aware NMS without ``cv2.dnn.NMSBoxesBatched`` (OpenCV 4.7+): the car's OpenCV 4.5/4.6.

numpy + OpenCV only, so it also runs in the car's environment (``make test``'s ``.venv-car``).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cone_perception.model.decode import nms_per_class, postprocess


def reference_nms(xywh: np.ndarray, scores: np.ndarray, cls: np.ndarray, conf: float, iou: float) -> list[int]:
    """Plain greedy NMS per class, best score first (what NMSBoxesBatched promises), in float64."""
    x1, y1 = xywh[:, 0].astype(np.float64), xywh[:, 1].astype(np.float64)
    x2, y2 = x1 + xywh[:, 2], y1 + xywh[:, 3]
    area = (x2 - x1) * (y2 - y1)
    order = [i for i in np.argsort(-scores, kind="stable") if scores[i] > conf]
    kept: list[int] = []
    for i in order:
        ok = True
        for k in kept:
            if cls[k] != cls[i]:
                continue
            iw = max(0.0, min(x2[i], x2[k]) - max(x1[i], x1[k]))
            ih = max(0.0, min(y2[i], y2[k]) - max(y1[i], y1[k]))
            inter = iw * ih
            if inter / (area[i] + area[k] - inter) > iou:
                ok = False
                break
        if ok:
            kept.append(int(i))
    return kept


def random_boxes(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clustered boxes (so that many overlap), some with negative corners, 5 classes."""
    centres = rng.uniform(-20, 980, size=(max(1, n // 20), 2))
    c = centres[rng.integers(0, len(centres), n)] + rng.normal(0, 4, size=(n, 2))
    wh = rng.uniform(20, 60, size=(n, 1)) * rng.uniform(0.7, 1.3, size=(n, 2))
    xywh = np.concatenate([c - wh / 2, wh], 1).astype(np.float32)
    return xywh, rng.uniform(0, 1, n).astype(np.float32), rng.integers(0, 5, n)


def test_nms_per_class_matches_reference_on_many_random_sets():
    rng = np.random.default_rng(17)
    batched = getattr(cv2.dnn, "NMSBoxesBatched", None)  # OpenCV >= 4.7 only
    total_in = total_kept = 0
    for trial in range(300):
        n = int(rng.integers(1, 400))
        xywh, scores, cls = random_boxes(rng, n)
        conf, iou = float(rng.uniform(0.05, 0.5)), float(rng.uniform(0.2, 0.8))
        got = nms_per_class(xywh, scores, cls, conf, iou)
        assert got.dtype == np.int64
        assert got.tolist() == reference_nms(xywh, scores, cls, conf, iou), f"trial {trial}"
        if batched is not None:
            want = np.asarray(batched(xywh.tolist(), scores.tolist(), cls.tolist(), conf, iou)).reshape(-1)
            assert got.tolist() == want.tolist(), f"trial {trial}: differs from cv2.dnn.NMSBoxesBatched"
        total_in += int((scores > conf).sum())
        total_kept += len(got)
    assert total_kept < 0.8 * total_in  # the sets really overlap: NMS had work to do


def test_nms_classes_never_suppress_each_other():
    xywh = np.array([[10, 10, 40, 80]] * 5, np.float32)  # one box, five times
    scores = np.array([0.9, 0.8, 0.7, 0.6, 0.5], np.float32)
    assert nms_per_class(xywh, scores, np.arange(5), 0.1, 0.5).tolist() == [0, 1, 2, 3, 4]
    assert nms_per_class(xywh, scores, np.zeros(5, int), 0.1, 0.5).tolist() == [0]
    assert nms_per_class(np.zeros((0, 4), np.float32), np.zeros(0), np.zeros(0, int), 0.1, 0.5).shape == (0,)


def test_postprocess_uses_no_opencv_4_7_api(monkeypatch):
    """With NMSBoxesBatched gone (as in OpenCV 4.5/4.6), postprocess still gives the boxes."""
    monkeypatch.delattr(cv2.dnn, "NMSBoxesBatched", raising=False)
    pred = np.zeros((9, 3), np.float32)
    pred[:4] = np.array([[30, 31, 130], [50, 50, 50], [40, 40, 40], [80, 80, 80]], np.float32)
    pred[4, 0], pred[4, 1], pred[5, 2] = 0.9, 0.8, 0.7
    boxes, scores, cls = postprocess(pred, conf=0.25, iou=0.45)
    assert cls.tolist() == [0, 1]
    np.testing.assert_allclose(boxes, [[10, 10, 50, 90], [110, 10, 150, 90]])
    np.testing.assert_allclose(scores, [0.9, 0.7])


