"""Post-processing of one image of the common YOLO export layout: confidence filter and class-aware NMS.

``(4 + nc, N)``: centre-x, centre-y, w, h in input pixels, then class scores (:mod:`.decode`). Numpy + OpenCV
only, so every backend shares it and it imports without torch (the ONNX Runtime path of the nodes).
"""

from __future__ import annotations

import cv2
import numpy as np


def nms_per_class(
    xywh: np.ndarray, scores: np.ndarray, cls: np.ndarray, conf: float, iou: float
) -> np.ndarray:
    """Class-aware NMS: indices of the boxes kept, (K,) int64, in OpenCV's order (best score first).

    ``xywh``: (N, 4) float, top-left x, y, width, height in px; ``scores``: (N,) float;
    ``cls``: (N,) int class ids. Boxes of different classes never suppress each other.

    The same boxes as ``cv2.dnn.NMSBoxesBatched`` (OpenCV >= 4.7), built as that function is:
    each class's boxes shifted by ``class_id * (max_coord + 1)`` (in float64) so that classes
    cannot overlap, then one ``cv2.dnn.NMSBoxes`` (OpenCV 3.4+: the car's apt OpenCV 4.5/4.6).
    """
    xywh = np.asarray(xywh, dtype=np.float64).reshape(-1, 4)
    if xywh.shape[0] == 0:
        return np.zeros(0, np.int64)
    x2y2 = xywh[:, :2] + xywh[:, 2:]
    max_coord = max(0.0, float(xywh[:, :2].max()), float(x2y2.max()))
    shifted = xywh.copy()
    shifted[:, :2] += (np.asarray(cls, dtype=np.float64).reshape(-1) * (max_coord + 1.0))[:, None]
    idx = cv2.dnn.NMSBoxes(shifted.tolist(), np.asarray(scores).reshape(-1).tolist(), conf, iou)  # no top_k: it
    return np.asarray(idx, dtype=np.int64).reshape(-1)  # would cut before NMS


def postprocess(
    pred: np.ndarray,
    conf: float = 0.25,
    iou: float = 0.45,
    max_det: int = 300,
    max_candidates: int = 3000,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One image of the export layout -> detections after class-aware NMS.

    ``pred``: (4 + nc, N) float, cx cy w h in input px, then class scores in 0..1.
    Returns ((K, 4) float32 boxes x1 y1 x2 y2 in input px, (K,) float32 scores,
    (K,) int64 class ids), best first, K <= ``max_det``. Each cell gives one box,
    for its best class. NMS is :func:`nms_per_class` (boxes of different classes
    never suppress each other).
    """
    pred = np.asarray(pred, dtype=np.float32)
    if pred.ndim != 2 or pred.shape[0] < 5:
        raise ValueError(f"expected (4 + nc, N) predictions, got shape {pred.shape}")
    scores_all = pred[4:]
    cls = scores_all.argmax(0)
    scores = scores_all[cls, np.arange(pred.shape[1])]
    keep = np.flatnonzero(scores > conf)
    empty = (np.zeros((0, 4), np.float32), np.zeros(0, np.float32), np.zeros(0, np.int64))
    if keep.size == 0:
        return empty
    if keep.size > max_candidates:
        keep = keep[np.argpartition(-scores[keep], max_candidates)[:max_candidates]]
    cxcywh = pred[:4, keep].T
    scores, cls = scores[keep], cls[keep].astype(np.int64)
    xywh = cxcywh.copy()
    xywh[:, :2] -= cxcywh[:, 2:] / 2  # top-left corner + size, as OpenCV wants
    idx = nms_per_class(xywh, scores, cls, conf, iou)
    if idx.size == 0:
        return empty
    idx = idx[np.argsort(-scores[idx], kind="stable")][:max_det]
    boxes = np.concatenate([xywh[idx, :2], xywh[idx, :2] + xywh[idx, 2:]], 1).astype(np.float32)
    return boxes, scores[idx].astype(np.float32), cls[idx]
