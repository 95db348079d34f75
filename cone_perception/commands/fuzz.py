"""``cone-perception fuzz``: malformed messages through the nodes' callbacks; crashes, counts, time, RSS.

The fuzzer is :mod:`cone_perception.rostools.fuzz`; what it sends, prints and fails on: docs/robustness.md,
"cone-perception fuzz".
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--n", type=int, default=10_000, help="messages per node (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="generator seed: same seed, same messages (default 0)")
    p.add_argument("--targets", default="all",
                   help="comma-separated nodes: driver_adapter_raw, driver_adapter_compressed, detection, mapping, "
                        "pipeline_raw, pipeline_compressed (default: all)")
    p.add_argument("--calib", default=None, help="calibration YAML or shipped camera name (default: the nodes')")
    p.add_argument("--model", default=None, help="model file of detection / pipeline (default: the shipped one)")
    p.add_argument("--json", type=Path, default=None, help="also write the figures as JSON to this file")
    p.add_argument("--force", action="store_true", help="overwrite an existing --json")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from ..rostools.fuzz import run_fuzz  # rclpy and the nodes: only when fuzzing

    return run_fuzz(args)
