"""COCO-style detection metrics (mAP@0.5, mAP@0.5:0.95, per class, PR curves) with pycocotools,
and the counts at one operating point (precision / recall / F1, confusion matrix).

Inputs are plain arrays per image, boxes x1 y1 x2 y2 in the same pixel frame
for ground truth and predictions. Evaluation runs in memory (no JSON files),
quietly, and takes well under a second for a few hundred images.

Ground-truth boxes may be marked *ignore* (too small or mostly hidden to be
labelled): they count neither as misses nor make a detection on them false.
They go to pycocotools as ``iscrowd`` regions, so a detection is ignored when
its intersection with such a box covers >= the IoU threshold of its own area;
:func:`operating_point` uses the same rule.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass, field

import numpy as np

from ..classes import CLASS_NAMES
from ..params import DEFAULT_CONF


@dataclass
class ImageDetections:
    """One image: ground truth and predictions (x1 y1 x2 y2 px)."""

    gt_boxes: np.ndarray  # (M, 4) float
    gt_classes: np.ndarray  # (M,) int
    pred_boxes: np.ndarray  # (K, 4) float
    pred_scores: np.ndarray  # (K,) float
    pred_classes: np.ndarray  # (K,) int
    gt_ignore: np.ndarray | None = None  # (M,) bool: ignore regions (not labelled), None = none


#: Recall points of the COCO precision curves (101 points 0, 0.01, ..., 1).
RECALL_POINTS = np.linspace(0.0, 1.0, 101)


@dataclass
class DetectionMetrics:
    map50: float
    map50_95: float
    ap50_per_class: dict[str, float] = field(default_factory=dict)  # only classes present in the ground truth
    ap_per_class: dict[str, float] = field(default_factory=dict)
    num_images: int = 0
    num_gt: int = 0
    #: precision at :data:`RECALL_POINTS`, IoU 0.5, per class present (COCO interpolation)
    pr50_per_class: dict[str, list[float]] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {
            "map50": self.map50, "map50_95": self.map50_95, "ap50_per_class": dict(self.ap50_per_class),
            "ap_per_class": dict(self.ap_per_class), "num_images": self.num_images, "num_gt": self.num_gt,
            "pr50_per_class": {k: list(v) for k, v in self.pr50_per_class.items()},
        }


def coco_map(images: list[ImageDetections], class_names: tuple[str, ...] = CLASS_NAMES, max_dets: int = 300) -> DetectionMetrics:
    """COCO mAP over ``images``; classes without (non-ignored) ground truth are left out of the mean."""
    from pycocotools.coco import COCO  # pip only (not on the car), needed by the tools' mAP alone
    from pycocotools.cocoeval import COCOeval

    gt_anns, dets, imgs = [], [], []
    ann_id = 1
    for i, im in enumerate(images):
        imgs.append({"id": i})
        gb, gc = np.asarray(im.gt_boxes, np.float64).reshape(-1, 4), np.asarray(im.gt_classes).reshape(-1)
        ign = np.zeros(len(gb), bool) if im.gt_ignore is None else np.asarray(im.gt_ignore, bool).reshape(-1)
        for b, c, g in zip(gb, gc, ign):
            w, h = float(b[2] - b[0]), float(b[3] - b[1])
            gt_anns.append({"id": ann_id, "image_id": i, "category_id": int(c), "bbox": [float(b[0]), float(b[1]), w, h],
                            "area": w * h, "iscrowd": int(g)})
            ann_id += 1
        pb = np.asarray(im.pred_boxes, np.float64).reshape(-1, 4)
        for b, s, c in zip(pb, np.asarray(im.pred_scores).reshape(-1), np.asarray(im.pred_classes).reshape(-1)):
            dets.append([i, b[0], b[1], b[2] - b[0], b[3] - b[1], float(s), int(c)])
    present = sorted({a["category_id"] for a in gt_anns if not a["iscrowd"]})
    num_gt = sum(1 for a in gt_anns if not a["iscrowd"])
    if not present:
        return DetectionMetrics(0.0, 0.0, num_images=len(images), num_gt=0)
    if not dets:
        zeros = {class_names[c]: 0.0 for c in present}
        flat = {class_names[c]: [0.0] * len(RECALL_POINTS) for c in present}
        return DetectionMetrics(0.0, 0.0, zeros, dict(zeros), len(images), num_gt, flat)
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
    pr50 = {class_names[c]: np.clip(p[0, :, k], 0.0, None).tolist() for k, c in enumerate(present)}
    return DetectionMetrics(
        map50=float(np.mean(list(ap50.values()))), map50_95=float(np.mean(list(apall.values()))),
        ap50_per_class=ap50, ap_per_class=apall, num_images=len(images), num_gt=num_gt, pr50_per_class=pr50,
    )


# ------------------------------------------------------------------ one operating point


@dataclass
class OperatingPoint:
    """Counts at one confidence and IoU threshold.

    ``tp``/``fp``/``fn`` per class name come from class-aware matching (a detection is right only
    with the right class). ``confusion`` comes from class-agnostic matching: ``(C + 1, C + 1)`` int,
    rows = true class, columns = predicted class, last row / column = background (a detection on
    no cone / a cone with no detection).
    """

    conf: float
    iou: float
    class_names: tuple[str, ...]
    tp: dict[str, int]
    fp: dict[str, int]
    fn: dict[str, int]
    confusion: np.ndarray

    def scores(self) -> dict[str, dict[str, float]]:
        """Per class and ``all`` (summed counts): precision, recall, F1 and the counts."""
        rows = {n: (self.tp[n], self.fp[n], self.fn[n]) for n in self.class_names}
        rows["all"] = tuple(sum(r[i] for r in rows.values()) for i in range(3))
        return {n: _prf(*r) for n, r in rows.items()}

    def to_dict(self) -> dict:
        return {"conf": self.conf, "iou": self.iou, "per_class": self.scores(),
                "confusion": {"labels": list(self.class_names) + ["background"], "rows_true_cols_pred": self.confusion.tolist()}}


def _prf(tp: int, fp: int, fn: int) -> dict:
    p = tp / (tp + fp) if tp + fp else float("nan")
    r = tp / (tp + fn) if tp + fn else float("nan")
    f1 = 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else float("nan")  # = 2PR / (P + R)
    return {"tp": int(tp), "fp": int(fp), "fn": int(fn), "precision": p, "recall": r, "f1": f1}


def box_iou(a: np.ndarray, b: np.ndarray, b_ignore: np.ndarray | None = None) -> np.ndarray:
    """(K, M) IoU of x1 y1 x2 y2 boxes, as COCO computes it; against an ignore box (``b_ignore``) the
    overlap is divided by the first box's own area instead."""
    from pycocotools import mask as mask_utils  # pip only, as above

    a, b = np.asarray(a, np.float64).reshape(-1, 4), np.asarray(b, np.float64).reshape(-1, 4)
    if len(a) == 0 or len(b) == 0:
        return np.zeros((len(a), len(b)))
    crowd = np.zeros(len(b), np.uint8) if b_ignore is None else np.asarray(b_ignore, bool).reshape(-1).astype(np.uint8)
    xywh = lambda x: np.c_[x[:, :2], x[:, 2:] - x[:, :2]]  # noqa: E731
    return np.asarray(mask_utils.iou(xywh(a), xywh(b), crowd.tolist())).reshape(len(a), len(b))


def greedy_match(pred_boxes: np.ndarray, gt_boxes: np.ndarray, gt_ignore: np.ndarray, iou: float) -> tuple[np.ndarray, np.ndarray]:
    """COCO's matching at one IoU threshold, predictions given best score first.

    Each prediction takes the unmatched, non-ignored ground-truth box of highest IoU >= ``iou``;
    failing that it is *ignored* if it lies on an ignore box (intersection / own area >= ``iou``).
    Boxes x1 y1 x2 y2 px: ``pred_boxes`` (K, 4), ``gt_boxes`` (M, 4), ``gt_ignore`` (M,) bool.
    Returns ((K,) int ground-truth index or -1, (K,) bool ignored).
    """
    pb, gb = np.asarray(pred_boxes, np.float64).reshape(-1, 4), np.asarray(gt_boxes, np.float64).reshape(-1, 4)
    ign = np.asarray(gt_ignore, bool).reshape(-1)
    to_gt, ignored = np.full(len(pb), -1, np.int64), np.zeros(len(pb), bool)
    if len(pb) == 0 or len(gb) == 0:
        return to_gt, ignored
    ious = box_iou(pb, gb, ign)
    used = ign.copy()
    for k in range(len(pb)):
        cand = np.where(used, -1.0, ious[k])
        j = int(np.argmax(cand))
        if cand[j] >= iou:
            to_gt[k], used[j] = j, True
        elif np.any(ious[k, ign] >= iou):
            ignored[k] = True
    return to_gt, ignored


def match_by_class(pred_boxes: np.ndarray, pred_classes: np.ndarray, gt_boxes: np.ndarray, gt_classes: np.ndarray,
                   gt_ignore: np.ndarray, iou: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`greedy_match` within each class (predictions best score first): a prediction matches only a
    box of its own class. Returns ((K,) ground-truth index into ``gt_boxes`` or -1, (K,) bool ignored)."""
    pb, gb = np.asarray(pred_boxes, np.float64).reshape(-1, 4), np.asarray(gt_boxes, np.float64).reshape(-1, 4)
    pc, gc = np.asarray(pred_classes, np.int64).reshape(-1), np.asarray(gt_classes, np.int64).reshape(-1)
    gi = np.asarray(gt_ignore, bool).reshape(-1)
    to_gt, ignored = np.full(len(pb), -1, np.int64), np.zeros(len(pb), bool)
    for c in np.unique(pc):
        mp, mg = np.flatnonzero(pc == c), np.flatnonzero(gc == c)
        t, ig = greedy_match(pb[mp], gb[mg], gi[mg], iou)
        to_gt[mp] = np.where(t >= 0, mg[np.maximum(t, 0)] if len(mg) else -1, -1)
        ignored[mp] = ig
    return to_gt, ignored


def at_conf(scores: np.ndarray, conf: float) -> np.ndarray:
    """Indices of the detections with score >= ``conf``, best score first (the order matching needs)."""
    ps = np.asarray(scores, np.float64).reshape(-1)
    keep = np.flatnonzero(ps >= conf)
    return keep[np.argsort(-ps[keep], kind="stable")]


def operating_point(images: list[ImageDetections], conf: float = DEFAULT_CONF, iou: float = 0.5,
                    class_names: tuple[str, ...] = CLASS_NAMES) -> OperatingPoint:
    """Precision / recall / F1 counts and the confusion matrix of detections with score >= ``conf``."""
    C = len(class_names)
    tp, fp, fn = np.zeros(C, np.int64), np.zeros(C, np.int64), np.zeros(C, np.int64)
    cm = np.zeros((C + 1, C + 1), np.int64)
    for im in images:
        gb, gc = np.asarray(im.gt_boxes, np.float64).reshape(-1, 4), np.asarray(im.gt_classes, np.int64).reshape(-1)
        gi = np.zeros(len(gb), bool) if im.gt_ignore is None else np.asarray(im.gt_ignore, bool).reshape(-1)
        keep = at_conf(im.pred_scores, conf)
        pb, pc = np.asarray(im.pred_boxes, np.float64).reshape(-1, 4)[keep], np.asarray(im.pred_classes, np.int64).reshape(-1)[keep]
        to_gt_c, ignored_c = match_by_class(pb, pc, gb, gc, gi, iou)  # class-aware: precision / recall / F1
        hit_c = np.zeros(len(gb), bool)
        hit_c[to_gt_c[to_gt_c >= 0]] = True
        for c in range(C):
            tp[c] += int((hit_c & (gc == c)).sum())
            fp[c] += int(((to_gt_c < 0) & ~ignored_c & (pc == c)).sum())
            fn[c] += int((~hit_c & ~gi & (gc == c)).sum())
        to_gt, ignored = greedy_match(pb, gb, gi, iou)  # class-agnostic: confusion matrix
        for k, j in enumerate(to_gt):
            if j >= 0:
                cm[gc[j], pc[k]] += 1
            elif not ignored[k]:
                cm[C, pc[k]] += 1
        hit = np.zeros(len(gb), bool)
        hit[to_gt[to_gt >= 0]] = True
        for j in np.flatnonzero(~hit & ~gi):
            cm[gc[j], C] += 1
    names = tuple(class_names)
    return OperatingPoint(float(conf), float(iou), names, dict(zip(names, tp.tolist())), dict(zip(names, fp.tolist())),
                          dict(zip(names, fn.tolist())), cm)
