"""``cone-perception validate``: the pipeline's settings judged on the validation suite (docs/validation.md).

  cone-perception validate --out DIR [--quick | --drives NAME,...] [--tuning] [--cache DIR] [pipeline settings]
  cone-perception validate --list [--tuning]

A fixed list of rendered drives (their seeds are the judging seeds: tune on ``--tuning``'s) and the real labelled
sets, each replayed as the node runs it; one row per drive, the median, worst tenth and worst over the drives,
a picture of the spread. Exit 1 when a drive failed (after the others ran).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import fields
from pathlib import Path

from ..attitude import ATTITUDE_MODES
from ..detector import BACKEND_CHOICES, DEFAULT_BACKEND, RUNTIME_THREADS
from ..params import DEFAULT_CONF, PARAMS
from ..replay.suite import Settings, run_suite, select
from ..replay.suite_drives import FPS, SECONDS
from ._args import add_far_box_model, add_far_model, add_far_verifier


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
    g = p.add_argument_group("the pipeline settings judged (as `replay`; defaults: the node's)")
    g.add_argument("--model", default=None, help="the band's model file (default: the shipped model)")
    g.add_argument("--backend", default=DEFAULT_BACKEND, choices=BACKEND_CHOICES, help="default %(default)s")
    g.add_argument("--conf", type=float, default=DEFAULT_CONF, help="confidence threshold (default %(default)s)")
    g.add_argument("--threads", type=int, default=RUNTIME_THREADS, help="network threads (default %(default)s)")
    g.add_argument("--far-rows", default=None, metavar="auto|none|V0,V1", help="the far strip (replay --far-rows)")
    add_far_model(g)
    add_far_verifier(g)
    add_far_box_model(g)
    g.add_argument("--far-every", type=int, default=PARAMS["far_every"].default, metavar="N", help="replay --far-every")
    g.add_argument("--far-tiles", type=int, default=PARAMS["far_tiles"].default, metavar="W", help="replay --far-tiles")
    g.add_argument("--band-rows", default=None, metavar="crop|auto|V0,V1", help="replay --band-rows")
    g.add_argument("--attitude", choices=ATTITUDE_MODES, default="image", help="default %(default)s (the node's)")
    g.add_argument("--box-model", choices=("auto", "model", "rendered"), default="auto", help="replay --box-model")
    g.add_argument("--box-behaviour", choices=("as-is", "real"), default="as-is", help="replay --box-behaviour")
    g.add_argument("--min-height-ratio", type=float, default=PARAMS["min_height_ratio"].default, metavar="R",
                   help="replay --min-height-ratio")
    g.add_argument("--one-ray-range", type=float, default=PARAMS["one_ray_range_m"].default, metavar="M",
                   help="replay --one-ray-range")


def run(args: argparse.Namespace) -> int:
    drives, real = select(args.drives, args.quick, args.tuning)
    if args.list:
        for d in drives:
            print(f"{d.name:<22} seed {d.seed:<7} {d.describe()}  ({d.note})")
        for r in real:
            print(f"{r.name:<22} real   {r.path}: band rows {r.crop[0]}-{r.crop[1]} / {r.downscale}, far rows {r.far_rows}")
        return 0
    if args.out is None:
        print("cone-perception validate: error: --out is required (or --list)", file=sys.stderr)
        return 2
    settings = Settings(**{f.name: getattr(args, f.name) for f in fields(Settings)})
    return run_suite(drives, real, settings, args.out, args.cache, args.seconds, args.fps, not args.no_progress,
                     "cone-perception " + " ".join(sys.argv[1:]))
