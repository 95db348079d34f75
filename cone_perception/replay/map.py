"""The ``cone-perception map`` run: pixels, a boxes CSV or a prediction file through a calibration's mapper ->
rear_axle metres (and the attitude the boxes give) on stdout.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ..attitude import attitude_estimator, attitude_for_boxes
from ..data.predictions import read_predictions
from ..detector.farband import drawn_by_far
from ..detector.model_files import attitude_config_for, default_model_path
from ..errors import ConfigError, FrameError
from ..geometry.calib import load_calibration
from ..mapping import ConeMapper, one_box_per_cone, validate_boxes
from ..params import check_options
from ..records import BOX_DTYPE, BoxColumns, read_boxes_csv
from ..resources import far_model_for


def run_map(args: argparse.Namespace) -> int:
    calib = load_calibration(args.calib)
    out = sys.stdout
    if args.pixel:
        uv = np.asarray(args.pixel, dtype=np.float64)
        xy, _ = ConeMapper(calib).ground.map_pixels(uv)
        for (u, v), (x, y) in zip(uv, xy):
            out.write(f"{u:g},{v:g},{x:.4f},{y:.4f}\n")
        return 0
    # boxes: the steps the pipeline node runs after its detector (one box per cone, the flat-box gate, one cone per
    # ray, the attitude
    # with each network's boxes read through its own box model), so a file is mapped as the node maps a frame
    check_options({"--min-height-ratio": ("min_height_ratio", args.min_height_ratio),
                   "--one-ray-range": ("one_ray_range_m", args.one_ray_range)})
    mapper = ConeMapper(calib, args.min_height_ratio, args.one_ray_range)
    config = None
    if args.attitude == "image" or args.attitude is None and calib.has_attitude_model:
        model = args.model or default_model_path()
        config, _ = attitude_config_for(args.box_model, model, far_model_for(args.far_model, model), False,
                                        args.far_box_model)
    mode, est = attitude_estimator(mapper, args.attitude, None, config)
    if args.boxes.suffix == ".jsonl":
        return _run_sequence(args, calib, mapper, mode, est)
    boxes = BoxColumns.of(read_boxes_csv(args.boxes))
    try:
        validate_boxes(boxes)
    except FrameError as e:
        raise ConfigError(str(args.boxes), None, str(e)) from None
    kept = one_box_per_cone(boxes)
    mapper.dropped["second_box"] += len(boxes) - len(kept)
    boxes = kept
    att = None
    if est is not None:
        att = est.single_frame(boxes.xyxy.astype(np.float64), boxes.class_id.astype(np.intp))
        print(f"attitude ({mode}, {att.source}, {att.n_cones} cones): pitch {att.pitch_deg:+.3f} +- "
              f"{att.sigma_pitch_deg:.3f} deg, roll {att.roll_deg:+.3f} +- {att.sigma_roll_deg:.3f} deg", file=sys.stderr)
    cones = mapper.map_boxes(boxes, att)
    for c in cones:
        out.write(
            f"{c['x']:.4f},{c['y']:.4f},{int(c['class_id'])},{c['score']:.4f},"
            f"{c['cov_xx']:.6g},{c['cov_xy']:.6g},{c['cov_yy']:.6g}\n"
        )
    _print_dropped(mapper)
    return 0


def _print_dropped(mapper: ConeMapper) -> None:
    """The boxes that reached no cone, by cause (as the node counts them), to stderr."""
    if any(mapper.dropped.values()):
        print("boxes dropped: " + ", ".join(f"{k} {v}" for k, v in mapper.dropped.items() if v), file=sys.stderr)


def _run_sequence(args: argparse.Namespace, calib, mapper: ConeMapper, mode: str, est) -> int:
    """The frames of a prediction file in order, one attitude filter across them (as the node sees a stream)."""
    out = sys.stdout
    n_frames, n_far = 0, 0
    for pred in read_predictions(args.boxes):
        keep = pred.boxes["score"] >= args.conf
        b = pred.boxes[keep].astype(BOX_DTYPE)
        sx, sy = calib.image_width / pred.width, calib.image_height / pred.height  # image px -> the calibration's px
        b["u1"] *= sx
        b["u2"] *= sx
        b["v1"] *= sy
        b["v2"] *= sy
        kept = one_box_per_cone(BoxColumns.of(b))  # the frame's boxes as columns, once
        mapper.dropped["second_box"] += len(b) - len(kept)
        far = drawn_by_far(kept.records, b[pred.far[keep]]) if pred.far is not None else None  # the strip's, of those kept
        n_far += int(far.sum()) if far is not None else 0
        b = kept
        att = attitude_for_boxes(est, b, None, far)
        n_frames += 1
        if est is not None:
            print(f"{pred.image}: attitude ({mode}, {att.source}, {att.n_cones} cones): pitch {att.pitch_deg:+.3f} +- "
                  f"{att.sigma_pitch_deg:.3f} deg, roll {att.roll_deg:+.3f} +- {att.sigma_roll_deg:.3f} deg", file=sys.stderr)
        for c in mapper.map_boxes(b, att):
            out.write(f"{pred.image},{c['x']:.4f},{c['y']:.4f},{int(c['class_id'])},{c['score']:.4f},"
                      f"{c['cov_xx']:.6g},{c['cov_xy']:.6g},{c['cov_yy']:.6g}\n")
    summary = f"{n_frames} frames of {args.boxes}, {n_far} boxes of the far strip kept"
    if est is not None:
        summary += ", attitude fits: " + ", ".join(f"{k} {v}" for k, v in est.counts.as_dict().items())
    print(summary, file=sys.stderr)
    _print_dropped(mapper)
    return 0
