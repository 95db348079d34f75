"""Would the flat-box gate (mapping's ``min_height_ratio``) drop true cones on the real validation clips?

    .venv/bin/python docs/experiments/flat_boxes_real.py PRED.jsonl [--gt data/real_val_1080] [--ratios 0.7,0.8,0.85]

PRED.jsonl: `cone-perception detect data/real_val_1080 --crop 96,672 --downscale 2 --conf 0.25 --out PRED.jsonl` (the
car's band, models/cone_detector.md "Metrics"). The clips have no calibration, so the gate cannot run on them as it
does on the car; this measures what it would see with a calibration-free stand-in of the same geometry. On flat
ground a cone whose foot stands ``dv`` px below the horizon row is ``dv x cone height / camera height`` px tall
(a pinhole, small pitch; the horizon a line across the image for the roll): per frame the horizon and the camera
height are fitted (least squares, then the
labels more than 15 % off dropped and refitted) to the LABELLED cones of the frame (at least 4, each class by its own
height, classes.CONE_SIZE_M), and each detection matched to a label (its class, IoU >= 0.5) gets the gate's ratio:
its box height over the fitted height of a cone at its foot row. Printed: the ratios of the true detections (their
quantiles) and how many of them each gate would drop; the same for the detections on no label (mostly unlabelled
far cones and cones of another class, not marks on the ground: these clips show none), and the labels' own ratios
(how well the stand-in fits: the labels are a few percent loose or tight); and each true detection's height over its
label's: the part of the ratio the detector adds where the range is known exactly.
"""
from __future__ import annotations

import argparse

import numpy as np

from cone_perception.classes import CONE_SIZE_M
from cone_perception.data.predictions import read_predictions
from cone_perception.evaluation.groundtruth import load_ground_truth, pair_with_predictions
from cone_perception.evaluation.metrics import match_by_class

MIN_LABELS = 4


def _design(boxes: np.ndarray) -> np.ndarray:
    return np.c_[boxes[:, 3], 0.5 * (boxes[:, 0] + boxes[:, 2]), np.ones(len(boxes))]


def fit_frame(boxes: np.ndarray, cls: np.ndarray) -> np.ndarray | None:
    """(a, c, b) fitted to labelled boxes: h / H_cls = k (v_foot - v_h(u)) = a v_foot + c u + b, the horizon a line
    (pitch and roll); None with too few labels (or a horizon below them)."""
    hc = np.array([CONE_SIZE_M.get(int(c), (np.nan,))[0] for c in cls])
    ok = np.isfinite(hc)
    if ok.sum() < MIN_LABELS:
        return None
    X, y = _design(boxes[ok]), (boxes[ok, 3] - boxes[ok, 1]) / hc[ok]
    keep = np.ones(len(y), bool)
    for _ in range(2):
        if keep.sum() < MIN_LABELS:
            return None
        p = np.linalg.lstsq(X[keep], y[keep], rcond=None)[0]
        if p[0] <= 0:
            return None
        keep = np.abs(y / (X @ p) - 1) < 0.15
    return p


def ratios(boxes: np.ndarray, cls: np.ndarray, fit: np.ndarray) -> np.ndarray:
    hc = np.array([CONE_SIZE_M.get(int(c), (np.nan,))[0] for c in cls])
    with np.errstate(invalid="ignore", divide="ignore"):
        model = hc * (_design(boxes) @ fit)
        return np.where(model > 0, (boxes[:, 3] - boxes[:, 1]) / model, np.nan)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("pred")
    ap.add_argument("--gt", default="data/real_val_1080")
    ap.add_argument("--ratios", default="0.7,0.75,0.8,0.85,0.9")
    ap.add_argument("--max-score", type=float, default=1.0,
                    help="the gate acts only on boxes scoring under this (its score condition; default 1: on all)")
    args = ap.parse_args()
    gates = [float(x) for x in args.ratios.split(",")]
    images, _ = pair_with_predictions(load_ground_truth(args.gt), list(read_predictions(args.pred)), args.pred)
    tp, fp, lab = [], [], []
    frames = skipped = 0
    for im in images:
        gt_keep = ~im.gt_ignore
        fit = fit_frame(im.gt_boxes[gt_keep], im.gt_classes[gt_keep])
        if fit is None:
            skipped += 1
            continue
        frames += 1
        lab.append(ratios(im.gt_boxes[gt_keep], im.gt_classes[gt_keep], fit))
        if len(im.pred_boxes) == 0:
            continue
        order = np.argsort(-im.pred_scores, kind="stable")  # the matching takes the best first
        pb, pc = im.pred_boxes[order], im.pred_classes[order]
        to_gt, ignored = match_by_class(pb, pc, im.gt_boxes, im.gt_classes, im.gt_ignore, 0.5)
        r = ratios(pb, pc, fit)
        r[im.pred_scores[order] >= args.max_score] = np.inf  # boxes the gate does not act on
        h = pb[:, 3] - pb[:, 1]
        matched, unmatched = to_gt >= 0, (to_gt < 0) & ~ignored
        lh = im.gt_boxes[to_gt[matched], 3] - im.gt_boxes[to_gt[matched], 1]
        own = np.where(np.isinf(r[matched]), np.inf, h[matched] / lh)
        tp.append(np.c_[r[matched], h[matched], own])
        fp.append(np.c_[r[unmatched], h[unmatched], np.full(unmatched.sum(), np.nan)])
    tp, fp, lab = np.concatenate(tp), np.concatenate(fp), np.concatenate(lab)
    print(f"{frames} frames with >= {MIN_LABELS} labelled cones ({skipped} with fewer: not used)")

    def row(name, r):
        r = r[~np.isnan(r)]  # inf: a box the gate does not act on (its score)
        f = r[np.isfinite(r)]
        q = np.quantile(f, [0.01, 0.05, 0.5, 0.95]) if len(f) else [np.nan] * 4
        drops = " | ".join(f"{int((r < g).sum())} ({(r < g).mean() if len(r) else 0:.3f})" for g in gates)
        print(f"| {name} | {len(r)} | " + " / ".join(f"{x:.2f}" for x in q) + f" | {drops} |")

    print("| boxes | n | ratio q01 / q05 / median / q95 (of those it acts on) | " + " | ".join(f"< {g:g}" for g in gates) + " |")
    print("|---|---|---|" + "---|" * len(gates))
    row("labels (the stand-in's own fit)", lab)
    row("detections on a label (true cones)", tp[:, 0])
    row("true cones, boxes >= 12 px at the model input (>= 24 px)", tp[tp[:, 1] >= 24, 0])
    row("true cones, boxes < 24 px", tp[tp[:, 1] < 24, 0])
    row("detections on no label", fp[:, 0])
    row("true cones: box height / its label's (the box's own part of the ratio)", tp[:, 2])


if __name__ == "__main__":
    main()
