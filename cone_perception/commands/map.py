"""``cone-perception map``: check a calibration by mapping pixels or boxes to rear_axle metres.

  cone-perception map --calib calib/example_mainhoop.yaml --pixel 960,800 --pixel 100,500
      -> one CSV line ``u,v,x,y`` per pixel, no header (``nan,nan`` above the horizon / beyond range)
  cone-perception map --calib CAL --boxes boxes.csv
      -> one line ``x,y,class_id,score,cov_xx,cov_xy,cov_yy`` per kept cone (columns of boxes.csv:
         ``u1,v1,u2,v2,score,class_id``, full-image px, optional header line)
  cone-perception map --calib CAL --boxes boxes.csv --attitude image
      -> the same, the boxes taken as ONE frame whose camera attitude is fitted from them first
         (default with a mount pose in the calibration; the attitude used goes to stderr)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..attitude import attitude_estimator
from ..errors import ConfigError, FrameError
from ..geometry.calib import DEFAULT_CAMERA, load_calibration
from ..mapping import ConeMapper, validate_boxes
from ..records import read_boxes_csv


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
    g.add_argument("--boxes", type=Path, metavar="FILE.csv", help="CSV of boxes u1,v1,u2,v2,score,class_id")
    p.add_argument("--attitude", choices=("fixed", "image"), default=None,
                   help="--boxes: fixed (the calibration's H) or image (the boxes are one frame: fit its pitch/roll "
                        "first; needs mount_pose and camera_matrix). Default: image when the calibration has both, else fixed")


def run(args: argparse.Namespace) -> int:
    calib = load_calibration(args.calib)
    mapper = ConeMapper(calib)
    out = sys.stdout
    if args.pixel:
        uv = np.asarray(args.pixel, dtype=np.float64)
        xy, _ = mapper.ground.map_pixels(uv)
        for (u, v), (x, y) in zip(uv, xy):
            out.write(f"{u:g},{v:g},{x:.4f},{y:.4f}\n")
        return 0
    boxes = read_boxes_csv(args.boxes)
    try:
        validate_boxes(boxes)
    except FrameError as e:
        raise ConfigError(str(args.boxes), None, str(e)) from None
    mode, est = attitude_estimator(mapper, args.attitude)
    att = None
    if est is not None:
        b = np.column_stack([boxes["u1"], boxes["v1"], boxes["u2"], boxes["v2"]]).astype(np.float64)
        att = est.single_frame(b, boxes["class_id"].astype(np.intp))
        print(f"attitude ({mode}, {att.source}, {att.n_cones} cones): pitch {att.pitch_deg:+.3f} +- "
              f"{att.sigma_pitch_deg:.3f} deg, roll {att.roll_deg:+.3f} +- {att.sigma_roll_deg:.3f} deg", file=sys.stderr)
    cones = mapper.map_boxes(boxes, att)
    for c in cones:
        out.write(
            f"{c['x']:.4f},{c['y']:.4f},{int(c['class_id'])},{c['score']:.4f},"
            f"{c['cov_xx']:.6g},{c['cov_xy']:.6g},{c['cov_yy']:.6g}\n"
        )
    return 0
