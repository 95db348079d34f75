"""Anchors, DFL decoding, and post-processing (confidence filter, class-aware NMS).

Two layouts meet here:

* raw head output: list of (B, 4*reg_max + nc, H_i, W_i) logits (training);
* the common YOLO export layout: (B, 4 + nc, N) with centre-x, centre-y, w, h
  in input pixels, then class probabilities (what :func:`decode_outputs` makes,
  what our TorchScript/ONNX exports hold, what other YOLO tools export).

:func:`postprocess` turns one image of the export layout into boxes; it is
numpy + OpenCV, so every backend shares it.
"""

from __future__ import annotations

import cv2
import numpy as np
import torch


def make_anchors(
    feats: list[torch.Tensor], strides: tuple[int, ...], offset: float = 0.5
) -> tuple[torch.Tensor, torch.Tensor]:
    """Cell centres (N, 2) in stride units (x, y) and each cell's stride (N, 1)."""
    points, stride_t = [], []
    for f, s in zip(feats, strides):
        h, w = f.shape[2], f.shape[3]
        sx = torch.arange(w, device=f.device, dtype=f.dtype) + offset
        sy = torch.arange(h, device=f.device, dtype=f.dtype) + offset
        yy, xx = torch.meshgrid(sy, sx, indexing="ij")
        points.append(torch.stack((xx, yy), -1).view(-1, 2))
        stride_t.append(torch.full((h * w, 1), float(s), dtype=f.dtype, device=f.device))
    return torch.cat(points), torch.cat(stride_t)


def dfl_expectation(box_logits: torch.Tensor, reg_max: int) -> torch.Tensor:
    """(B, 4*reg_max, N) logits -> (B, 4, N) expected distances (left, top, right, bottom), stride units."""
    b, _, n = box_logits.shape
    prob = box_logits.view(b, 4, reg_max, n).softmax(2)
    bins = torch.arange(reg_max, dtype=prob.dtype, device=prob.device).view(1, 1, reg_max, 1)
    return (prob * bins).sum(2)


def dist2bbox(ltrb: torch.Tensor, anchors: torch.Tensor, xywh: bool, dim: int = -1) -> torch.Tensor:
    """Distances to the sides + anchor points -> boxes (xyxy, or cx cy w h when ``xywh``)."""
    lt, rb = ltrb.chunk(2, dim)
    x1y1 = anchors - lt
    x2y2 = anchors + rb
    if xywh:
        return torch.cat(((x1y1 + x2y2) / 2, x2y2 - x1y1), dim)
    return torch.cat((x1y1, x2y2), dim)


def bbox2dist(anchors: torch.Tensor, xyxy: torch.Tensor, reg_max: int) -> torch.Tensor:
    """Boxes (..., 4) xyxy + anchors (..., 2) -> distances (l, t, r, b) clamped to [0, reg_max - 1.01]."""
    x1y1, x2y2 = xyxy.chunk(2, -1)
    return torch.cat((anchors - x1y1, x2y2 - anchors), -1).clamp_(0, reg_max - 1 - 0.01)


def decode_outputs(feats: list[torch.Tensor], strides: tuple[int, ...], reg_max: int, nc: int) -> torch.Tensor:
    """Raw head output -> (B, 4 + nc, N): cx, cy, w, h in input px, then sigmoid class scores."""
    b = feats[0].shape[0]
    x = torch.cat([f.view(b, 4 * reg_max + nc, -1) for f in feats], 2)
    box_logits, cls_logits = x.split((4 * reg_max, nc), 1)
    anchors, stride_t = make_anchors(feats, strides)
    ltrb = dfl_expectation(box_logits, reg_max)
    boxes = dist2bbox(ltrb, anchors.transpose(0, 1).unsqueeze(0), xywh=True, dim=1) * stride_t.transpose(0, 1)
    return torch.cat((boxes, cls_logits.sigmoid()), 1)


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
