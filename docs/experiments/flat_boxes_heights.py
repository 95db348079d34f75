"""Each `/cones` box's height over the cone model's at its mapped centre (mapping's ``height_ratios``), true boxes
against phantoms, by range band (issue 26, docs/benchmarks.md "Flat boxes").

    .venv/bin/python docs/experiments/flat_boxes_heights.py REC.pkl [REC.pkl ...]

REC.pkl: recordings of `false_cones.py BAG` (gate off: record them at main's defaults or with
`-- --min-height-ratio 0`). A box is true when it lies on a rendered cone's box (false_cones.cone_of_box), a phantom
otherwise; "unmatched real": true boxes whose cone `/cones` did not match. Prints the ratio's quantiles and the
boxes' height / width.
"""
import pickle
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from false_cones import cone_of_box, load_gt_boxes, origin_of  # noqa: E402
from cone_perception.geometry.calib import load_calibration  # noqa: E402
from cone_perception.mapping import ConeMapper  # noqa: E402
from cone_perception.data.bags import read_ground_truth  # noqa: E402
from cone_perception.evaluation import match_cones  # noqa: E402

rows = []
for p in sys.argv[1:]:
    with open(p, "rb") as f:
        d = pickle.load(f)
    calib = load_calibration(d["calib"])
    ia = ConeMapper(calib).image_attitude()
    gtb = load_gt_boxes(d["bag"] + "_gt.jsonl")
    truth = read_ground_truth(d["bag"], "/cones_gt")
    for stamp, fr in sorted(d["frames"].items()):
        if stamp not in gtb or stamp not in truth:
            continue
        b = fr["boxes"]
        if len(b) == 0:
            continue
        cones = fr["cones"]
        t = truth[stamp]
        t_xy = np.c_[t["x"], t["y"]].astype(float)
        p_xy = np.c_[cones["x"], cones["y"]].astype(float)
        matched = np.zeros(len(cones), bool)
        for i, _, _ in match_cones(p_xy, t_xy):
            matched[i] = True
        for i in range(len(b)):
            ci = fr["cone_of"][i]
            if ci < 0:
                continue
            xy = p_xy[ci]
            cls = int(b["class_id"][i])
            hm = ia.model_heights(xy[None], np.array([cls]))[0]
            h, w = float(b["v2"][i] - b["v1"][i]), float(b["u2"][i] - b["u1"][i])
            gi = cone_of_box((b["u1"][i], b["v1"][i], b["u2"][i], b["v2"][i]), gtb[stamp])
            rows.append((p.split("/")[-1][:7], float(np.hypot(*xy)), h, w, hm, float(b["score"][i]), cls, gi >= 0, bool(matched[ci]), origin_of(b[i], fr["band"], fr["far"])))
a = np.array([(r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8]) for r in rows], float)
rng, h, w, hm, s, cls, real, mt = a.T
ratio = h / hm
aspect = h / w
print("n", len(a), "phantom", int((real == 0).sum()))
for lo, hi in ((0, 7), (7, 15), (15, 25), (25, 40)):
    sel = (rng >= lo) & (rng < hi)
    for lab, m in (("real", real == 1), ("phantom", real == 0), ("unmatched real", (real == 1) & (mt == 0))):
        q = ratio[sel & m]
        qa = aspect[sel & m]
        if len(q):
            rq = " ".join(f"{k} {np.nanquantile(q, x):.2f}" for k, x in (("q01", .01), ("q05", .05), ("med", .5), ("q95", .95), ("q99", .99)))
            aq = " ".join(f"{k} {np.nanquantile(qa, x):.2f}" for k, x in (("q01", .01), ("med", .5), ("q99", .99)))
            print(f"{lo}-{hi} {lab:15s} n {len(q):5d} ratio {rq} | height / width {aq}")
