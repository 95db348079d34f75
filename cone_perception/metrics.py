"""COCO-style detection metrics (mAP@0.5, mAP@0.5:0.95, per class) with pycocotools.

Inputs are plain arrays per image, boxes x1 y1 x2 y2 in the same pixel frame
for ground truth and predictions. Evaluation runs in memory (no JSON files),
quietly, and takes well under a second for a few hundred images.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass, field

import numpy as np

from .classes import CLASS_NAMES


@dataclass
class ImageDetections:
    """One image: ground truth and predictions (x1 y1 x2 y2 px)."""

    gt_boxes: np.ndarray  # (M, 4) float
    gt_classes: np.ndarray  # (M,) int
    pred_boxes: np.ndarray  # (K, 4) float
    pred_scores: np.ndarray  # (K,) float
    pred_classes: np.ndarray  # (K,) int


@dataclass
class DetectionMetrics:
    map50: float
    map50_95: float
    ap50_per_class: dict[str, float] = field(default_factory=dict)  # only classes present in the ground truth
    ap_per_class: dict[str, float] = field(default_factory=dict)
    num_images: int = 0
    num_gt: int = 0

    def to_dict(self) -> dict:
        return {
            "map50": self.map50, "map50_95": self.map50_95, "ap50_per_class": dict(self.ap50_per_class),
            "ap_per_class": dict(self.ap_per_class), "num_images": self.num_images, "num_gt": self.num_gt,
        }


def coco_map(images: list[ImageDetections], class_names: tuple[str, ...] = CLASS_NAMES, max_dets: int = 300) -> DetectionMetrics:
    """COCO mAP over ``images``; classes without ground truth are left out of the mean."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    gt_anns, dets, imgs = [], [], []
    ann_id = 1
    for i, im in enumerate(images):
        imgs.append({"id": i})
        for b, c in zip(np.asarray(im.gt_boxes, np.float64).reshape(-1, 4), np.asarray(im.gt_classes).reshape(-1)):
            w, h = float(b[2] - b[0]), float(b[3] - b[1])
            gt_anns.append({"id": ann_id, "image_id": i, "category_id": int(c), "bbox": [float(b[0]), float(b[1]), w, h],
                            "area": w * h, "iscrowd": 0})
            ann_id += 1
        pb = np.asarray(im.pred_boxes, np.float64).reshape(-1, 4)
        for b, s, c in zip(pb, np.asarray(im.pred_scores).reshape(-1), np.asarray(im.pred_classes).reshape(-1)):
            dets.append([i, b[0], b[1], b[2] - b[0], b[3] - b[1], float(s), int(c)])
    present = sorted({a["category_id"] for a in gt_anns})
    if not gt_anns:
        return DetectionMetrics(0.0, 0.0, num_images=len(images), num_gt=0)
    if not dets:
        zeros = {class_names[c]: 0.0 for c in present}
        return DetectionMetrics(0.0, 0.0, zeros, dict(zeros), len(images), len(gt_anns))
    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO()
        gt.dataset = {"images": imgs, "annotations": gt_anns,
                      "categories": [{"id": c, "name": n} for c, n in enumerate(class_names)]}
        gt.createIndex()
        dt = gt.loadRes(np.asarray(dets, dtype=np.float64))
        ev = COCOeval(gt, dt, "bbox")
        ev.params.catIds = present
        ev.params.maxDets = [1, 10, max_dets]
        ev.evaluate()
        ev.accumulate()
    prec = ev.eval["precision"]  # (T iou thresholds, R recall, K classes, A areas, M maxDets)
    p = prec[:, :, :, 0, -1]

    def ap(x: np.ndarray) -> float:
        x = x[x > -1]
        return float(x.mean()) if x.size else 0.0

    ap50 = {class_names[c]: ap(p[0, :, k]) for k, c in enumerate(present)}
    apall = {class_names[c]: ap(p[:, :, k]) for k, c in enumerate(present)}
    return DetectionMetrics(
        map50=float(np.mean(list(ap50.values()))), map50_95=float(np.mean(list(apall.values()))),
        ap50_per_class=ap50, ap_per_class=apall, num_images=len(images), num_gt=len(gt_anns),
    )
