"""``cone-perception calibrate``: one camera's calibration to the rear axle (thesis ch. 4).

From a picture of a chessboard lying on the ground in front of the car (and/or
extra reference points), or from a known mount pose, write the calibration
YAML (``H_S_B``, ``T_F_S``, optional lens model) plus a quality report and
pictures beside it. See ``calib/README.md`` for the procedure at the track.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..calibrate.run import run_calibrate


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.description = (
        "Calibrate one camera to the rear axle: image pixels -> ground metres (H_F_B = T_F_S @ H_S_B).\n\n"
        "From an image:   calibrate --image calib.png --board 9x6 --square 0.2 --x-offset 4.0 --camera mainhoop\n"
        "From a bag:      calibrate --bag run1 --frame 10 --board 9x6 --square 0.2 --x-offset 4.0 --camera mainhoop\n"
        "From a CAD pose: calibrate --from-pose --hfov 90 --size 1920x1080 --cam-x 0.5 --height 1.2 --pitch 10 "
        "--camera mainhoop\n\n"
        "Writes calib/NAME.yaml (crop, foot points and pixel sigmas of an existing file are kept) and beside it\n"
        "NAME.report.txt / .report.json (errors, coverage, predicted error) and NAME.points.png / NAME.birdseye.png.\n"
        "Frame S: the board frame, origin at the centre of the board's inner-corner grid, x forward (away from\n"
        "the car), y left. T_F_S: S -> rear_axle from --x-offset/--y-offset/--yaw."
    )
    src = p.add_argument_group("input image")
    src.add_argument("--image", type=Path, metavar="IMG",
                     help="calibration image (full camera resolution, as the camera delivers it)")
    src.add_argument("--bag", type=Path, metavar="BAG", help="rosbag2 folder or file to take the calibration image from")
    src.add_argument("--frame", type=int, metavar="N", default=0,
                     help="index of the image message in --bag (0 = first; default 0)")
    src.add_argument("--topic", metavar="TOPIC",
                     help="image topic in --bag (default: the only sensor_msgs Image/CompressedImage topic)")

    pts = p.add_argument_group("reference points (frame S, metres)")
    pts.add_argument("--board", metavar="COLSxROWS", help="chessboard size in INNER corners COLSxROWS, e.g. 9x6")
    pts.add_argument("--square", type=float, metavar="M", help="chessboard square size in metres, e.g. 0.2")
    pts.add_argument("--board-pose", default="0,0,0", metavar="X,Y,YAW",
                     help="centre of the board's inner-corner grid in S (m) and the angle of its lines (deg); default "
                          "0,0,0 (S is the board frame). Which way round the board lies is found from the image")
    pts.add_argument("--points", type=Path, metavar="FILE.csv",
                     help="CSV of extra pairs u,v,x_s,y_s (raw image px, metres in S), e.g. cones at measured spots")
    pts.add_argument("--ransac-px", type=float, metavar="PX", default=3.0,
                     help="RANSAC inlier threshold in pixels (default 3)")

    tf = p.add_argument_group("S -> rear_axle (T_F_S)")
    tf.add_argument("--x-offset", type=float, metavar="M", default=0.0,
                    help="x of S's origin in rear_axle (m, forward); thesis: board distance")
    tf.add_argument("--y-offset", type=float, metavar="M", default=0.0, help="y of S's origin in rear_axle (m, left)")
    tf.add_argument("--yaw", type=float, metavar="DEG", default=0.0,
                    help="angle of S's x axis from rear_axle's x axis (deg, counter-clockwise)")

    lens = p.add_argument_group("lens (optional; H is then estimated on undistorted points)")
    lens.add_argument("--intrinsics", metavar="FILE", type=Path,
                      help="YAML with camera_matrix (3x3) and dist_coeffs (OpenCV), e.g. another calibration YAML or "
                           "ROS ost.yaml")
    lens.add_argument("--views", type=Path, nargs="+", metavar="IMG",
                      help="chessboard views (>= 3, tilted) -> cv2.calibrateCamera")
    lens.add_argument("--no-progress", action="store_true", help="no progress bar while reading --views")
    lens.add_argument("--views-board", metavar="COLSxROWS", help="board of the --views if not the --board on the ground")
    lens.add_argument("--views-square", type=float, metavar="M",
                      help="square size of the --views board (default --square)")
    lens.add_argument("--no-intrinsics", action="store_true",
                      help="drop camera_matrix/dist_coeffs kept from an existing --out")

    pose = p.add_argument_group("from a known mount pose (--from-pose)")
    pose.add_argument("--from-pose", action="store_true", help="H from K and the mount pose instead of an image")
    pose.add_argument("--size", metavar="WxH", help="image size WxH (default: from --image, --out or 1920x1080)")
    pose.add_argument("--hfov", type=float, metavar="DEG",
                      help="horizontal field of view (deg) for a square-pixel K centred in the image")
    pose.add_argument("--cam-x", type=float, metavar="M", default=0.0, help="camera x in rear_axle (m, forward)")
    pose.add_argument("--cam-y", type=float, metavar="M", default=0.0, help="camera y in rear_axle (m, left)")
    pose.add_argument("--height", type=float, metavar="M", help="camera height above the ground (m)")
    pose.add_argument("--pitch", type=float, metavar="DEG", help="camera pitch (deg, positive looks down)")
    pose.add_argument("--roll", type=float, metavar="DEG", default=0.0,
                      help="camera roll (deg, positive lowers the right side)")
    pose.add_argument("--cam-yaw", type=float, metavar="DEG", default=0.0, help="camera yaw (deg, positive looks left)")

    out = p.add_argument_group("output")
    out.add_argument("--camera", metavar="NAME", help="camera name (default: the --out file's stem)")
    out.add_argument("--out", type=Path, metavar="FILE.yaml", help="calibration YAML to write (default calib/CAMERA.yaml)")
    out.add_argument("--force", action="store_true", help="update an existing --out (its crop, foot points and other "
                     "keys are kept) and overwrite its report files")
    out.add_argument("--far-m", type=float, metavar="M", default=10.0,
                     help="warn when no point lies this far ahead (default 10 m)")


def run(args: argparse.Namespace) -> int:
    defaults = argparse.ArgumentParser()
    add_arguments(defaults)
    return run_calibrate(args, vars(defaults.parse_args([])))
