"""How to merge the far strip's boxes with the band's (issue 26): replay a synthetic drive with the far strip
merged another way, to compare false cones and recall by range with the shipped rule.

    .venv/bin/python docs/experiments/far_merge.py VARIANT BAG CALIB OUT.json [replay options, e.g. --far-model band]

VARIANT: ``nms0.45`` (class-aware NMS over both sets only: the rule before ``seen_by_far``), ``nms0.2``,
``nms0.05`` (the same at a lower IoU), ``shipped`` (detector/farband.py: of a band box and a strip box of one
cone and class, the strip's is kept while scored at least half the band box's, else the band's; then NMS),
``any_box`` (the rule of commit f0b74fb: a band box gives way to a strip box of its place and size of any class
and score, then NMS), ``strip_decides`` (shipped, and band boxes wholly inside the span of the strip's boxes
dropped: a stand-in for the strip's rows, which the pipeline's merge is not told). The variants replace
``pipeline.merge_boxes`` (the Pipeline's merge; until issue 26d they replaced ``FarBand.merged``, which the
Pipeline no longer calls since issue 26c, so such runs all measured the shipped rule). BAG / CALIB / ground truth as for ``replay --gt-topic /cones_gt``.
"""
import sys

import numpy as np

from cone_perception import pipeline
from cone_perception.cli import main
from cone_perception.detector import farband

variant, bag, calib, out = sys.argv[1:5]


def _nms(both, iou):
    xywh = np.stack([both["u1"], both["v1"], both["u2"] - both["u1"], both["v2"] - both["v1"]], 1)
    return both[farband.nms_per_class(xywh, both["score"], both["class_id"], 0.0, iou)]


def merged(band_boxes, far, iou):
    """The merge the pipeline calls (pipeline.merge_boxes: replay runs the Pipeline, not FarBand.merged)."""
    if len(far) == 0:
        return band_boxes
    if variant.startswith("nms"):
        return _nms(np.concatenate([band_boxes, far]), float(variant[3:]))
    if variant == "any_box":
        return _nms(np.concatenate([band_boxes[~farband.same_cone(band_boxes, far, same_class=False).any(1)], far]), iou)
    # strip_decides: band boxes wholly inside the strip's rows (those of the far boxes' frame) dropped
    v0, v1 = float(far["v1"].min()), float(far["v2"].max())  # a stand-in for the strip's rows: its boxes' span
    inside = (band_boxes["v1"] >= v0) & (band_boxes["v2"] <= v1)
    return farband.merge_boxes(band_boxes[~inside], far, iou)


if variant not in ("nms0.45", "nms0.2", "nms0.05", "shipped", "any_box", "strip_decides"):
    raise SystemExit(f"unknown variant {variant!r}")
if variant != "shipped":
    pipeline.merge_boxes = merged
sys.exit(main(["replay", bag, "--calib", calib, "--gt-topic", "/cones_gt", "--no-progress", "--force", "--json", out, *sys.argv[5:]]))
