"""``cone-perception fuzz``: malformed messages through the nodes' callbacks; crashes, counts, time, RSS.

  cone-perception fuzz [--n 10000] [--seed 0] [--targets driver_adapter_raw,...] [--json FILE]

Each target node is built in-process with the shipped calibration and model and gets ``--n``
messages from a seeded generator (``cone_perception/rostools/fuzz.py``): random and structured
malformed Image, CompressedImage (header bombs included), CameraInfo and PointCloud2, stamps
jumping, a few valid frames. Prints per node the crashes (an exception out of a callback), the
messages counted (every one must be: ok or dropped with its cause), the time (worst message and
worst header bomb) and the RSS; then the issue's header bombs timed through the adapter. Exit 1 on
any crash or uncounted message. Run before a release (the tests run a bounded version).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict
from pathlib import Path

from tqdm import tqdm

from ..data.outfiles import print_written, refuse_existing
from ..errors import ConfigError
from ..geometry.calib import resolve_calibration_path


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
    from ..rostools.fuzz import TARGETS, bomb_timings, fuzz_target  # rclpy and the nodes: only when fuzzing

    targets = list(TARGETS) if args.targets == "all" else [t.strip() for t in args.targets.split(",") if t.strip()]
    unknown = [t for t in targets if t not in TARGETS]
    if unknown:
        raise ConfigError("--targets", None, f"unknown {', '.join(unknown)}; known: {', '.join(TARGETS)}")
    if args.n <= 0:
        raise ConfigError("--n", None, f"must be > 0, got {args.n}")
    if args.json:
        refuse_existing([args.json], args.force, "fuzz")
    params = {}
    if args.calib:
        params["calibration"] = str(resolve_calibration_path(args.calib))
    if args.model:
        params["model"] = str(Path(args.model).resolve())
    reports, bad = [], 0
    for t in targets:
        prog = (lambda it, total, t=t: tqdm(it, total=total, desc=t, unit="msg", file=sys.stderr,
                                             disable=args.no_progress))
        rep = fuzz_target(t, args.n, args.seed, params, prog)
        reports.append(rep)
        print(rep.line())
        for ex in rep.crash_examples:
            print(f"  crash: {ex}")
        bad += rep.crashes + (0 if rep.all_counted else 1)
    bombs = bomb_timings(args.calib or "example_mainhoop")
    print("header bombs through the adapter (worst of 20):")
    for name, b in bombs.items():
        print(f"  {name}: {b['bytes']} bytes declaring {b['declared']} px: {b['max_ms']:.3f} ms, "
              f"RSS {b['rss_growth_mb']:+.1f} MB")
    total = sum(r.messages for r in reports)
    print(f"fuzz: {total} messages, {sum(r.crashes for r in reports)} crashes, "
          f"{sum(r.counted for r in reports)} counted" + ("" if not bad else "  FAILED"))
    if args.json:
        doc = {"n": args.n, "seed": args.seed, "targets": [asdict(r) for r in reports], "bombs": bombs}
        args.json.write_text(json.dumps(doc, indent=1))
        print_written([args.json], "fuzz")
    return 1 if bad else 0
