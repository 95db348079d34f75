"""``eval``: detection and localisation quality of a prediction file against ground truth.

:func:`evaluate` turns paired images (:mod:`.groundtruth`) into every figure: COCO mAP@0.5 and
mAP@0.5:0.95 (pycocotools, :mod:`.metrics`), precision / recall / F1 and the confusion matrix at
the operating threshold, the same per distance group, and with cone positions in the ground truth
the localisation error (:mod:`.localisation`) and the thesis's blue-yellow pair distance error.
:func:`write_report` writes ``metrics.json``, ``report.md`` and the pictures (:mod:`.plots`); :func:`format_summary`
is the printed table.

Distance of a ground-truth box: its true range (``gt.jsonl``) or, with a calibration, the range of
its foot point mapped through ``H_F_B``. Distance of a detection: that of the ground-truth box it
overlaps most (IoU >= the threshold), else of its own foot point through the calibration; a
detection with neither is left out of the groups (counted). In a group's evaluation the boxes of
other groups are ignore regions, so a detection is never counted false for a cone of another group.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..attitude import FIXED, attitude_estimator
from ..attitude.box_files import attitude_config_for
from ..classes import CLASS_NAMES
from ..data.outfiles import json_safe
from ..data.predictions import read_predictions
from ..geometry.calib import Calibration, load_calibration
from ..mapping import ConeMapper
from ..params import DEFAULT_CONF
from ..records import CONE_DTYPE, boxes_from_arrays
from ..resources import default_model_path, far_model_for
from ..words import plural
from .attitude import AttitudeReport
from .groundtruth import EvalImage, load_ground_truth, pair_with_predictions, restrict
from .localisation import DISTANCE_GROUPS, EXTRA_GROUPS, LocalisationReport, PairDistanceReport, distance_group
from .metrics import ImageDetections, coco_map, greedy_match, operating_point
from .plots import plot_by_distance, plot_confusion, plot_localisation, plot_pairs, plot_pr, plot_worst_frames

FILES = {
    "report": "report.md",
    "metrics": "metrics.json",
    "confusion": "confusion_matrix.png",
    "pr": "pr_curves.png",
    "by_distance": "detection_by_distance.png",
    "localisation": "localisation_boxplots.png",
    "pairs": "pair_distance_error.png",
    "worst": "worst_frames.jpg",
}


@dataclass
class EvalResult:
    metrics: dict  # every figure (what metrics.json holds)
    confusion: np.ndarray  # (C + 1, C + 1) rows true, cols predicted, last = background
    loc: LocalisationReport | None = None  # per-pair errors for the box plots
    pairs: PairDistanceReport | None = None
    notes: list[str] = field(default_factory=list)
    images: list[EvalImage] = field(default_factory=list)  # what was scored (pictures of the worst frames)


def _to_calib_px(boxes_px: np.ndarray, width: int, height: int, calib: Calibration) -> np.ndarray:
    """(N, 4) boxes in an image of ``width`` x ``height`` px -> the calibration's full-image px."""
    sx, sy = calib.image_width / width, calib.image_height / height
    return np.asarray(boxes_px, np.float64).reshape(-1, 4) * np.array([sx, sy, sx, sy])


def box_ranges_m(boxes_px: np.ndarray, class_ids: np.ndarray, width: int, height: int, mapper) -> np.ndarray:
    """(N,) range in m of each box's foot point through ``mapper`` (a ConeMapper without range cut); NaN above the horizon."""
    if len(boxes_px) == 0:
        return np.zeros(0)
    rec = boxes_from_arrays(_to_calib_px(boxes_px, width, height, mapper.calib), np.ones(len(boxes_px)), class_ids)
    xy, _ = mapper.ground.map_pixels(mapper.foot_points(rec))
    return np.hypot(xy[:, 0], xy[:, 1])


def _group_or_none(range_m: np.ndarray) -> np.ndarray:
    """(N,) distance group index, -1 where the range is unknown (NaN)."""
    g = distance_group(np.nan_to_num(range_m, nan=0.0))
    g[np.isnan(range_m)] = -1
    return g


def _detections(im: EvalImage, gt_keep: np.ndarray | None = None, pred_keep: np.ndarray | None = None) -> ImageDetections:
    ign = im.gt_ignore if gt_keep is None else (im.gt_ignore | ~gt_keep)
    pk = slice(None) if pred_keep is None else pred_keep
    return ImageDetections(im.gt_boxes, im.gt_classes, im.pred_boxes[pk], im.pred_scores[pk], im.pred_classes[pk], ign)


HEIGHT_BINS = ((0.0, 8.0), (8.0, 12.0), (12.0, 24.0), (24.0, 48.0), (48.0, math.inf))
#: Box heights in the ground-truth image's own px (issue 26: the small cones of a real clip are counted at its scale).
IMAGE_HEIGHT_BINS = ((0.0, 6.0), (6.0, 9.0), (9.0, 12.0), (12.0, 20.0), (20.0, math.inf))
MIN_HEIGHT_PX = 12.0  # the default-model target: recall >= 0.90 for boxes at least this tall at the model input


def _height_name(lo: float, hi: float) -> str:
    return f">= {lo:g} px" if math.isinf(hi) else f"{lo:g}-{hi:g} px"


def recall_by_box_height(images: list[EvalImage], conf: float, iou: float, bins=HEIGHT_BINS, image_px: bool = False) -> dict:
    """Recall at the operating point of ground-truth boxes binned by their height at the model input.

    Heights are image px times the prediction file's ``input_scale`` (model input px per image
    px); without it, image px (and ``unit`` says so). ``image_px``: in the ground-truth image's own px
    (``unit`` names the image sizes), binned by ``bins``.
    """
    scales = [im.input_scale for im in images]
    known = all(s is not None for s in scales) and not image_px
    heights = [(im.gt_boxes[:, 3] - im.gt_boxes[:, 1]) * (im.input_scale if known else 1.0) for im in images]
    sizes = ", ".join(f"{w}x{h}" for w, h in sorted({(im.width, im.height) for im in images}))
    unit = ("model input px" if known else f"image px of the {sizes} images" if image_px
            else "image px (the prediction file has no input_scale)")
    out: dict = {"unit": unit, "bins": {}}

    def block(lo: float, hi: float) -> dict:
        keep = [(h >= lo) & (h < hi) for h in heights]
        op = operating_point([_detections(im, k) for im, k in zip(images, keep)], conf, iou, CLASS_NAMES).to_dict()
        a = op["per_class"]["all"]
        return {"num_gt": int(sum((k & ~im.gt_ignore).sum() for im, k in zip(images, keep))),
                "tp": a["tp"], "fn": a["fn"], "recall": a["recall"]}

    for lo, hi in bins:
        out["bins"][_height_name(lo, hi)] = block(lo, hi)
    out["at_least_min_height"] = {"min_height_px": MIN_HEIGHT_PX, **block(MIN_HEIGHT_PX, math.inf)}
    return out


def _detection_block(dets: list[ImageDetections], conf: float, iou: float) -> tuple[dict, np.ndarray]:
    m = coco_map(dets, CLASS_NAMES).to_dict()
    op = operating_point(dets, conf, iou, CLASS_NAMES)
    m["operating_point"] = op.to_dict()
    return m, op.confusion


#: Predictions whose lowest score is above this were cut at a threshold: mAP then is not the model's.
FULL_CURVE_SCORE = 0.01


def lowest_score_note(images: list[EvalImage]) -> str | None:
    """A warning when the predictions were cut at a score above :data:`FULL_CURVE_SCORE` (what mAP then means)."""
    scores = [im.pred_scores for im in images if len(im.pred_scores)]
    if not scores:
        return None
    low = float(min(s.min() for s in scores))
    if low <= FULL_CURVE_SCORE:
        return None
    return (f"the predictions' lowest score is {low:.3f} (> {FULL_CURVE_SCORE:g}): they were cut at a score threshold, so "
            f"the PR curves end at the recall reached at {low:.3f} and mAP is that of the cut predictions, below the "
            f"model's own; for the model's mAP run detect with --conf 0.001 (P/R/F1 at the operating point are not affected "
            f"as long as --conf >= {low:.3f})")


def evaluate(images: list[EvalImage], calib: Calibration | None, conf: float = DEFAULT_CONF, iou: float = 0.5,
             has_positions: bool = False, progress: bool = False, attitude: str = "fixed",
             attitude_config=None) -> EvalResult:
    """Every figure of the report for paired images; ``calib`` maps boxes to metres (optional).
    ``attitude``: ``fixed`` (the calibration's H) or ``image`` (each image's camera attitude fitted from its
    own detections first, as ``map --boxes --attitude image``; needs a mount pose in the calibration), reading the
    boxes as ``attitude_config`` says (an :class:`~cone_perception.attitude.ImageAttitudeConfig`; None: its
    defaults, the rendered table), the far strip's (``EvalImage.pred_far``) through its ``far_reading``."""
    notes: list[str] = []
    range_mapper = ConeMapper(replace(calib, max_range_m=math.inf)) if calib is not None else None
    mapper = ConeMapper(calib) if calib is not None else None
    do_loc = has_positions and calib is not None
    if has_positions and calib is None:
        notes.append("localisation skipped: the ground truth has positions but no calibration was given (--calib) or found beside it")
    loc = LocalisationReport(max_range_m=calib.max_range_m) if do_loc else None
    pairs = PairDistanceReport() if do_loc else None
    att_report = AttitudeReport() if do_loc else None
    att_est = attitude_estimator(mapper, attitude, None, attitude_config)[1] if do_loc and attitude != "fixed" else None

    if calib is not None:
        ratio = calib.image_width / calib.image_height
        odd = sorted({(im.width, im.height) for im in images if abs(im.width / im.height / ratio - 1.0) > 0.01})
        if odd:
            notes.append(f"boxes of {', '.join(f'{w}x{h}' for w, h in odd)} images were scaled per axis to the calibration's "
                         f"{calib.image_width}x{calib.image_height} (different aspect: right only for images squeezed from that camera)")
    gt_range, pred_range = [], []
    no_pred_range = 0
    for im in tqdm(images, desc="eval", unit="img", disable=not progress):
        if im.gt_xy_m is not None:
            gr = np.hypot(im.gt_xy_m[:, 0], im.gt_xy_m[:, 1])
        elif range_mapper is not None:
            gr = box_ranges_m(im.gt_boxes, im.gt_classes, im.width, im.height, range_mapper)
        else:
            gr = np.full(len(im.gt_boxes), np.nan)
        order = np.argsort(-im.pred_scores, kind="stable")
        to_gt, _ = greedy_match(im.pred_boxes[order], im.gt_boxes, np.zeros(len(gr), bool), iou)
        pr = np.full(len(im.pred_boxes), np.nan)
        pr[order] = np.where(to_gt >= 0, gr[np.maximum(to_gt, 0)] if len(gr) else np.nan, np.nan)
        if range_mapper is not None:
            own = box_ranges_m(im.pred_boxes, im.pred_classes, im.width, im.height, range_mapper)
            pr = np.where(np.isnan(pr), own, pr)
        no_pred_range += int(np.isnan(pr[im.pred_scores >= conf]).sum())
        gt_range.append(gr)
        pred_range.append(pr)
        if loc is not None:
            keep = im.pred_scores >= conf
            rec = boxes_from_arrays(_to_calib_px(im.pred_boxes[keep], im.width, im.height, calib), im.pred_scores[keep], im.pred_classes[keep])
            att = FIXED
            if att_est is not None:
                b = np.column_stack([rec["u1"], rec["v1"], rec["u2"], rec["v2"]]).astype(np.float64)
                att = att_est.single_frame(b, rec["class_id"].astype(np.intp),
                                           im.pred_far[keep] if im.pred_far is not None else None)
            pred_cones = mapper.map_boxes(rec, att)
            truth = np.zeros(int((~im.gt_ignore).sum()), CONE_DTYPE)
            truth["x"], truth["y"] = im.gt_xy_m[~im.gt_ignore, 0], im.gt_xy_m[~im.gt_ignore, 1]
            truth["class_id"] = im.gt_classes[~im.gt_ignore]
            matches = loc.add_frame(pred_cones, truth)
            pairs.add_frame(pred_cones, truth, matches)
            att_report.add_frame(att, None, pred_cones, truth, matches)

    low = lowest_score_note(images)
    if low:
        notes.append(low)
    overall, confusion = _detection_block([_detections(im) for im in images], conf, iou)
    n_gt = int(sum((~im.gt_ignore).sum() for im in images))
    metrics: dict = {
        "inputs": {"images": len(images), "gt_boxes": n_gt, "gt_ignored_boxes": int(sum(im.gt_ignore.sum() for im in images)),
                   "predictions": int(sum(len(im.pred_scores) for im in images)),
                   "predictions_at_conf": int(sum((im.pred_scores >= conf).sum() for im in images)),
                   "min_score": min((float(im.pred_scores.min()) for im in images if len(im.pred_scores)), default=None),
                   "conf": conf, "iou": iou, "calibration": calib.source if calib is not None else None,
                   "max_range_m": (calib.max_range_m if math.isfinite(calib.max_range_m) else None) if calib is not None else None},
        "detection": overall,
    }
    metrics["by_box_height"] = recall_by_box_height(images, conf, iou)
    metrics["by_box_height_image"] = recall_by_box_height(images, conf, iou, IMAGE_HEIGHT_BINS, image_px=True)
    has_dist = any(np.isfinite(r).any() for r in gt_range)
    if has_dist:
        groups = {}
        gt_group, pred_group = [_group_or_none(r) for r in gt_range], [_group_or_none(r) for r in pred_range]
        for k, (name, lo, hi) in enumerate(DISTANCE_GROUPS):
            dets = [_detections(im, gg == k, pg == k) for im, gg, pg in zip(images, gt_group, pred_group)]
            block, _ = _detection_block(dets, conf, iou)
            block["range_m"] = [lo, hi if math.isfinite(hi) else None]
            groups[name] = block
        bands = {}
        for name, lo, hi in EXTRA_GROUPS:  # the look-ahead bands to 40 m (issue 26), beside the groups
            dets = [_detections(im, (gr >= lo) & (gr < hi), (pr >= lo) & (pr < hi))
                    for im, gr, pr in zip(images, gt_range, pred_range)]
            op = operating_point(dets, conf, iou, CLASS_NAMES).to_dict()["per_class"]["all"]
            bands[name] = {"range_m": [lo, hi], "num_gt": int(sum(((gr >= lo) & (gr < hi) & ~im.gt_ignore).sum()
                                                                  for im, gr in zip(images, gt_range))),
                           "tp": op["tp"], "fp": op["fp"], "fn": op["fn"], "recall": op["recall"],
                           "precision": op["precision"], "fp_per_image": op["fp"] / len(images) if images else float("nan")}
        metrics["by_distance"] = {
            "distance_from": "ground-truth positions" if has_positions else "foot points through the calibration",
            "gt_boxes_without_distance": int(sum((np.isnan(gr) & ~im.gt_ignore).sum() for im, gr in zip(images, gt_range))),
            "predictions_without_distance": no_pred_range,
            "groups": groups,
            "bands": bands,
        }
    else:
        notes.append("per-distance metrics skipped: no cone positions in the ground truth and no calibration (--calib)")
    if loc is not None:
        metrics["localisation"] = loc.summary()
        metrics["localisation"]["attitude"] = {"mode": attitude, **att_report.summary()}
        if att_est is not None:
            metrics["localisation"]["attitude"]["fits"] = att_est.counts.as_dict()
        metrics["pair_distance"] = pairs.summary()
    return EvalResult(metrics, confusion, loc, pairs, notes, images)


# ------------------------------------------------------------------ report, json, summary


def _f(x, nd: int = 3) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{nd}f}"


def _range_cut_text(inp: dict) -> dict[str, str]:
    """What range cut each table has: ``image`` (scored in the image: none) and ``metres`` (mapped to metres:
    the calibration's ``max_range_m``)."""
    r = inp.get("max_range_m")
    return {"image": "Range cut: none (scored in the image, every distance; the calibration's max_range_m does not apply).",
            "metres": (f"Range cut: max_range_m = {r:g} m of the calibration (true cones and detections farther away are "
                       "not counted, as the mapper drops them on the car)." if r is not None
                       else "Range cut: none (the calibration has no max_range_m).")}


def _detection_table(d: dict) -> list[str]:
    rows = ["| class | AP@0.5 | AP@0.5:0.95 | TP | FP | FN | precision | recall | F1 |", "|---|---|---|---|---|---|---|---|---|"]
    pc = d["operating_point"]["per_class"]
    for name in list(CLASS_NAMES) + ["all"]:
        s = pc[name]
        if name != "all" and name not in d["ap50_per_class"] and s["tp"] + s["fp"] + s["fn"] == 0:
            continue
        ap50 = d["map50"] if name == "all" else d["ap50_per_class"].get(name)
        ap = d["map50_95"] if name == "all" else d["ap_per_class"].get(name)
        label = "**all** (mAP)" if name == "all" else name
        rows.append(f"| {label} | {_f(ap50)} | {_f(ap)} | {s['tp']} | {s['fp']} | {s['fn']} | {_f(s['precision'])} | {_f(s['recall'])} | {_f(s['f1'])} |")
    return rows


def write_report(res: EvalResult, out: Path, pred_source: str, gt_source: str, worst: int = 6) -> dict[str, Path]:
    """``metrics.json``, ``report.md`` and the PNGs into ``out`` (with ``worst`` > 0 also a picture of the
    frames with most errors); returns the written files by key."""
    out.mkdir(parents=True, exist_ok=True)
    m = res.metrics
    inp = m["inputs"]
    files = {}
    files["confusion"] = plot_confusion(res.confusion, out / FILES["confusion"],
                                        f"confusion matrix, conf >= {inp['conf']:g}, IoU >= {inp['iou']:g} ({plural(inp['images'], 'image')})")
    files["pr"] = plot_pr(m["detection"], out / FILES["pr"], f"precision-recall at IoU 0.5 ({plural(inp['images'], 'image')}, {plural(inp['gt_boxes'], 'cone')})")
    md = [
        "# Evaluation report", "",
        f"- predictions: `{pred_source}`", f"- ground truth: `{gt_source}`",
        f"- images {inp['images']}, ground-truth cones {inp['gt_boxes']} (+ {inp['gt_ignored_boxes']} ignored: too small, hidden"
        f"{' or outside the band' if 'band_rows' in m.get('ground_truth', {}) else ''}"
        f"{' or below --min-height' if 'min_height_px' in m.get('ground_truth', {}) else ''}"
        f"{' or beyond --max-range' if 'max_range_m' in m.get('ground_truth', {}) else ''}), "
        f"detections {inp['predictions']} ({inp['predictions_at_conf']} with score >= {inp['conf']:g})",
        f"- operating point: score >= {inp['conf']:g}, IoU >= {inp['iou']:g}; mAP by pycocotools over all scores",
        f"- calibration: `{inp['calibration']}`" if inp["calibration"] else "- calibration: none",
    ]
    md += [f"- {k.replace('_', ' ')}: {v}" for k, v in m.get("ground_truth", {}).items()]
    md += [f"- note: {n}" for n in res.notes]
    d = m["detection"]
    cut = _range_cut_text(inp)
    md += ["", "## Detection", "", f"mAP@0.5 **{_f(d['map50'])}**, mAP@0.5:0.95 **{_f(d['map50_95'])}** "
           f"(mean over the classes present in the ground truth). {cut['image']}", ""]
    md += _detection_table(d)
    md += ["", f"![PR curves]({FILES['pr']})", "",
           "Confusion matrix: rows true class, columns predicted class; detections matched to cones by IoU whatever "
           "their class; *background* = a detection on no cone (column) or a cone without detection (row).", "",
           f"![confusion matrix]({FILES['confusion']})"]
    bh = m["by_box_height"]
    md += ["", "## Recall by box height", "",
           f"Ground-truth box height in {bh['unit']}; recall at the operating point (score >= {inp['conf']:g}, IoU >= {inp['iou']:g}). "
           f"{cut['image']}", "",
           "| box height | cones | TP | FN | recall |", "|---|---|---|---|---|"]
    for name, s in list(bh["bins"].items()) + [(f"**>= {bh['at_least_min_height']['min_height_px']:g} px**", bh["at_least_min_height"])]:
        md.append(f"| {name} | {s['num_gt']} | {s['tp']} | {s['fn']} | {_f(s['recall'])} |")
    bi = m["by_box_height_image"]
    md += ["", f"The same by ground-truth box height in {bi['unit']}:", "",
           "| box height | cones | TP | FN | recall |", "|---|---|---|---|---|"]
    md += [f"| {name} | {s['num_gt']} | {s['tp']} | {s['fn']} | {_f(s['recall'])} |" for name, s in bi["bins"].items()]
    if "by_distance" in m:
        bd = m["by_distance"]
        files["by_distance"] = plot_by_distance(bd["groups"], out / FILES["by_distance"])
        md += ["", "## Detection by distance group", "",
               f"Distance from {bd['distance_from']}; cones of other groups are ignore regions in each group's evaluation. "
               f"Cones without a distance: {bd['gt_boxes_without_distance']}; detections (at the operating point) without one: "
               f"{bd['predictions_without_distance']}. {cut['image']}", "",
               "| group | cones | mAP@0.5 | mAP@0.5:0.95 | TP | FP | FN | precision | recall | F1 |", "|---|---|---|---|---|---|---|---|---|---|"]
        for name, g in bd["groups"].items():
            s = g["operating_point"]["per_class"]["all"]
            md.append(f"| {name} | {g['num_gt']} | {_f(g['map50'])} | {_f(g['map50_95'])} | {s['tp']} | {s['fp']} | {s['fn']} | "
                      f"{_f(s['precision'])} | {_f(s['recall'])} | {_f(s['f1'])} |")
        md += ["", f"![detection by distance]({FILES['by_distance']})", "",
               "Look-ahead bands (to 40 m; a detection's distance as above, false = a detection on no cone):", "",
               "| band | cones | TP | FP | FN | recall | precision | false per image |", "|---|---|---|---|---|---|---|---|"]
        md += [f"| {name} | {b['num_gt']} | {b['tp']} | {b['fp']} | {b['fn']} | {_f(b['recall'])} | {_f(b['precision'])} | "
               f"{_f(b['fp_per_image'], 2)} |" for name, b in bd["bands"].items()]
    if "localisation" in m:
        lo = m["localisation"]
        files["localisation"] = plot_localisation(res.loc, out / FILES["localisation"])
        files["pairs"] = plot_pairs(res.pairs, out / FILES["pairs"])
        md += ["", "## Localisation", "",
               f"Detections (score >= {inp['conf']:g}) mapped to metres through the calibration, matched to true cones by "
               f"ground distance (greedy, nearest first, gate 0.5 m + 10 % of the range). Errors in m. {cut['metres']}", "",
               "| group | true cones | recall | matched | median err | p90 err | median abs x | median abs y | same class |",
               "|---|---|---|---|---|---|---|---|---|"]
        for name, s in list(lo["groups"].items()) + [("**all**", lo["all"])]:
            md.append(f"| {name} | {s['n_true']} | {_f(s['recall'])} | {s['n_matched']} | {_f(s['median_err_m'])} | {_f(s['p90_err_m'])} | "
                      f"{_f(s['median_abs_err_x_m'])} | {_f(s['median_abs_err_y_m'])} | {_f(s['class_accuracy'])} |")
        md += _uncertainty_table(lo.get("attitude"))
        md += ["", f"Unmatched detections (false positives in metres): {lo['false_positives']}.", "",
               f"![localisation box plots]({FILES['localisation']})", "",
               "### Blue-yellow pair distance (thesis metric)", "",
               f"Each true blue cone is paired with the nearest true yellow cone (within {m['pair_distance']['max_pair_m']:g} m); "
               "a pair is measured when both are matched; error = measured - true distance; group by the pair's midpoint. "
               f"{cut['metres']}", "",
               "| group | pairs | measured | median err | median abs err | mean abs err | p90 abs err |", "|---|---|---|---|---|---|---|"]
        pdist = m["pair_distance"]
        for name, s in list(pdist["groups"].items()) + [("**all**", pdist["all"])]:
            md.append(f"| {name} | {s['n_pairs']} | {s['n_measured']} | {_f(s['median_err_m'])} | {_f(s['median_abs_err_m'])} | "
                      f"{_f(s['mean_abs_err_m'])} | {_f(s['p90_abs_err_m'])} |")
        md += ["", f"![pair distance error]({FILES['pairs']})"]
    if worst > 0:
        band = m.get("ground_truth", {}).get("band_rows")
        p, listed = plot_worst_frames(res.images, inp["conf"], inp["iou"], out / FILES["worst"], worst,
                                      tuple(band) if band else None)
        md += ["", "## Frames with the most errors", ""]
        if p is None:
            md.append("No frame with errors could be drawn (no errors, or the image files are not readable).")
        else:
            files["worst"] = p
            md += [f"At the operating point: green = found, red = false detection, magenta = missed cone, grey = ignore region"
                   f"{', cyan = the band' if band else ''}.", "",
                   "| frame | missed | false | found |", "|---|---|---|---|"]
            md += [f"| {d['image']} | {d['missed']} | {d['false']} | {d['found']} |" for d in listed]
            md += ["", f"![frames with the most errors]({FILES['worst']})"]
    md += ["", f"Every figure is in [{FILES['metrics']}]({FILES['metrics']}).", ""]
    (out / FILES["report"]).write_text("\n".join(md), encoding="utf-8")
    files["report"] = out / FILES["report"]
    (out / FILES["metrics"]).write_text(json.dumps(json_safe(m), indent=1) + "\n", encoding="utf-8")
    files["metrics"] = out / FILES["metrics"]
    return files


def _uncertainty_table(att: dict | None) -> list[str]:
    """report.md lines: per distance group the matched cones' median error beside their median 1-sigma
    (covariance: foot-point pixels and, with ``--attitude image``, the attitude's uncertainty)."""
    if not att or not att.get("groups"):
        return []
    src = ", ".join(f"{k} {v}" for k, v in sorted(att["frames_by_source"].items()))
    md = ["", f"Each matched cone's predicted 1-sigma (sqrt of the trace of its covariance; attitude `{att['mode']}`: "
              f"images by source {src}) beside its error:", "",
          "| group | matched | median err | median 1-sigma | err <= 2 sigma |", "|---|---|---|---|---|"]
    md += [f"| {name} | {g['n']} | {_f(g['median_err_m'])} | {_f(g['median_sigma_m'])} | {_f(g['within_2sigma'], 2)} |"
           for name, g in att["groups"].items()]
    return md


def format_summary(res: EvalResult) -> str:
    """The printed summary: overall, per group, localisation and pair error in a few lines."""
    m = res.metrics
    d, inp = m["detection"], m["inputs"]
    a = d["operating_point"]["per_class"]["all"]
    lines = [f"images {inp['images']}, cones {inp['gt_boxes']}, detections {inp['predictions_at_conf']} (score >= {inp['conf']:g})"
             ,
             f"mAP@0.5 {_f(d['map50'])}  mAP@0.5:0.95 {_f(d['map50_95'])}  precision {_f(a['precision'])}  recall {_f(a['recall'])}  F1 {_f(a['f1'])}"
             "  (no range cut)"]
    big = m["by_box_height"]["at_least_min_height"]
    lines.append(f"recall of boxes >= {big['min_height_px']:g} px tall ({m['by_box_height']['unit']}): {_f(big['recall'])} of {big['num_gt']}")
    bi = m["by_box_height_image"]
    lines.append(f"recall by box height ({bi['unit']}): "
                 + ", ".join(f"{k} {_f(v['recall'])} ({v['num_gt']})" for k, v in bi["bins"].items()))
    if "by_distance" in m:
        lines.append(f"{'group':<16}{'cones':>7}{'mAP50':>8}{'recall':>8}{'prec':>8}   (no range cut)")
        for name, g in m["by_distance"]["groups"].items():
            s = g["operating_point"]["per_class"]["all"]
            lines.append(f"{name:<16}{g['num_gt']:>7}{_f(g['map50']):>8}{_f(s['recall']):>8}{_f(s['precision']):>8}")
        lines.append(f"{'band':<16}{'cones':>7}{'recall':>8}{'prec':>8}{'false/img':>10}")
        for name, b in m["by_distance"]["bands"].items():
            lines.append(f"{name:<16}{b['num_gt']:>7}{_f(b['recall']):>8}{_f(b['precision']):>8}{_f(b['fp_per_image'], 2):>10}")
    if "localisation" in m:
        r = inp.get("max_range_m")
        lines.append(f"{'localisation':<16}{'true':>7}{'recall':>8}{'med err':>9}{'p90 err':>9}{'pair err':>10}{'1-sigma':>9}   "
                     + (f"(within max_range_m {r:g} m)" if r is not None else "(no range cut)"))
        lo, pd = m["localisation"], m["pair_distance"]
        sig = (lo.get("attitude") or {}).get("groups", {})
        for name in list(lo["groups"]) + ["all"]:
            s = lo["all"] if name == "all" else lo["groups"][name]
            p = pd["all"] if name == "all" else pd["groups"][name]
            sg = _f(sig[name]["median_sigma_m"]) if name in sig else "-"
            lines.append(f"{name:<16}{s['n_true']:>7}{_f(s['recall']):>8}{_f(s['median_err_m']):>9}{_f(s['p90_err_m']):>9}"
                         f"{_f(p['median_abs_err_m']):>10}{sg:>9}")
        att = lo.get("attitude") or {}
        lines.append("errors in m; pair err = median |measured - true| blue-yellow distance (thesis metric); 1-sigma = the "
                     f"matched cones' median predicted 1-sigma (attitude {att.get('mode', 'fixed')})")
    lines += [f"note: {n}" for n in res.notes]
    return "\n".join(lines)


def evaluate_predictions(pred: Path, gt_path: Path, gt_names: str | None = None, calib_arg: str | None = None,
                         conf: float = DEFAULT_CONF, iou: float = 0.5, only_predicted: bool = False, progress: bool = True,
                         verbose: bool = True, band: tuple[int, int] | None = None, min_height: float | None = None,
                         attitude: str = "fixed", box_model: str = "auto", model: str | Path | None = None,
                         far_model: str | None = None, max_range: float | None = None, far_box_model: str = "band"):
    """A prediction file against ground truth -> :class:`~cone_perception.evaluation.report.EvalResult`, as ``eval``
    computes it (``gt_names`` comma-separated; ``band``, ``min_height``, ``max_range``, ``attitude``, ``box_model``,
    ``model``, ``far_model``, ``far_box_model``: as ``eval --band``, ``--min-height``, ``--max-range``, ``--attitude``,
    ``--box-model``, ``--model``, ``--far-model``, ``--far-box-model``).
    Used by ``eval`` and ``bench table``."""
    names = [n.strip() for n in gt_names.split(",") if n.strip()] if gt_names else None
    gt = load_ground_truth(gt_path, names)
    preds = list(read_predictions(pred))
    images, counts = pair_with_predictions(gt, preds, str(pred), only_predicted)
    images, cut = restrict(images, band, min_height, max_range, iou, str(gt_path))
    counts = {**counts, **cut}
    calib_path = calib_arg if calib_arg is not None else gt.calib_path
    calib = load_calibration(calib_path) if calib_path is not None else None
    if verbose and calib is not None and calib_arg is None:
        print(f"calibration: {calib_path} (found beside the ground truth)")
    if verbose and gt_path.is_dir() and (gt_path / "gt.jsonl").is_file():
        print(f"note: {gt_path / 'gt.jsonl'} exists; pass it as --gt for localisation and distances from true positions")
    att_cfg = None
    if attitude == "image" and calib is not None:  # the boxes read as the node reads them (docs/attitude.md, Box model)
        band_model = model or default_model_path()
        att_cfg, what = attitude_config_for(box_model, band_model, far_model_for(far_model, band_model),
                                            calib.camera == "synth", far_box_model)
        if verbose:
            print(f"image attitude: box model {what}")
    res = evaluate(images, calib, conf, iou, gt.has_positions, progress=progress, attitude=attitude,
                   attitude_config=att_cfg)
    res.metrics["ground_truth"] = {"format": gt.kind, **gt.info, **counts}
    return res
