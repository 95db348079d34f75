"""``cone-perception synth``: synthetic FS scenes with exact ground truth.

Actions: ``dataset`` (images + YOLO labels + gt.jsonl + calib.yaml), ``bag``
(rosbag2 MCAP with camera images and /cones_gt), ``preview`` (contact sheet
PNG), ``mapcheck`` (mapping error with perfect boxes), ``bench`` (render speed).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..synth.look import PAINT_LINES
from ..synth.run import run_synth


def _common(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("camera and scene")
    g.add_argument("--seed", type=int, default=0, help="random seed: same seed, same output (default 0)")
    g.add_argument("--size", default="1920x1080", help="image size WxH in px (default 1920x1080)")
    g.add_argument("--hfov", type=float, default=90.0, help="horizontal field of view in degrees (default 90)")
    g.add_argument("--mount-x", type=float, default=0.5, help="camera x ahead of the rear axle in m (default 0.5)")
    g.add_argument("--height", type=float, default=1.2, help="camera height above ground in m (default 1.2)")
    g.add_argument("--pitch", type=float, default=10.0, help="camera pitch in degrees, positive looks down (default 10)")
    g.add_argument("--roll", type=float, default=0.0, help="camera roll in degrees (default 0)")
    g.add_argument("--yaw", type=float, default=0.0, help="camera yaw in degrees, positive looks left (default 0)")
    g.add_argument("--k1", type=float, default=0.0, help="radial distortion k1 (OpenCV model, default 0 = ideal pinhole)")
    g.add_argument("--k2", type=float, default=0.0, help="radial distortion k2 (default 0)")
    g.add_argument("--no-jitter", action="store_true", help="switch off the +-1 degree body pitch/roll jitter")
    g.add_argument("--car-motion", action="store_true",
                   help="bag: the car moves like a car: speed profile with braking / acceleration pitch (up to +-2 deg), "
                        "cornering roll, bumps, grade changes of the road ahead (up to 2 %%); on top of the jitter")
    g.add_argument("--nose-prob", type=float, default=0.5, help="chance a scene shows the car nose at the bottom (default 0.5)")
    g.add_argument("--no-photometric", action="store_true", help="no exposure / white balance / noise / blur / JPEG randomisation")
    g.add_argument("--tracks", default="autocross,skidpad,acceleration",
                   help="comma-separated track kinds to draw from (default all three)")
    g.add_argument("--missing", type=float, default=0.0, help="fraction of cones removed from each track (default 0)")
    g.add_argument("--stray", type=int, default=0, help="stray cones placed off the track per track (default 0)")
    g.add_argument("--knocked", type=float, default=0.0, help="fraction of cones knocked over, lying on their side (default 0)")
    g.add_argument("--paint-lines", choices=PAINT_LINES, default="random",
                   help="the ground's painted lines: random (default: 70 %% of looks, a fifth of them yellow), or yellow "
                        "/ white in every look (hard negatives: a detector's boxes on no cone stand on yellow paint; "
                        "docs/training.md)")
    p.add_argument("--no-progress", "--quiet", dest="no_progress", action="store_true",
                   help="no progress bar (--quiet: the same, kept for old scripts)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    p = sub.add_parser("dataset", help="images + YOLO labels + data.yaml + gt.jsonl + calib.yaml")
    p.add_argument("--n", type=int, required=True, help="number of frames")
    p.add_argument("--out", type=Path, required=True, help="output directory (new or empty)")
    p.add_argument("--frames-per-track", type=int, default=20, help="frames per random track and look (default 20)")
    p.add_argument("--val-frac", type=float, default=0.1, help="fraction of tracks in the val split (default 0.1; at least one track when there are two or more; "
                        "frames of one track only: no val split, data.yaml without val:)")
    p.add_argument("--vary-mount", action="store_true",
                   help="new random viewpoint per track (hfov 70-120, pitch -4..+16 deg around --pitch, height +-0.3 m) for "
                        "detector training; calib.yaml then holds the nominal mount only, each gt.jsonl line its own camera")
    _common(p)
    p = sub.add_parser("bag", help="rosbag2 (MCAP): camera images + /cones_gt, calibration YAML beside it")
    p.add_argument("--seconds", type=float, required=True, help="length of the recording in s")
    p.add_argument("--fps", type=float, default=20.0, help="frame rate in Hz (default 20)")
    p.add_argument("--out", type=Path, required=True, help="bag directory to create (must not exist)")
    p.add_argument("--compressed", action="store_true", help="JPEG CompressedImage on /camera/image_raw/compressed instead of YUYV")
    p.add_argument("--speed", type=float, default=8.0, help="car speed along the centre line in m/s (default 8)")
    p.add_argument("--stand", type=float, default=0.0, metavar="S",
                   help="begin with S seconds of /imu alone, the car standing still (for `cone-perception imu-rest BAG "
                        "--seconds S`; default 0)")
    p.add_argument("--track", default="autocross", help="track kind: autocross, skidpad, acceleration (default autocross)")
    _common(p)
    p = sub.add_parser("preview", help="contact sheet PNG of sample frames with ground-truth boxes")
    p.add_argument("--out", type=Path, required=True, help="PNG file to write")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out")
    p.add_argument("--n", type=int, default=8, help="number of frames (default 8)")
    _common(p)
    p = sub.add_parser("mapcheck", help="map exact boxes through the exact calibration: error left by the foot-point rule "
                                        "and jitter")
    p.add_argument("--frames", type=int, default=30, help="frames to render (default 30)")
    _common(p)
    p = sub.add_parser("bench", help="measure render speed (frames/s) at the given size")
    p.add_argument("--frames", type=int, default=30, help="frames to time (default 30)")
    _common(p)


def run(args: argparse.Namespace) -> int:
    return run_synth(args)
