"""The ``cone-perception soak`` run: a synthetic drive played at a rate into a live node for a while
(the player: :mod:`cone_perception.rostools.soak`), its figures per window against the targets
(:mod:`cone_perception.bench.soak`).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

from tqdm import tqdm

from ..bench import soak as core
from ..data.outfiles import print_written, refuse_existing
from ..errors import ConfigError


#: The soak's own ROS_DOMAIN_IDs: apart from the test runs' 100-199 (tests/conftest.py), so a soak never sees a test's nodes.
SOAK_DOMAINS = range(200, 233)


def default_domain_id(pid: int) -> int:
    """The soak's ROS_DOMAIN_ID without ``--domain-id``: one of :data:`SOAK_DOMAINS`, from the process id."""
    return SOAK_DOMAINS[pid % len(SOAK_DOMAINS)]


def run_soak(args: argparse.Namespace) -> int:
    if not args.rate > 0 or not args.seconds > 0 or not args.window > 0:
        raise ConfigError("soak", None, "--rate, --seconds and --window must be > 0")
    if args.domain_id is not None and not 0 <= args.domain_id <= 232:
        raise ConfigError("--domain-id", None, f"must be within 0-232, got {args.domain_id}")
    outs = [p for p in (args.json, args.plot) if p]
    refuse_existing(outs, args.force, "soak")
    for p in args.param:
        if ":=" not in p:
            raise ConfigError("--param", None, f"expected NAME:=VALUE, got {p!r}")
    os.environ["ROS_DOMAIN_ID"] = str(args.domain_id if args.domain_id is not None else default_domain_id(os.getpid()))

    from ..rostools import soak as player  # rclpy and the localhost DDS environment: on use only

    tmp = Path(tempfile.mkdtemp(prefix="cone_perception_soak_"))
    try:
        frames, compressed, topic, calib = player.drive_frames(args.bag, args.topic, tmp, args.drive_seconds, args.seed,
                                                               args.calib, not args.no_progress)
        node_args = []
        for k, v in (("calibration", calib), ("model", args.model)):
            if v:
                node_args += ["-p", f"{k}:={Path(v).resolve() if Path(v).exists() else v}"]
        for p in args.param:
            node_args += ["-p", p]
        if compressed:
            node_args += ["-p", "input_transport:=compressed", "-r", f"image_raw/compressed:={topic}"]
        else:
            node_args += ["-r", f"image_raw:={topic}"]
        print(f"soak: {len(frames)} frames looped at {args.rate:g} Hz for {args.seconds:g} s into a pipeline node "
              f"(ROS_DOMAIN_ID {os.environ['ROS_DOMAIN_ID']}, localhost)", file=sys.stderr)
        bar = tqdm(total=round(args.seconds), unit="s", desc="soak", file=sys.stderr, disable=args.no_progress)

        def progress(t: float) -> None:
            bar.update(max(0, round(t) - bar.n))

        res = player.soak(frames, compressed, topic, args.rate, args.seconds, node_args, window_s=args.window,
                   progress=progress)
        bar.close()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    r = core.summarize(res.sent, res.base, res.final, topic, res.windows, args.window, args.rate, args.seconds,
                       res.wall_s, res.cones, res.died)
    print(core.format_report(r))
    if res.died is not None:
        print(f"soak: the node exited with code {res.died}:\n{res.node_output[-3000:]}", file=sys.stderr)
    if args.json:
        args.json.write_text(json.dumps(core.to_json(r), indent=1))
    if args.plot:
        core.plot(r, args.plot)
    if outs:
        print_written(outs, "soak")
    return 0 if r["passed"] else 1
