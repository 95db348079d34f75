"""The ``cone-perception map`` run: pixels or a boxes CSV through a calibration's mapper -> rear_axle metres
(and the attitude a single frame's boxes give) on stdout.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ..attitude import attitude_estimator
from ..errors import ConfigError, FrameError
from ..geometry.calib import load_calibration
from ..mapping import ConeMapper, validate_boxes
from ..records import read_boxes_csv


def run_map(args: argparse.Namespace) -> int:
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
