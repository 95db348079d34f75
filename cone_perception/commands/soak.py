"""``cone-perception soak``: a drive published at a given rate for a given time into a live node; every
frame accounted for, memory and latency over time.

What it counts, its targets (exit 1 when one is missed) and figures: docs/robustness.md, "cone-perception soak".
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..replay.soak import run_soak


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rate", type=float, default=30.0, help="frames per second published (default %(default)s)")
    p.add_argument("--seconds", type=float, default=60.0, help="how long to publish, in s (default %(default)s)")
    p.add_argument("--bag", type=Path, default=None,
                   help="play this rosbag's camera frames (default: render a synthetic drive, see --drive-seconds)")
    p.add_argument("--topic", default=None, help="--bag's camera topic (default: its only image topic)")
    p.add_argument("--drive-seconds", type=float, default=3.0,
                   help="length of the synthetic drive rendered and looped, at 20 Hz (default %(default)s: 60 frames, "
                        "240 MB of YUYV in memory)")
    p.add_argument("--seed", type=int, default=2026, help="synthetic drive's seed (default %(default)s)")
    p.add_argument("--calib", default=None,
                   help="calibration of the node (default: the synthetic drive's, or the node's default with --bag)")
    p.add_argument("--model", default=None, help="model file of the node (default: the shipped one)")
    p.add_argument("--param", action="append", default=[], metavar="NAME:=VALUE",
                   help="another node parameter (repeatable), e.g. --param threads:=1")
    p.add_argument("--window", type=float, default=10.0, help="seconds per row of the time table (default %(default)s)")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS_DOMAIN_ID of the soak (default: one from this process id, 200-232)")
    p.add_argument("--json", type=Path, default=None, help="also write the result as JSON")
    p.add_argument("--plot", type=Path, default=None, help="also draw rates, RSS and latency over time (PNG)")
    p.add_argument("--force", action="store_true", help="overwrite existing --json / --plot")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    return run_soak(args)
