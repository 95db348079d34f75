"""Recall of small cones by box height at a chosen pixel scale, and precision, at one score threshold.

For the far strip's model (models/cone_detector_far.md): the issue's real-clip figures count cones by
their height in the 640x360 source video (6-9 px, 9-12 px), which `eval`'s bins (model input px)
do not split. This reads `detect` output and ground truth as `eval` does (same pairing, same band
restriction, class-aware greedy matching at IoU 0.5) and prints, per height bin, cones, found and
recall, plus the precision of all detections in the band at the threshold.

    .venv/bin/python docs/experiments/far_strip_recall.py PRED.jsonl GT [--gt-names ...] [--band V0,V1]
        [--scale 0.3333] [--bins 0,6,9,12,24,1000] [--conf 0.25 | --at-precision 0.703] [--only-predicted]
        [--max-range 40]

--at-precision P: instead of --conf, the lowest score threshold of 0.01, 0.02, .. 0.99 whose precision
is at least P (recall falls as the threshold rises, so this is the most recall at that precision):
issue 26 compares the far strip's models at equal precision.

--max-range M (ground truth with cone positions: a synth gt.jsonl): cones farther than M m from the rear axle
are left out, as ignore regions (neither a miss nor a detection on them a false one): issue 26's design range
is 40 m.

--scale: factor from the prediction's image px to the px the bins count in (1920-px frames of the
640x360 video: 1/3). Real clips: GT data/real_val_1080 with --gt-names
blue_cone,large_orange_cone,orange_cone,yellow_cone.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from cone_perception.data.predictions import read_predictions
from cone_perception.evaluation.groundtruth import load_ground_truth, pair_with_predictions, restrict_to_band
from cone_perception.evaluation.metrics import at_conf, match_by_class


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("pred")
    p.add_argument("gt")
    p.add_argument("--gt-names", default=None)
    p.add_argument("--band", default=None, help="V0,V1 as eval --band")
    p.add_argument("--scale", type=float, default=1.0)
    p.add_argument("--bins", default="0,6,9,12,24,1000")
    p.add_argument("--conf", type=float, default=0.25)
    p.add_argument("--at-precision", type=float, default=None,
                   help="use the lowest threshold (0.01 steps) whose precision is at least this")
    p.add_argument("--iou", type=float, default=0.5)
    p.add_argument("--only-predicted", action="store_true")
    p.add_argument("--max-range", type=float, default=None, help="leave out cones farther than this (m)")
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    gt = load_ground_truth(a.gt, a.gt_names.split(",") if a.gt_names else None)
    images, _ = pair_with_predictions(gt, list(read_predictions(a.pred)), a.pred, a.only_predicted)
    if a.band:
        images, _ = restrict_to_band(images, tuple(int(v) for v in a.band.split(",")))
    edges = [float(v) for v in a.bins.split(",")]
    if a.at_precision is None:
        out = _at(images, a.conf, edges, a)
    else:
        out = None
        for c in np.arange(1, 100) / 100:
            out = _at(images, float(c), edges, a)
            if out["precision"] >= a.at_precision:
                break
        out["at_precision"] = a.at_precision
    if a.json:
        print(json.dumps(out))
    else:
        print(f"score >= {out['conf']:.2f}: precision {out['precision']:.3f} of {out['detections']} detections")
        for k, v in out["bins"].items():
            r = "-" if v["recall"] is None else f"{v['recall']:.3f}"
            print(f"  {k} px: {v['found']}/{v['cones']} recall {r}")
    return 0


def _at(images, conf: float, edges: list[float], a) -> dict:
    """Recall per height bin and precision of all detections at score >= conf."""
    n = np.zeros(len(edges) - 1, int)
    hit = np.zeros(len(edges) - 1, int)
    tp = fp = 0
    for im in images:
        keep = at_conf(im.pred_scores, conf)
        gt_ignore = im.gt_ignore
        if a.max_range is not None:
            if im.gt_xy_m is None:
                raise SystemExit(f"--max-range: the ground truth of {im.image} has no cone positions")
            gt_ignore = gt_ignore | (np.hypot(im.gt_xy_m[:, 0], im.gt_xy_m[:, 1]) > a.max_range)
        to_gt, ignored = match_by_class(im.pred_boxes[keep], im.pred_classes[keep], im.gt_boxes, im.gt_classes,
                                        gt_ignore, a.iou)
        found = np.zeros(len(im.gt_boxes), bool)
        found[to_gt[to_gt >= 0]] = True
        tp += int((to_gt >= 0).sum())
        fp += int(((to_gt < 0) & ~ignored).sum())
        h = (im.gt_boxes[:, 3] - im.gt_boxes[:, 1]) * a.scale
        k = np.searchsorted(edges, h, side="right") - 1
        for j in range(len(edges) - 1):
            m = (k == j) & ~gt_ignore
            n[j] += int(m.sum())
            hit[j] += int((m & found).sum())
    out = {"conf": conf, "precision": tp / max(tp + fp, 1), "detections": tp + fp,
           "bins": {f"{edges[j]:g}-{edges[j + 1]:g}": {"cones": int(n[j]), "found": int(hit[j]),
                                                       "recall": hit[j] / n[j] if n[j] else None}
                    for j in range(len(edges) - 1)}}
    return out


if __name__ == "__main__":
    raise SystemExit(main())
