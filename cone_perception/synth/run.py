"""The ``cone-perception synth`` run: a synthetic dataset, bag, preview, map check or rendering benchmark
from the parsed options.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from ..data.outfiles import print_written, refuse_existing
from ..errors import ConfigError
from ..geometry.camera import MountPose
from ..synth import mapcheck, writers
from ..synth.config import SynthConfig
from ..synth.scene import random_pose
from ..words import parse_size


def config_from_args(args: argparse.Namespace):
    w, h = parse_size(args.size, "--size", "1920x1080")
    return SynthConfig(
        width=w,
        height=h,
        hfov_deg=args.hfov,
        mount=MountPose(x_m=args.mount_x, height_m=args.height, pitch_deg=args.pitch, roll_deg=args.roll, yaw_deg=args.yaw),
        k1=args.k1,
        k2=args.k2,
        seed=args.seed,
        jitter=not args.no_jitter,
        car_motion=getattr(args, "car_motion", False),
        nose_prob=args.nose_prob,
        photometric=not args.no_photometric,
        track_kinds=tuple(k.strip() for k in args.tracks.split(",") if k.strip()),
        missing_frac=args.missing,
        stray=args.stray,
        knocked_frac=args.knocked,
        vary_mount=getattr(args, "vary_mount", False),
        paint_lines=getattr(args, "paint_lines", "random"),
    )


def run_synth(args: argparse.Namespace) -> int:
    cfg = config_from_args(args)
    if args.action == "dataset":
        c = writers.write_dataset(cfg, args.n, args.out, args.frames_per_track, args.val_frac, progress=not args.no_progress)
        print(f"wrote {c['train']} train + {c['val']} val frames, {c['labels']} YOLO labels, {c['cones']} cones in gt.jsonl -> {args.out}")
    elif args.action == "bag":
        c = writers.write_scene_bag(cfg, args.seconds, args.fps, args.out, args.compressed, args.speed, args.track,
                                    not args.no_progress, args.stand)
        calib, gt = writers.bag_side_paths(Path(args.out))
        print(f"wrote {args.out}: " + ", ".join(f"{t} {k}" for t, k in c.items()) + f"; calibration {calib}; ground truth {gt}")
    elif args.action == "preview":
        refuse_existing([args.out], args.force, "synth preview")
        print_written([writers.write_preview(cfg, args.out, args.n)], "synth preview")
    elif args.action == "mapcheck":
        rows = mapcheck.mapping_check(cfg, args.frames)
        print(f"exact boxes of fully visible cones -> foot-point rule -> H_F_B ({args.frames} frames, "
              f"{cfg.width}x{cfg.height}, jitter {'on' if cfg.jitter else 'off'}): position error in m")
        print("  range      n  median    p95    max")
        for r in rows:
            print(f"  {r['lo_m']:2.0f}-{r['hi_m']:2.0f} m {r['n']:5d} {r['median_m']:7.3f} {r['p95_m']:6.3f} {r['max_m']:6.3f}")
    else:
        return _bench(cfg, args.frames)
    return 0


def _bench(cfg, frames: int) -> int:
    if frames <= 0:
        raise ConfigError("--frames", None, f"must be > 0, got {frames}")
    cfg.validate()
    renderer = cfg.renderer()
    rng = np.random.default_rng(cfg.seed)
    times, looks, n_cones = [], [], 0
    for k in range(frames):
        if k % 10 == 0:
            track = cfg.track(k, rng)
            t0 = time.perf_counter()
            look = renderer.new_look(rng)
            looks.append(time.perf_counter() - t0)
        pose = random_pose(track, rng, cfg.jitter)
        t0 = time.perf_counter()
        _, truths = renderer.render(track, pose, look, rng)
        times.append(time.perf_counter() - t0)
        n_cones += len(truths)
    t = np.array(times)
    print(
        f"synth bench {cfg.width}x{cfg.height}, {frames} frames, photometric {'on' if cfg.photometric else 'off'}: "
        f"{1.0 / t.mean():.1f} frames/s (mean {1e3 * t.mean():.1f} ms, median {1e3 * np.median(t):.1f} ms, "
        f"max {1e3 * t.max():.1f} ms), {n_cones / frames:.1f} visible cones/frame; "
        f"new scene look {1e3 * np.mean(looks):.0f} ms every 10 frames"
    )
    return 0
