"""``cone-perception replay``: run the full pipeline over a rosbag, offline (no ROS) or live.

Offline, live, what is printed, ``--gt-topic``, ``--track``: docs/replay.md, "cone-perception replay"; the tracker's
figures: docs/tracking.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..geometry.calib import DEFAULT_CAMERA
from ..replay.run import run_replay
from ._args import add_pipeline_settings


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = "Run the full pipeline over a rosbag's camera topic, offline (no ROS) or through live nodes."
    p.add_argument("bag", type=Path, help="rosbag2 directory (MCAP or sqlite3)")
    p.add_argument("--calib", default=DEFAULT_CAMERA, help="calibration YAML or shipped camera name (default: %(default)s)")
    add_pipeline_settings(p)
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
    p.add_argument("--live", choices=["fused", "separate"], default=None,
                   help="play the bag into live node processes instead of replaying offline")
    p.add_argument("--pace", choices=["lockstep", "rate"], default="lockstep",
                   help="live: next frame when the last one's /cones came back, or at the recorded rate")
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
