"""``cone-perception replay``: run the full pipeline over a rosbag, offline (no ROS) or live.

Offline, live, what is printed, ``--gt-topic``, ``--track``: docs/replay.md, "cone-perception replay"; the tracker's
figures: docs/tracking.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..attitude import ATTITUDE_MODES
from ..detector import BACKEND_CHOICES, DEFAULT_BACKEND, RUNTIME_THREADS
from ..geometry.calib import DEFAULT_CAMERA
from ..params import DEFAULT_CONF, PARAMS
from ..replay.run import run_replay
from ._args import add_far_box_model, add_far_model, add_far_verifier


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = "Run the full pipeline over a rosbag's camera topic, offline (no ROS) or through live nodes."
    p.add_argument("bag", type=Path, help="rosbag2 directory (MCAP or sqlite3)")
    p.add_argument("--calib", default=DEFAULT_CAMERA, help="calibration YAML or shipped camera name (default: %(default)s)")
    p.add_argument("--model", default=None, help="model file (default: the shipped default model)")
    p.add_argument("--backend", default=DEFAULT_BACKEND, choices=BACKEND_CHOICES,
                   help="inference backend (default %(default)s: ONNX Runtime on the CPU where installed, else torch)")
    p.add_argument("--conf", type=float, default=DEFAULT_CONF, help="confidence threshold (default %(default)s)")
    p.add_argument("--threads", type=int, default=RUNTIME_THREADS,
                   help="torch / ONNX Runtime threads of the network (default %(default)s, as the nodes; 0 = library default)")
    p.add_argument("--bf16", action="store_true", help="backend torch with bfloat16 autocast on the CPU")
    p.add_argument("--topic", default=None, help="camera topic (default: the bag's only image topic)")
    p.add_argument("--out", type=Path, default=None, help="write /cone_boxes and /cones to this new bag (MCAP)")
    p.add_argument("--gt-topic", default=None, help="ground-truth cones topic (e.g. /cones_gt): print the localisation table")
    p.add_argument("--track", action="store_true",
                   help="run the cone tracker too (live: the pipeline with track: true, or a cone_tracker node after the "
                        "separate nodes; motion from the cones); /cones/tracked goes to --out, and with --gt-topic on a "
                        "synthetic bag (its <bag>_gt.jsonl beside it) the tracking figures are printed")
    p.add_argument("--drop-detections", type=float, default=0.0, metavar="P",
                   help="offline: drop a random share P (0..1) of the detections before tracking and scoring (seeded by "
                        "--drop-seed), to measure gap filling (default 0)")
    p.add_argument("--drop-seed", type=int, default=0, help="seed of --drop-detections (default %(default)s)")
    p.add_argument("--odom-topic", default=None,
                   help="offline, --track: the car's motion from this nav_msgs/Odometry or geometry_msgs/TwistStamped topic "
                        "of the bag (default: estimated from the cones)")
    p.add_argument("--track-conf", type=float, default=None, metavar="S",
                   help="offline, --track: run the detector at this lower score threshold; detections from S up to --conf "
                        "go to the tracker only (weak detections: a cone on /cones/tracked once they recur or land on a "
                        "track; docs/tracking.md 'Weak detections'). Default: off")
    p.add_argument("--tracker", action="append", default=[], metavar="FIELD=VALUE",
                   help="offline, --track: set a TrackerConfig field (cone_perception/tracking/tracker.py, units in its "
                        "names), repeatable, e.g. --tracker max_range_m=40 --tracker spawn_max_m=2")
    p.add_argument("--max-range", type=float, default=None, metavar="M",
                   help="offline: use this max_range_m instead of the calibration's (cones farther are dropped; to "
                        "measure a range before setting it in a calibration)")
    p.add_argument("--far-rows", default=None, metavar="auto|none|V0,V1",
                   help="the far band, image rows also run at full resolution, the whole width (docs/detector.md "
                        "'Far band'): auto (default) = the calibration's far strip, moved each frame with the attitude; "
                        "V0,V1 = these rows, fixed; none (or off) = the band alone. Live: the pipeline node's far_rows (fused only)")
    p.add_argument("--far-every", type=int, default=PARAMS["far_every"].default, metavar="N",
                   help="the far band's cadence: its strip on every N-th frame only, the band alone between (a far cone "
                        "is seen up to N-1 frames late; docs/detector.md 'Far band'; default %(default)s = every frame). "
                        "Live: the pipeline node's far_every (fused only)")
    p.add_argument("--far-tiles", type=int, default=PARAMS["far_tiles"].default, metavar="W",
                   help="with --far-every above 1, on the frames between: the strip's windows around the last two frames' "
                        "far cones in one mosaic at most W columns wide (docs/detector.md 'Far band'); 0 (default) = off, the "
                        "band alone between. Live: the pipeline node's far_tiles (fused only)")
    p.add_argument("--band-split", default=None, metavar="none|auto|N0,U1",
                   help="offline: the band in two (docs/detector.md 'Row-scaled band'): none (default) = one band; auto = "
                        "split from the calibration, the near rows at a quarter of full resolution; N0,U1 = the near band "
                        "from row N0, the upper band to row U1")
    p.add_argument("--band-rows", default=None, metavar="crop|auto|V0,V1",
                   help="the band's rows (docs/detector.md 'Band rows'): crop (default) = the calibration's crop, auto = "
                        "placed from the calibration, V0,V1 = these rows; the cones expected in view follow the band. "
                        "Live: the pipeline node's band_rows (fused only)")
    add_far_model(p, after="; live: the node's far_model")
    add_far_verifier(p)
    add_far_box_model(p)
    p.add_argument("--min-height-ratio", type=float, default=PARAMS["min_height_ratio"].default, metavar="R",
                   help="offline: a box lower than R x the height a cone of its class has where its foot maps is a mark "
                        "on the ground, not a cone: dropped and counted (summary: boxes dropped); 0 = off (default "
                        "%(default)s; live: the nodes' min_height_ratio)")
    p.add_argument("--one-ray-range", type=float, default=PARAMS["one_ray_range_m"].default, metavar="M",
                   help="offline: two cones of one class (two classes from 15 m on) nearly on one viewing ray (under "
                        "0.15 m across, 2 m along it), the better-scored nearer than M m, are one cone seen twice: the "
                        "other is dropped and counted (summary: boxes dropped, one_ray); 0 = off (default %(default)s; "
                        "live: the nodes' one_ray_range_m)")
    p.add_argument("--live", choices=["fused", "separate"], default=None,
                   help="play the bag into live node processes instead of replaying offline")
    p.add_argument("--pace", choices=["lockstep", "rate"], default="lockstep",
                   help="live: next frame when the last one's /cones came back, or at the recorded rate")
    p.add_argument("--attitude", choices=ATTITUDE_MODES, default=None,
                   help="camera attitude per frame: fixed (the calibration's H), image (from the cone boxes), imu (the "
                        "bag's IMU), fused (IMU + image); all but fixed need mount_pose in the calibration. Default: "
                        "fused when the bag has the IMU topic, else image, fixed without a mount pose")
    p.add_argument("--box-model", choices=("auto", "model", "rendered"), default="auto",
                   help="attitude image/fused (live: the nodes' box_model): which box model the image fit reads the detector's boxes with: "
                        "model (measured on real frames, MODEL.box_model.yaml beside the model file; a model without one "
                        "gets a conservative default and a warning), rendered (the rendered drives' table, for synthetic "
                        "bags), auto (rendered with --gt-topic, i.e. a synthetic drive with truth, unless --box-behaviour "
                        "real; else model; default %(default)s)")
    p.add_argument("--box-behaviour", choices=("as-is", "real"), default="as-is",
                   help="offline, synthetic bags: real gives the detector's boxes the real frames' behaviour of its box "
                        "model (MODEL.box_model.yaml: heights 0.97-0.99x, tops 1-3 %% low, the top scattered by the "
                        "measured spread; synth/boxlook.py; the far strip's boxes its far model's, that model's rendered "
                        "offset taken out first), as-is keeps them (default %(default)s)")
    p.add_argument("--box-jitter", type=float, default=None, metavar="F",
                   help="--box-behaviour real: 1-sigma of each box top as a fraction of its height (default: the box "
                        "model's measured spread, 0.07 for the shipped models; 0 = the medians only)")
    p.add_argument("--imu-topic", default="/imu", help="offline: the bag's sensor_msgs/Imu topic (default %(default)s)")
    p.add_argument("--imu-rest", default="0,0", metavar="PITCH,ROLL",
                   help="the IMU's pitch and roll (degrees) with the car at rest on the level calibration ground "
                        "(`cone-perception imu-rest REST_BAG` measures it; default %(default)s)")
    p.add_argument("--attitude-png", type=Path, default=None, metavar="PNG",
                   help="offline: plot the attitude used per frame (and the bag's /attitude_gt where it has one)")
    p.add_argument("--json", type=Path, default=None, help="also write the summary as JSON to this file")
    p.add_argument("--force", action="store_true", help="replace an existing --out bag and --json file")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    return run_replay(args)
