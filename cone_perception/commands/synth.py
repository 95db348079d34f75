"""``cone-perception synth``: synthetic FS scenes with exact ground truth.

Actions: ``dataset`` (images + YOLO labels + gt.jsonl + calib.yaml), ``bag``
(rosbag2 MCAP with camera images and /cones_gt), ``preview`` (contact sheet
PNG), ``mapcheck`` (mapping error with perfect boxes), ``bench`` (render speed).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


def _common(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("camera and scene")
    g.add_argument("--seed", type=int, default=0, help="random seed: same seed, same output (default 0)")
    g.add_argument("--size", default="1920x1080", help="image size WxH in px (default 1920x1080)")
    g.add_argument("--hfov", type=float, default=90.0, help="horizontal field of view in degrees (default 90)")
    g.add_argument("--mount-x", type=float, default=0.5, help="camera x ahead of the rear axle in m (default 0.5)")
    g.add_argument("--height", type=float, default=1.2, help="camera height above ground in m (default 1.2)")
    g.add_argument("--pitch", type=float, default=10.0, help="camera pitch in degrees, positive looks down (default 10)")
    g.add_argument("--roll", type=float, default=0.0, help="camera roll in degrees (default 0)")
    g.add_argument("--yaw", type=float, default=0.0, help="camera yaw in degrees, positive looks left (default 0)")
    g.add_argument("--k1", type=float, default=0.0, help="radial distortion k1 (OpenCV model, default 0 = ideal pinhole)")
    g.add_argument("--k2", type=float, default=0.0, help="radial distortion k2 (default 0)")
    g.add_argument("--no-jitter", action="store_true", help="switch off the +-1 degree body pitch/roll jitter")
    g.add_argument("--car-motion", action="store_true",
                   help="bag: the car moves like a car: speed profile with braking / acceleration pitch (up to +-2 deg), "
                        "cornering roll, bumps, grade changes of the road ahead (up to 2 %%); on top of the jitter")
    g.add_argument("--nose-prob", type=float, default=0.5, help="chance a scene shows the car nose at the bottom (default 0.5)")
    g.add_argument("--no-photometric", action="store_true", help="no exposure / white balance / noise / blur / JPEG randomisation")
    g.add_argument(
        "--tracks", default="autocross,skidpad,acceleration", help="comma-separated track kinds to draw from (default all three)"
    )
    g.add_argument("--missing", type=float, default=0.0, help="fraction of cones removed from each track (default 0)")
    g.add_argument("--stray", type=int, default=0, help="stray cones placed off the track per track (default 0)")
    g.add_argument("--knocked", type=float, default=0.0, help="fraction of cones knocked over, lying on their side (default 0)")
    p.add_argument("--no-progress", "--quiet", dest="no_progress", action="store_true",
                   help="no progress bar (--quiet: the same, kept for old scripts)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    p = sub.add_parser("dataset", help="images + YOLO labels + data.yaml + gt.jsonl + calib.yaml")
    p.add_argument("--n", type=int, required=True, help="number of frames")
    p.add_argument("--out", type=Path, required=True, help="output directory (new or empty)")
    p.add_argument("--frames-per-track", type=int, default=20, help="frames per random track and look (default 20)")
    p.add_argument("--val-frac", type=float, default=0.1, help="fraction of tracks in the val split (default 0.1; at least one track when there are two or more; "
                        "frames of one track only: no val split, data.yaml without val:)")
    p.add_argument(
        "--vary-mount",
        action="store_true",
        help="new random viewpoint per track (hfov 70-120, pitch -4..+16 deg around --pitch, height +-0.3 m) for detector training; "
        "calib.yaml then holds the nominal mount only, each gt.jsonl line its own camera",
    )
    _common(p)
    p = sub.add_parser("bag", help="rosbag2 (MCAP): camera images + /cones_gt, calibration YAML beside it")
    p.add_argument("--seconds", type=float, required=True, help="length of the recording in s")
    p.add_argument("--fps", type=float, default=20.0, help="frame rate in Hz (default 20)")
    p.add_argument("--out", type=Path, required=True, help="bag directory to create (must not exist)")
    p.add_argument("--compressed", action="store_true", help="JPEG CompressedImage on /camera/image_raw/compressed instead of YUYV")
    p.add_argument("--speed", type=float, default=8.0, help="car speed along the centre line in m/s (default 8)")
    p.add_argument("--stand", type=float, default=0.0, metavar="S",
                   help="begin with S seconds of /imu alone, the car standing still (for `cone-perception imu-rest BAG "
                        "--seconds S`; default 0)")
    p.add_argument("--track", default="autocross", help="track kind: autocross, skidpad, acceleration (default autocross)")
    _common(p)
    p = sub.add_parser("preview", help="contact sheet PNG of sample frames with ground-truth boxes")
    p.add_argument("--out", type=Path, required=True, help="PNG file to write")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out")
    p.add_argument("--n", type=int, default=8, help="number of frames (default 8)")
    _common(p)
    p = sub.add_parser(
        "mapcheck", help="map exact boxes through the exact calibration: error left by the foot-point rule and jitter"
    )
    p.add_argument("--frames", type=int, default=30, help="frames to render (default 30)")
    _common(p)
    p = sub.add_parser("bench", help="measure render speed (frames/s) at the given size")
    p.add_argument("--frames", type=int, default=30, help="frames to time (default 30)")
    _common(p)


def config_from_args(args: argparse.Namespace):
    from ..geometry.camera import MountPose
    from ..synth.config import SynthConfig
    from ._args import parse_size

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
    )


def run(args: argparse.Namespace) -> int:
    from ..synth import mapcheck, writers

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
        from ..data.outfiles import print_written, refuse_existing

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
    from ..errors import ConfigError
    from ..synth.scene import random_pose

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
