"""The box model of a detector measured on labelled frames (``eval --box-model-out``; issue 27).

Each labelled cone whole inside the band (and the image), not an ignore region, at least
``min_height_px`` tall at the model input, that a detection of its own class overlaps with IoU >= ``iou``
at score >= ``conf``, gives one sample of the detected box against the label: height ratio, top and
bottom offsets as fractions of the labelled height (:mod:`cone_perception.attitude.boxes`). The medians
per height bucket (of the detected box at the model input) make the :class:`BoxModel`; per class too
(report only).
"""

from __future__ import annotations

import numpy as np

from ..attitude.boxes import BOX_MODEL_BUCKETS_PX, BoxModel
from ..classes import CLASS_NAMES
from .groundtruth import EvalImage
from .metrics import at_conf, match_by_class

MAD_TO_SIGMA = 1.4826


def box_samples(images: list[EvalImage], conf: float = 0.25, iou: float = 0.5, band: tuple[float, float] | None = None,
                edge_px: float = 1.0) -> dict[str, np.ndarray]:
    """Matched (detection, label) pairs: ``height_in`` (detected height at the model input px),
    ``height_ratio``, ``top_low``, ``bottom_high`` (fractions of the labelled height), ``class_id``, ``input_scale``.
    ``band``: image rows ``(v0, v1)`` the detector saw (labels reaching within ``edge_px`` of them are left out)."""
    out: dict[str, list] = {k: [] for k in ("height_in", "height_ratio", "top_low", "bottom_high", "class_id", "input_scale")}
    for im in images:
        if len(im.gt_boxes) == 0 or len(im.pred_boxes) == 0:
            continue
        v0, v1 = band if band is not None else (0.0, float(im.height))
        g = im.gt_boxes
        whole = ((g[:, 1] > v0 + edge_px) & (g[:, 3] < v1 - edge_px) & (g[:, 0] > edge_px) & (g[:, 2] < im.width - edge_px)
                 & ~im.gt_ignore)
        keep = at_conf(im.pred_scores, conf)
        to_gt, _ = match_by_class(im.pred_boxes[keep], im.pred_classes[keep], g, im.gt_classes, ~whole, iou)
        s = im.input_scale if im.input_scale is not None else 1.0
        for k, j in zip(keep, to_gt):
            if j < 0:
                continue
            p, lab = im.pred_boxes[k], g[j]
            lh = lab[3] - lab[1]
            if lh <= 0:
                continue
            out["height_in"].append((p[3] - p[1]) * s)
            out["height_ratio"].append((p[3] - p[1]) / lh)
            out["top_low"].append((p[1] - lab[1]) / lh)
            out["bottom_high"].append((lab[3] - p[3]) / lh)
            out["class_id"].append(int(im.gt_classes[j]))
            out["input_scale"].append(s)
    return {k: np.asarray(v, dtype=np.int64 if k == "class_id" else np.float64) for k, v in out.items()}


def measure_box_model(images: list[EvalImage], conf: float = 0.25, iou: float = 0.5,
                      band: tuple[float, float] | None = None, buckets_px: tuple = BOX_MODEL_BUCKETS_PX,
                      note: str = "") -> BoxModel:
    """The :class:`BoxModel` of the detections in ``images`` (module doc). Raises ValueError when no
    detection matches a whole labelled cone of at least the first bucket's height."""
    s = box_samples(images, conf, iou, band)
    h = s["height_in"]
    use = h >= buckets_px[0]
    if not use.any():
        raise ValueError(f"no detection at score >= {conf} matches a whole labelled cone of at least {buckets_px[0]:g} px "
                         "at the model input: nothing to measure")
    edges = list(buckets_px) + [np.inf]
    ratio, top, bottom, counts = [], [], [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = use & (h >= lo) & (h < hi)
        counts.append(int(m.sum()))
        ratio.append(float(np.median(s["height_ratio"][m])) if m.any() else 1.0)
        top.append(float(np.median(s["top_low"][m])) if m.any() else 0.0)
        bottom.append(float(np.median(s["bottom_high"][m])) if m.any() else 0.0)
    t = s["top_low"][use]  # the fit's residual is the top row: its spread is the per-cone uncertainty
    sigma = MAD_TO_SIGMA * float(np.median(np.abs(t - np.median(t))))
    by_class = {}
    for c in np.unique(s["class_id"][use]):
        m = use & (s["class_id"] == c)
        by_class[CLASS_NAMES[int(c)]] = {"count": int(m.sum()), "height_ratio": round(float(np.median(s["height_ratio"][m])), 4),
                                        "top_low": round(float(np.median(s["top_low"][m])), 4),
                                        "bottom_high": round(float(np.median(s["bottom_high"][m])), 4)}
    scale = float(np.median(s["input_scale"][use]))
    return BoxModel(tuple(float(x) for x in buckets_px), tuple(ratio), tuple(top), tuple(bottom), tuple(counts),
                    max(sigma, 1e-3), scale, "measured", note, by_class)


def format_box_model(bm: BoxModel) -> str:
    """The box model as a Markdown table (cards, ``eval``'s printout)."""
    lines = ["| box height at the model input | cones | median height ratio | top low | bottom high |", "|---|---|---|---|---|"]
    for i, lo in enumerate(bm.buckets_px):
        hi = bm.buckets_px[i + 1] if i + 1 < len(bm.buckets_px) else None
        name = f"{lo:g}-{hi:g} px" if hi is not None else f">= {lo:g} px"
        lines.append(f"| {name} | {bm.counts[i]} | {bm.height_ratio[i]:.3f} | {100 * bm.top_low[i]:+.1f} % | "
                     f"{100 * bm.bottom_high[i]:+.1f} % |")
    for name, d in (bm.by_class or {}).items():
        lines.append(f"| {name} (all heights) | {d['count']} | {d['height_ratio']:.3f} | {100 * d['top_low']:+.1f} % | "
                     f"{100 * d['bottom_high']:+.1f} % |")
    lines.append(f"\nSpread of the top offset (1.4826 MAD, fraction of the height): {bm.sigma_rel:.3f}; input scale {bm.input_scale:g}.")
    return "\n".join(lines)
