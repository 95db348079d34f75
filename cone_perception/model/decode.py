"""Anchors, DFL decoding, and post-processing (confidence filter, class-aware NMS).

Two layouts meet here:

* raw head output: list of (B, 4*reg_max + nc, H_i, W_i) logits (training);
* the common YOLO export layout: (B, 4 + nc, N) with centre-x, centre-y, w, h
  in input pixels, then class probabilities (what :func:`decode_outputs` makes,
  what our TorchScript/ONNX exports hold, what other YOLO tools export).

:func:`postprocess` turns one image of the export layout into boxes; it is
numpy + OpenCV, so every backend shares it, and lives in :mod:`.postprocess`
(importable without torch; re-exported here).
"""

from __future__ import annotations

import torch

from .postprocess import nms_per_class, postprocess  # noqa: F401 (re-exported: their home is postprocess.py)


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
