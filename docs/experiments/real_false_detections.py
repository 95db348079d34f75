"""What the false detections on the real validation clips are (issue 26: the precision that "equal precision" holds).

    .venv/bin/python docs/experiments/real_false_detections.py PRED.jsonl data/real_val_1080 [--conf 0.30] \
        [--band 96,672] [--scale 0.33333] [--sheet OUT.jpg --kind loose|unlabelled] [--n 18]

PRED.jsonl: a `detect` file of the frames (e.g. `detect data/real_val_1080 --crop 96,672 --downscale 2 --far-rows
240,432 --conf 0.001`). Each detection at score >= --conf in the band that matches no label of its class (IoU 0.5,
the match of `eval` and `far_strip_recall.py`) is put in one class by the label it overlaps most:

* ``loose``: IoU 0.1-0.5 with a label of its class that no other detection matched: the same cone, its box and the
  label's disagree;
* ``class swap``: IoU >= 0.5 with a label of another class;
* ``unlabelled``: IoU < 0.1 with every label: a box where the labels have no cone;

counted by its height in the source video (px x --scale) and by who drew it (the band or the far strip, the
file's ``far``). `--sheet`: 200x200 px patches of one kind (labels green, the detection red) for a look by eye.
"""
from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

import cv2
import numpy as np

from cone_perception.data.predictions import read_predictions
from cone_perception.evaluation.groundtruth import load_ground_truth, pair_with_predictions, restrict_to_band
from cone_perception.evaluation.metrics import at_conf, box_iou, match_by_class

NAMES = "blue_cone,large_orange_cone,orange_cone,yellow_cone"
BINS = ((0, 6), (6, 12), (12, 24), (24, 1e9))


def _bin(h: float) -> str:
    for lo, hi in BINS:
        if lo <= h < hi:
            return f"{lo:g}-{hi:g}" if hi < 1e9 else f">= {lo:g}"
    return "?"


def classify(images, conf: float, scale: float):
    """[(kind, video-px bin of the detection, origin, image, detection box, label box or None)] and the counts."""
    rows, n_det, n_tp = [], 0, 0
    for im in images:
        k = at_conf(im.pred_scores, conf)
        pb, pc = im.pred_boxes[k], im.pred_classes[k]
        far = im.pred_far[k] if im.pred_far is not None else np.zeros(len(pb), bool)
        to_gt, ign = match_by_class(pb, pc, im.gt_boxes, im.gt_classes, im.gt_ignore, 0.5)
        n_det += int((~ign | (to_gt >= 0)).sum())
        n_tp += int((to_gt >= 0).sum())
        matched = set(to_gt[to_gt >= 0].tolist())
        iou = box_iou(pb, im.gt_boxes) if len(im.gt_boxes) else np.zeros((len(pb), 0))
        for i in np.flatnonzero((to_gt < 0) & ~ign):
            j = int(iou[i].argmax()) if iou.shape[1] else -1
            best = float(iou[i, j]) if j >= 0 else 0.0
            if best >= 0.5:
                kind = "class swap" if im.gt_classes[j] != pc[i] else "duplicate"
            elif best >= 0.1 and im.gt_classes[j] == pc[i] and j not in matched:
                kind = "loose"
            elif best >= 0.1:
                kind = "near a found cone"
            else:
                kind = "unlabelled"
            h = (pb[i, 3] - pb[i, 1]) * scale
            rows.append((kind, _bin(h), "strip" if far[i] else "band", im, pb[i], im.gt_boxes[j] if j >= 0 else None))
    return rows, n_det, n_tp


def sheet(rows, kind: str, out: Path, n: int) -> int:
    """Patches of the detections of ``kind``, spread over the list, six to a row."""
    sel = [r for r in rows if r[0] == kind]
    if not sel:
        return 0
    sel = [sel[int(i)] for i in np.linspace(0, len(sel) - 1, min(n, len(sel)))]
    tiles = []
    for _, _, _, im, box, label in sel:
        img = cv2.imread(str(im.path))
        if img is None:
            continue
        cx, cy = int((box[0] + box[2]) / 2), int((box[1] + box[3]) / 2)
        x0 = min(max(cx - 100, 0), img.shape[1] - 200)
        y0 = min(max(cy - 100, 0), img.shape[0] - 200)
        t = img[y0:y0 + 200, x0:x0 + 200].copy()
        for b, col in ((label, (0, 255, 0)), (box, (0, 0, 255))):
            if b is not None and (kind != "unlabelled" or b is box):
                cv2.rectangle(t, (int(b[0] - x0), int(b[1] - y0)), (int(b[2] - x0), int(b[3] - y0)), col, 1)
        tiles.append(t)
    while len(tiles) % 6:
        tiles.append(np.zeros_like(tiles[0]))
    cv2.imwrite(str(out), np.vstack([np.hstack(tiles[i:i + 6]) for i in range(0, len(tiles), 6)]),
                [cv2.IMWRITE_JPEG_QUALITY, 85])
    return len(sel)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("pred", type=Path)
    ap.add_argument("gt", type=Path, help="the YOLO folder of the frames (e.g. data/real_val_1080)")
    ap.add_argument("--gt-names", default=NAMES)
    ap.add_argument("--conf", type=float, default=0.30, help="the operating score (default 0.30: the defaults' "
                                                              "threshold at the band alone's precision, far card)")
    ap.add_argument("--band", default="96,672")
    ap.add_argument("--scale", type=float, default=1 / 3, help="source-video px per image px (default 1/3)")
    ap.add_argument("--sheet", type=Path, default=None)
    ap.add_argument("--kind", default="loose", choices=("loose", "unlabelled", "class swap", "near a found cone"))
    ap.add_argument("--n", type=int, default=18)
    a = ap.parse_args(argv)
    gt = load_ground_truth(a.gt, a.gt_names.split(","))
    images, _ = pair_with_predictions(gt, list(read_predictions(a.pred)), str(a.pred), True)
    v0, v1 = (int(v) for v in a.band.split(","))
    images, _ = restrict_to_band(images, (v0, v1))
    rows, n_det, n_tp = classify(images, a.conf, a.scale)
    print(f"score >= {a.conf:g}: {n_det} detections, {n_tp} on a label, {len(rows)} false "
          f"(precision {n_tp / max(n_det, 1):.3f})")
    kinds = Counter(r[0] for r in rows)
    by = Counter((r[0], r[1], r[2]) for r in rows)
    print("| kind | false | by height in video px (band / strip) |")
    print("|---|---|---|")
    for kind, n in kinds.most_common():
        cells = ", ".join(f"{b}: {by[(kind, b, 'band')]} / {by[(kind, b, 'strip')]}"
                          for b in dict.fromkeys(r[1] for r in sorted(rows, key=lambda r: r[4][3] - r[4][1]))
                          if by[(kind, b, 'band')] + by[(kind, b, 'strip')])
        print(f"| {kind} | {n} | {cells} |")
    if a.sheet is not None:
        print(f"wrote {sheet(rows, a.kind, a.sheet, a.n)} patches of '{a.kind}' to {a.sheet}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
