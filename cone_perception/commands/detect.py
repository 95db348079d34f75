"""``cone-perception detect``: run the detector over an image, a folder, a video or a rosbag -> JSON lines.

Usage, sources, frame names and the line format: docs/detector.md, "cone-perception detect".
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..detector import BACKEND_CHOICES, DEFAULT_BACKEND
from ..params import DEFAULT_CONF, DEFAULT_IOU
from ..replay.detect import run_detect
from ._args import add_band_split, add_far_model, add_far_verifier, parse_crop, size_arg


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = ("Run the detector over an image, a folder of images, a video file (mp4, avi, mkv, ...) or a "
                     "rosbag's camera topic; write JSON lines.")
    p.add_argument("source", type=Path, help="image file, folder of images, video file, or rosbag2 directory")
    p.add_argument("--out", type=Path, required=True, help="JSON-lines output file")
    p.add_argument("--model", default=None, help="model file (default: the shipped default model)")
    p.add_argument("--backend", default=DEFAULT_BACKEND, choices=BACKEND_CHOICES,
                   help="inference backend (default %(default)s: ONNX Runtime on the CPU where installed, else torch)")
    p.add_argument("--bf16", action="store_true",
                   help="backend torch on the CPU: bfloat16 autocast (about 1.5-2x faster where the CPU has native bf16)")
    p.add_argument("--imgsz", type=size_arg, default=None, help="letterbox each image to this model input WxH")
    p.add_argument("--crop", type=parse_crop, default=None, help="band V0,V1[,U0,U1] in image px, cut before the model")
    p.add_argument("--downscale", type=int, default=1, choices=[1, 2, 4], help="with --crop: integer downscale")
    p.add_argument("--calib", default=None, metavar="C",
                   help="as the car runs this camera: the calibration's band (crop, downscale) and, unless --far-rows "
                        "says otherwise, its far strip at its calibrated rows (instead of --crop/--downscale)")
    add_band_split(p, "with --crop or --calib: ", "; auto needs --calib")
    p.add_argument("--far-rows", default=None, metavar="auto|none|V0,V1",
                   help="the far band: image rows also run at full resolution, the whole width, merged with the band's "
                        "boxes (docs/detector.md 'Far band'): auto = the --calib calibration's far strip (the default "
                        "with --calib); V0,V1 = these rows (with --crop or --calib); none (or off) = no far band (the default "
                        "without --calib)")
    add_far_model(p)
    add_far_verifier(p)
    p.add_argument("--conf", type=float, default=DEFAULT_CONF, help="confidence threshold (default %(default)s)")
    p.add_argument("--iou", type=float, default=DEFAULT_IOU, help="NMS IoU threshold (default %(default)s)")
    p.add_argument("--topic", default=None, help="rosbag: camera topic (default: the only image topic)")
    p.add_argument("--save-vis", type=Path, default=None, metavar="DIR",
                   help="write annotated images here (with --crop the band is drawn too)")
    p.add_argument("--every", type=int, default=1, metavar="N",
                   help="video or bag: every N-th frame only (default 1: all); frame indices stay those of the source")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    return run_detect(args)
