"""``cone-perception map``: check a calibration by mapping pixels or boxes to rear_axle metres.

Outputs, the boxes' way (as the pipeline node after its detector) and the attitude: docs/calibration.md,
"cone-perception map".
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..geometry.calib import DEFAULT_CAMERA
from ..params import DEFAULT_CONF, PARAMS
from ..replay.map import run_map
from ._args import add_far_box_reading


def _pixel(text: str) -> tuple[float, float]:
    try:
        u, v = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"pixel must be U,V (two numbers), got {text!r}") from None
    return u, v


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = __doc__.split("\n\n")[0].split(": ", 1)[1]
    p.epilog = (
        "Pixels are in the FULL camera image (before crop and downscale). Output: CSV without header, "
        "u,v,x,y per pixel (x, y in rear_axle metres, nan above the horizon or beyond max_range_m), or "
        "x,y,class_id,score,cov_xx,cov_xy,cov_yy per kept cone with --boxes."
    )
    p.add_argument("--calib", default=DEFAULT_CAMERA, help="calibration YAML or shipped camera name (default: %(default)s)")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--pixel", type=_pixel, action="append", metavar="U,V", help="a full-image pixel; repeatable")
    g.add_argument("--boxes", type=Path, metavar="FILE",
                   help="CSV of boxes u1,v1,u2,v2,score,class_id (one frame), or a prediction file of `detect` "
                        "(.jsonl: many frames, mapped in order with one attitude filter)")
    p.add_argument("--attitude", choices=("fixed", "image"), default=None,
                   help="--boxes: fixed (the calibration's H) or image (the boxes are one frame: fit its pitch/roll "
                        "first; needs mount_pose and camera_matrix). Default: image when the calibration has both, else fixed")
    p.add_argument("--model", type=Path, default=None, metavar="MODEL",
                   help="--attitude image: the detector that drew the boxes; the fit reads them through its box model "
                        "(MODEL.box_model.yaml, measured on real frames by `eval --box-model-out`; a model without one "
                        "gets a conservative default and a warning). Default: the shipped default model")
    p.add_argument("--box-model", choices=("model", "rendered"), default="model",
                   help="--attitude image: model (the --model's box model, for real frames; default) or rendered (the "
                        "rendered drives' box table, for boxes of a synthetic drive)")
    add_far_box_reading(p)
    p.add_argument("--min-height-ratio", type=float, default=PARAMS["min_height_ratio"].default, metavar="R",
                   help="--boxes: a box scoring under 0.5 and lower than R x the height a cone of its class has where "
                        "its foot maps is dropped as a mark on the ground, as the node does (its min_height_ratio; "
                        "needs a mount pose; 0 = off; default %(default)s)")
    p.add_argument("--one-ray-range", type=float, default=PARAMS["one_ray_range_m"].default, metavar="M",
                   help="--boxes: two cones of one class (two classes from 15 m on) nearly on one viewing ray (under "
                        "0.15 m across, 2 m along it), the better-scored nearer than M m, are one cone, as the node does "
                        "(its one_ray_range_m; 0 = off; default %(default)s)")
    p.add_argument("--conf", type=float, default=DEFAULT_CONF,
                   help="a .jsonl prediction file: map only boxes of at least this score (default %(default)s)")


def run(args: argparse.Namespace) -> int:
    return run_map(args)
