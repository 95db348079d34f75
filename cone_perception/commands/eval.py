"""``cone-perception eval``: a prediction file against ground truth -> report.md, metrics.json, PNGs.

Ground truth, options and the report: docs/evaluation.md (:mod:`cone_perception.evaluation.report`); ``--tracked``
(a ``replay --track`` bag against its drive): docs/tracking.md (:mod:`cone_perception.evaluation.tracking`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..evaluation.run import run_eval
from ..params import DEFAULT_CONF
from ._args import add_far_box_reading, parse_crop


def _unit(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number in 0..1, got {text!r}") from None
    if not 0.0 <= v <= 1.0:
        raise argparse.ArgumentTypeError(f"must be within 0..1, got {v}")
    return v


def _rows(text: str) -> tuple[int, int]:
    vals = parse_crop(text)
    if len(vals) != 2:
        raise argparse.ArgumentTypeError(f"must be two integer rows V0,V1, got {text!r}")
    if not 0 <= vals[0] < vals[1]:
        raise argparse.ArgumentTypeError(f"needs 0 <= V0 < V1, got {vals[0]},{vals[1]}")
    return vals


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = ("Evaluate a prediction file of `cone-perception detect` against ground truth: mAP (pycocotools), "
                     "precision/recall/F1, confusion matrix, PR curves, the same per distance group, localisation error "
                     "and the blue-yellow pair distance error; writes report.md, metrics.json and PNGs. With --tracked "
                     "instead of --pred: the tracking figures of a `replay --track --out` bag against a synthetic drive "
                     "(recall, false cones, error within 15 m of /cones and /cones/tracked, id switches, IDF1).")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--pred", type=Path, help="JSON-lines prediction file written by `cone-perception detect`")
    what.add_argument("--tracked", type=Path, metavar="BAG",
                      help="score tracking instead: the --out bag of `cone-perception replay --track` (its /cones and "
                           "/cones/tracked) against --gt, the gt.jsonl of the `synth bag` it replayed (BAG_gt.jsonl); "
                           "the table of `replay --gt-topic` without the ego-motion error (not in the bag)")
    p.add_argument("--gt", type=Path, required=True,
                   help="ground truth: a YOLO folder (images/ + labels/, flat or per split, class names in data.yaml) "
                        "or a gt.jsonl of `cone-perception synth` (with cone positions)")
    p.add_argument("--calib", default=None,
                   help="calibration YAML (or shipped camera name) to map boxes to metres: distances for YOLO ground truth, "
                        "detections for localisation (default: calib.yaml / <bag>_calib.yaml beside the ground truth, if any)")
    p.add_argument("--out", type=Path, required=True, help="output folder for report.md, metrics.json and the PNGs")
    p.add_argument("--conf", type=_unit, default=DEFAULT_CONF, help="operating score threshold for P/R/F1, confusion and localisation (default %(default)s)")
    p.add_argument("--iou", type=_unit, default=0.5, help="IoU for a detection to match a box at the operating point (default %(default)s)")
    p.add_argument("--gt-names", default=None,
                   help="YOLO folder without data.yaml: its class names in id order, comma-separated "
                        "(e.g. blue_cone,large_orange_cone,orange_cone,yellow_cone)")
    p.add_argument("--band", type=_rows, default=None, metavar="V0,V1",
                   help="score only what the car's band of image rows V0-V1 shows (as `detect --crop V0,V1`): "
                        "ground-truth boxes are clipped to it, and those less than 30 %% inside become ignore regions "
                        "(default: every labelled cone of the frame counts)")
    p.add_argument("--only-predicted", action="store_true",
                   help="evaluate only the ground-truth images the prediction file has lines for (default: all must be there)")
    p.add_argument("--min-height", type=float, default=None, metavar="PX",
                   help="score only cones at least PX tall at the model input, as COCO scores an area range: shorter "
                        "boxes become ignore regions, shorter detections count only where they match a kept cone "
                        "(default: every size counts)")
    p.add_argument("--max-range", type=float, default=None, metavar="M",
                   help="score only cones within M m of the rear axle (ground truth with cone positions: a gt.jsonl of "
                        "`synth`): farther ones become ignore regions, as the drives score within the far strip's "
                        "design range of 40 m (default: every distance counts)")
    p.add_argument("--worst", type=int, default=6, metavar="N",
                   help="draw the N frames with the most misses + false detections into worst_frames.jpg (default %(default)s; 0 = none)")
    p.add_argument("--attitude", choices=("fixed", "image"), default="fixed",
                   help="localisation: fixed (the calibration's H, default) or image (each image's camera pitch/roll fitted "
                        "from its own detections first, as `map --boxes --attitude image`; needs mount_pose and "
                        "camera_matrix in the calibration); the table gives each group's median predicted 1-sigma")
    p.add_argument("--model", type=Path, default=None, metavar="MODEL",
                   help="--attitude image: the detector that drew the predictions; the fit reads its boxes through its "
                        "box model (MODEL.box_model.yaml), as the node does. Default: the shipped default model")
    p.add_argument("--box-model", choices=("auto", "model", "rendered"), default="auto",
                   help="--attitude image: how the fit reads the boxes: model (the --model's measured box model, real "
                        "frames), rendered (the rendered drives' box table) or auto (default: rendered for a synthetic "
                        "camera's calibration, `camera: synth`, else model), as the nodes' box_model")
    add_far_box_reading(p)
    p.add_argument("--box-model-out", type=Path, default=None, metavar="FILE.yaml",
                   help="also measure the detector's box model (issue 27: median detected/labelled height and top/bottom "
                        "offsets per box height at the model input, and per class; whole labelled cones inside --band, "
                        "matched at --iou and --conf) and write it to FILE.yaml; beside the model as "
                        "MODEL.pt.box_model.yaml the image attitude uses it")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    return run_eval(args)
