"""``cone-perception demo``: the main job on a built-in sample (what ``make demo`` runs): a seeded synthetic drive
through the live ROS 2 pipeline, its summary and pictures (docs/replay.md, "make demo / cone-perception demo").
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..geometry.calib import DEFAULT_CAMERA
from ..replay.demo import run_demo


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = "The main job on a built-in sample: synthetic drive -> live ROS 2 pipeline -> summary and pictures."
    p.add_argument("--out", type=Path, default=Path("demo_out"), help="output folder (default %(default)s)")
    p.add_argument("--seed", type=int, default=2026, help="scene seed (default %(default)s)")
    p.add_argument("--seconds", type=float, default=10.0, help="length of the drive (default %(default)s)")
    p.add_argument("--fps", type=float, default=20.0, help="camera rate (default %(default)s)")
    p.add_argument("--speed", type=float, default=8.0, help="car speed in m/s (default %(default)s)")
    p.add_argument("--jitter", action=argparse.BooleanOptionalAction, default=True,
                   help="suspension pitch/roll jitter of about +-1 deg (default on: the real error source)")
    p.add_argument("--mode", choices=["fused", "separate"], default="fused",
                   help="one pipeline node, or driver_adapter + detection + mapping (default %(default)s)")
    p.add_argument("--calib", default=DEFAULT_CAMERA, help="calibration (default: shipped %(default)s)")
    p.add_argument("--model", default=None, help="model file (default: the shipped default model)")
    p.add_argument("--offline", action="store_true", help="replay offline (no ROS processes) instead of live")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    return run_demo(args)
