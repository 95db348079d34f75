"""``cone-perception``: one command with sub-commands.

Each sub-command lives in ``cone_perception/commands/<name>.py`` with
``add_arguments(parser)`` and ``run(args) -> int``; it is imported only when
used, so ``cone-perception --help`` answers at once (no torch import).
Errors of this package (:class:`~cone_perception.errors.ConePerceptionError`)
end the command with one clear line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from . import __version__
from .errors import ConePerceptionError

# name -> (module under cone_perception.commands, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("demo", "the main job: synthetic drive -> live ROS 2 pipeline -> summary and pictures"),
    "map": ("map", "map pixels or boxes to rear_axle metres with a calibration"),
    "bench": ("bench", "benchmark the per-frame stages on real-size frames"),
    "synth": ("synth", "synthetic FS scenes with exact ground truth: dataset, bag, preview, mapcheck, bench"),
    "detect": ("detect", "run the detector over images, a folder or a rosbag -> JSON lines"),
    "replay": ("replay", "run the full pipeline over a rosbag, offline or through live nodes"),
    "imu-rest": ("imu_rest", "the IMU's rest attitude (imu_rest_deg) from a bag of the car standing still"),
    "calibrate": ("calibrate", "calibrate a camera to the rear axle (chessboard / points / mount pose) with report and pictures"),
    "train": ("train", "train the cone detector on YOLO txt datasets"),
    "export": ("export", "export a detector checkpoint to TorchScript or ONNX, verified against eager"),
    "data": ("data", "dataset converters: fsoco-to-yolo, restore-aspect, far-crops, verifier-crops"),
    "speed": ("speed", "forward micro-benchmark of detector sizes and backends"),
    "validate": ("validate", "the validation suite: rendered drives and real sets through the pipeline -> rows and their spread"),
    "eval": ("eval", "evaluate a prediction file against ground truth -> report.md, metrics.json, plots"),
    "params": ("params", "the nodes' parameters from their schema; --write / --check the tables of docs/nodes.md and the docstrings"),
    "fuzz": ("fuzz", "malformed messages through the nodes' callbacks: crashes, counts, time, RSS"),
    "soak": ("soak", "a drive at a given rate for a given time into a live node: every frame accounted for, RSS, latency"),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cone-perception",
        description="Camera cone perception for a Formula Student driverless car: tools around the ROS 2 nodes.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}",
                        help="print the package version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_, help_text) in COMMANDS.items():
        sub.add_parser(name, help=help_text, add_help=False)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    if not argv or argv[0] not in COMMANDS:
        args = parser.parse_args(argv)  # prints help / the version / errors for unknown commands
        parser.print_help()
        return 1
    name = argv[0]
    module = importlib.import_module(f"cone_perception.commands.{COMMANDS[name][0]}")
    sub = argparse.ArgumentParser(prog=f"cone-perception {name}", description=COMMANDS[name][1])
    module.add_arguments(sub)
    args = sub.parse_args(argv[1:])

    try:
        return int(module.run(args) or 0)
    except ConePerceptionError as e:
        print(f"cone-perception {name}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"cone-perception {name}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
