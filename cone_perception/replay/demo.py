"""The ``cone-perception demo`` run: a synthetic drive through the live ROS 2 pipeline, then the summary and
its pictures.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..attitude.box_files import attitude_config_for
from ..data.bags import read_ground_truth
from ..resources import far_model_for
from ..detector import Detector, default_model_path
from ..detector.farband import FarBand
from ..detector.verifier import load_verifier
from ..errors import ConfigError
from ..evaluation import LocalisationReport, format_localisation
from ..evaluation.plots import bag_frames_picture
from ..geometry.calib import load_calibration, resolve_calibration_path
from ..mapping import ConeMapper, expected_truth
from ..model.checkpoint import RESTORE_HINT
from ..pipeline import Pipeline
from ..replay import offline_replay
from ..synth.config import SynthConfig
from ..synth.writers import bag_side_paths, write_scene_bag
from ..timing import format_table, summarize
from ..vis import birdseye_plot

#: How the image attitude reads the demo's boxes (``box_model``, the same for the nodes and ``--offline``): the
#: rendered tables. The demo's frames are rendered, but it maps them with a shipped calibration (camera
#: ``example_mainhoop``, the rendering camera's geometry), for which ``auto`` would pick the box models measured on
#: real frames: their corrections (tops 1-7 % low) tilt the image attitude on rendered boxes (docs/benchmarks.md,
#: "make demo: rendered frames through the rendered tables").
DEMO_BOX_MODEL = "rendered"


def node_params(calib: str, model: Path) -> dict[str, object]:
    """The parameters the demo gives its nodes: the calibration ``calib`` (a file or shipped camera name), the
    model file ``model`` and ``box_model`` :data:`DEMO_BOX_MODEL`; the rest are the nodes' defaults."""
    return {"calibration": str(resolve_calibration_path(calib)), "model": str(Path(model).resolve()),
            "box_model": DEMO_BOX_MODEL}


def offline_attitude_config(model: Path, far_model: Path | None, calib):
    """``(ImageAttitudeConfig, in words)`` of ``--offline``: as the pipeline node builds it from
    :func:`node_params` (``box_model`` :data:`DEMO_BOX_MODEL`) with the far strip's model ``far_model``
    (None: no strip)."""
    return attitude_config_for(DEMO_BOX_MODEL, model, far_model, calib.camera == "synth")


def _bag(args) -> tuple[Path, Path]:
    name = f"drive_seed{args.seed}_{args.seconds:g}s_{args.fps:g}hz{'' if args.jitter else '_nojitter'}"
    bag = args.out / name
    if not (bag / "metadata.yaml").is_file():
        for p in (bag, *bag_side_paths(bag)):
            if p.is_dir():
                shutil.rmtree(p)
            elif p.exists():
                p.unlink()
        print(f"[1/3] rendering {args.seconds:g} s at {args.fps:g} Hz (seed {args.seed}) -> {bag}")
        write_scene_bag(SynthConfig(seed=args.seed, jitter=args.jitter), args.seconds, args.fps, bag,
                        speed_mps=args.speed, progress=not args.no_progress)
    else:
        print(f"[1/3] using the cached drive {bag}")
    return bag, bag_side_paths(bag)[0]


def run_demo(args: argparse.Namespace) -> int:
    calib = load_calibration(args.calib)
    model = Path(args.model) if args.model else default_model_path()
    if not model.is_file():
        raise ConfigError(str(model), None, f"model file not found; {RESTORE_HINT}")
    args.out.mkdir(parents=True, exist_ok=True)
    bag, _ = _bag(args)
    truth = read_ground_truth(bag, "/cones_gt")
    progress = lambda it, total: tqdm(it, total=total, unit="frame", disable=args.no_progress, file=sys.stderr)  # noqa: E731

    if args.offline:
        print("[2/3] offline replay through the pipeline code (no ROS processes)")

        det = Detector.load(model)
        det.warmup()
        far_model = far_model_for(None, model)
        far = FarBand.for_calibration(far_model, None, calib, say=lambda t: print(f"  {t}"),  # as the node: the strip
                                      verifier=load_verifier(None))
        att_cfg, _ = offline_attitude_config(model, far_model if far else None, calib)  # as the nodes' box_model
        res = offline_replay(bag, Pipeline(calib, det, far=far, attitude_config=att_cfg), progress=progress)
        cones, boxes, wall = res.cones, res.boxes, res.wall_s
        latency = res.timer.summary().get("end_to_end", {"n": 0})
        sent, lost = res.stats.ok + res.stats.dropped_total, res.stats.dropped_total
        how = "offline"
    else:
        print(f"[2/3] live ROS 2 replay: {args.mode} node(s), shared-memory DDS, lockstep")
        from ..rostools.live_replay import live_replay  # rclpy, and it sets the DDS environment

        res = live_replay(bag, mode=args.mode, params=node_params(args.calib, model), progress=progress)
        cones, boxes, wall = res.cones, res.boxes, res.wall_s
        latency = summarize([v / 1e3 for v in res.latency_ms.values()])
        sent, lost = res.sent, len(res.lost)
        how = f"live {args.mode}"

    rep, mapper = LocalisationReport(max_range_m=calib.max_range_m), ConeMapper(calib)
    for stamp in sorted(cones):
        if stamp in truth:
            rep.add_frame(cones[stamp], expected_truth(truth[stamp], calib, mapper))
    loc = rep.summary()
    n = len(cones)
    per_frame = np.array([len(c) for c in cones.values()]) if cones else np.zeros(1)
    print("[3/3] summary")
    print(f"  drive: seed {args.seed}, {args.seconds:g} s at {args.fps:g} Hz, jitter {'on' if args.jitter else 'off'}; "
          f"model {model.name}; calibration {calib.camera}; box model {DEMO_BOX_MODEL} (rendered frames); {how}")
    print(f"  frames: {sent} sent, {n} with /cones, {lost} lost; {n / wall if wall else 0:.1f} frames/s; "
          f"cones per frame: mean {per_frame.mean():.1f}, max {per_frame.max()}")
    print(format_table({"latency": latency}))
    print(format_localisation(loc))

    stamps = sorted(cones)
    picks = [stamps[int(i)] for i in np.linspace(0, len(stamps) - 1, 4)] if stamps else []
    panels = [(f"t = {(s - stamps[0]) / 1e9:.2f} s", cones[s], truth.get(s)) for s in picks]
    be = birdseye_plot(panels, args.out / "birdseye.png", x_max_m=calib.max_range_m)
    fr = bag_frames_picture(bag, boxes, picks, calib, args.out / "frames.png", truth, stamps[0] if stamps else None)
    summary = {"drive": {"seed": args.seed, "seconds": args.seconds, "fps": args.fps, "jitter": args.jitter},
               "mode": how, "model": str(model), "calibration": calib.source, "box_model": DEMO_BOX_MODEL,
               "frames_sent": sent,
               "frames_with_cones": n, "lost": lost, "fps": n / wall if wall else 0.0, "latency_ms": latency,
               "cones_per_frame_mean": float(per_frame.mean()), "localisation": loc}
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    (args.out / "summary.md").write_text(
        f"# cone_perception demo\n\n{how}, seed {args.seed}\n\n```\n{format_table({'latency': latency})}\n\n"
        f"{format_localisation(loc)}\n```\n\n![bird's-eye]({be.name})\n\n![frames]({fr.name})\n")
    print(f"  wrote {be}, {fr}, {args.out / 'summary.json'}, {args.out / 'summary.md'}")
    return 0
