"""``cone-perception validate``: the pipeline's settings judged on the validation suite (docs/validation.md);
exit 1 when a drive failed (after the others ran)."""

from __future__ import annotations

import argparse
import sys
from dataclasses import fields
from pathlib import Path

from ..replay.suite import Settings, run_suite, select, suite_list
from ..replay.suite_drives import FPS, SECONDS
from ._args import add_pipeline_settings


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = ("The validation suite: fixed rendered drives (judging seeds) and the real labelled sets through the "
                     "pipeline as the node runs it; one row each and the spread over the drives (docs/validation.md).")
    p.add_argument("--out", type=Path, default=None, help="folder for suite.json, drives.csv, real.csv, spread.png, logs/")
    p.add_argument("--cache", type=Path, default=Path("runs/validate_bags"),
                   help="where the rendered drives are kept, so that a rerun only replays (default %(default)s)")
    p.add_argument("--quick", action="store_true", help="a handful of the drives (and the real sets): a few minutes")
    p.add_argument("--drives", default=None, metavar="NAME,...", help="only these drives / real sets (--list names them)")
    p.add_argument("--tuning", action="store_true",
                   help="the tuning drives: the same drives with seeds disjoint from the judging ones (tune on these)")
    p.add_argument("--list", action="store_true", help="print the drives and real sets and exit")
    p.add_argument("--seconds", type=float, default=SECONDS, help="each drive's length in s (default %(default)s)")
    p.add_argument("--fps", type=float, default=FPS, help="each drive's frame rate (default %(default)s)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    g = p.add_argument_group("the pipeline settings judged (as `replay`'s; defaults: the node's)")
    add_pipeline_settings(g)
    g.set_defaults(attitude="image")

def run(args: argparse.Namespace) -> int:
    drives, real = select(args.drives, args.quick, args.tuning)
    if args.list:
        print(suite_list(drives, real))
        return 0
    if args.out is None:
        print("cone-perception validate: error: --out is required (or --list)", file=sys.stderr)
        return 2
    settings = Settings(**{f.name: getattr(args, f.name) for f in fields(Settings)})
    return run_suite(drives, real, settings, args.out, args.cache, args.seconds, args.fps, not args.no_progress,
                     "cone-perception " + " ".join(sys.argv[1:]))
