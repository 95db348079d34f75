"""How to merge the far strip's boxes with the band's (issue 26): replay a synthetic drive with the far strip
merged another way, to compare false cones and recall by range with the shipped rule.

    .venv/bin/python docs/experiments/far_merge.py VARIANT BAG CALIB OUT.json

VARIANT: ``nms0.45`` (class-aware NMS over both sets only: the rule before ``seen_by_far``), ``nms0.2``,
``nms0.05`` (the same at a lower IoU), ``shipped`` (detector/farband.py: of a band box and a strip box of one
cone and class, the strip's is kept while scored at least half the band box's, else the band's; then NMS),
``any_box`` (the rule of commit f0b74fb: a band box gives way to a strip box of its place and size of any class
and score, then NMS), ``strip_decides`` (shipped, and band boxes wholly inside the
strip's rows are dropped). BAG / CALIB / ground truth as for ``replay --gt-topic /cones_gt``.
"""
import sys

import numpy as np

from cone_perception.cli import main
from cone_perception.detector import farband

variant, bag, calib, out = sys.argv[1:5]
shipped = farband.FarBand.merged


def merged(self, band_boxes, strip_bgr, crop=None):
    crop = crop or self.crop
    far = self.detect(strip_bgr, crop)
    if variant.startswith("nms"):
        if len(far) == 0:
            return band_boxes
        both = np.concatenate([band_boxes, far])
        xywh = np.stack([both["u1"], both["v1"], both["u2"] - both["u1"], both["v2"] - both["v1"]], 1)
        return both[farband.nms_per_class(xywh, both["score"], both["class_id"], 0.0, float(variant[3:]))]
    if variant == "any_box":
        if len(far) == 0:
            return band_boxes
        both = np.concatenate([band_boxes[~farband.same_cone(band_boxes, far, same_class=False).any(1)], far])
        xywh = np.stack([both["u1"], both["v1"], both["u2"] - both["u1"], both["v2"] - both["v1"]], 1)
        return both[farband.nms_per_class(xywh, both["score"], both["class_id"], 0.0, self.detector.iou)]
    inside = (band_boxes["v1"] > crop.v0 + farband.EDGE_PX) & (band_boxes["v2"] < crop.v1 - farband.EDGE_PX)
    return farband.merge_boxes(band_boxes[~inside] if variant == "strip_decides" else band_boxes, far, self.detector.iou)


if variant not in ("nms0.45", "nms0.2", "nms0.05", "shipped", "any_box", "strip_decides"):
    raise SystemExit(f"unknown variant {variant!r}")
if variant != "shipped":
    farband.FarBand.merged = merged
sys.exit(main(["replay", bag, "--calib", calib, "--gt-topic", "/cones_gt", "--no-progress", "--force", "--json", out]))
