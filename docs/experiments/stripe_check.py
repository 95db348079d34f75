"""A cone's stripe against a painted line (issue 26, docs/benchmarks.md "Flat boxes": measured, not shipped).

    .venv/bin/python docs/experiments/stripe_check.py --rec REC.pkl [REC.pkl ...]     # rendered drives
    .venv/bin/python docs/experiments/stripe_check.py --real PRED.jsonl [--gt data/real_val_1080]

Stripe contrast of a box: the mean luminance of its middle third of rows against its top and bottom thirds (the
smaller of the two differences, over the box's mean; the central half of its columns), in the full-resolution frame.
``--rec``: `false_cones.py` recordings, every second frame's `/cones` boxes read from the bag, true (on a rendered
cone's box) or phantom. ``--real``: `detect` boxes of the real validation clips (the car's band, models/cone_detector.md
"Metrics"), true (matched to a label of its class at IoU >= 0.5) or on no label. Prints quantiles per class and how
many boxes a stripe test at 0.05 / 0.08 would drop.
"""
from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from false_cones import cone_of_box, load_gt_boxes  # noqa: E402

from cone_perception.data.bags import read_bag_images  # noqa: E402
from cone_perception.data.predictions import read_predictions  # noqa: E402
from cone_perception.evaluation.groundtruth import load_ground_truth, pair_with_predictions  # noqa: E402
from cone_perception.evaluation.metrics import match_by_class  # noqa: E402


def stripe(img: np.ndarray, box) -> float:
    u1, v1, u2, v2 = (int(round(float(x))) for x in box[:4])
    w, h = u2 - u1, v2 - v1
    if h < 6 or w < 3:
        return np.nan
    c = img[max(v1, 0):v2, max(u1 + w // 4, 0):u2 - w // 4]
    if c.size == 0:
        return np.nan
    L = cv2.cvtColor(np.ascontiguousarray(c), cv2.COLOR_BGR2GRAY).astype(np.float32).mean(1)
    n = len(L)
    a, m, z = L[: n // 3].mean(), L[n // 3: 2 * n // 3].mean(), L[2 * n // 3:].mean()
    return float(min(abs(m - a), abs(m - z)) / max(L.mean(), 1.0))


def rendered(paths) -> list[tuple[float, bool, int]]:
    rows = []
    for p in paths:
        with open(p, "rb") as f:
            d = pickle.load(f)
        gtb = load_gt_boxes(d["bag"] + "_gt.jsonl")
        stamps = sorted(d["frames"])[::2]
        imgs = read_bag_images(d["bag"], set(stamps))
        for st in stamps:
            fr, img = d["frames"][st], imgs.get(st)
            if img is None or st not in gtb:
                continue
            for i, b in enumerate(fr["boxes"]):
                if fr["cone_of"][i] >= 0:
                    box = (b["u1"], b["v1"], b["u2"], b["v2"])
                    rows.append((stripe(img, box), cone_of_box(box, gtb[st]) >= 0, int(b["class_id"])))
    return rows


def real(pred: str, gt: str) -> list[tuple[float, bool, int]]:
    rows = []
    images, _ = pair_with_predictions(load_ground_truth(gt), list(read_predictions(pred)), pred)
    for im in images:
        img = cv2.imread(im.path)
        o = np.argsort(-im.pred_scores, kind="stable")
        to_gt, ignored = match_by_class(im.pred_boxes[o], im.pred_classes[o], im.gt_boxes, im.gt_classes, im.gt_ignore, 0.5)
        for k, i in enumerate(o):
            if not ignored[k]:
                rows.append((stripe(img, im.pred_boxes[i]), bool(to_gt[k] >= 0), int(im.pred_classes[i])))
    return rows


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rec", nargs="*", default=[])
    ap.add_argument("--real", default=None)
    ap.add_argument("--gt", default="data/real_val_1080")
    args = ap.parse_args()
    rows = rendered(args.rec) if args.rec else real(args.real, args.gt)
    a = np.array(rows, float).reshape(-1, 3)
    print("| class | boxes | n | stripe 5 % / 25 % / median | < 0.05 | < 0.08 |")
    print("|---|---|---|---|---|---|")
    for cl in np.unique(a[:, 2]).astype(int):
        for m, name in ((1, "true"), (0, "phantom / no label")):
            x = a[(a[:, 2] == cl) & (a[:, 1] == m) & np.isfinite(a[:, 0]), 0]
            if len(x):
                q = " / ".join(f"{v:.3f}" for v in np.quantile(x, [0.05, 0.25, 0.5]))
                print(f"| {cl} | {name} | {len(x)} | {q} | {int((x < 0.05).sum())} | {int((x < 0.08).sum())} |")
