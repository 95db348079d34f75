"""``cone-perception bench``: per-stage timings on real-size frames, through the code the nodes run.

  cone-perception bench adapter [--frames 300] [--calib CAL] [--encoding yuv422_yuy2] [--json]

``adapter``: 1920x1080 frames (size from the calibration) in the given encoding -> cropped,
downscaled BGR band, exactly as the ``driver_adapter`` node does it. Warm-up frames are excluded;
median, p90, p99, min-max (noise) and frames/s are reported, plus peak RSS.
"""

from __future__ import annotations

import argparse
import json
import sys

import cv2
import numpy as np

from ..adapter import DriverAdapter, bgr_to_yuyv
from ..benchmark import StageTimer, format_table, peak_rss_mb
from ..calib import DEFAULT_CAMERA, load_calibration
from ..errors import ConfigError

_BYTES_PER_PX = {"yuv422_yuy2": 2, "bgr8": 3, "rgb8": 3}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = "Benchmark per-frame stages on real-size frames (warm-up excluded)."
    p.add_argument("target", choices=["adapter"], help="what to benchmark")
    p.add_argument("--frames", type=int, default=300, help="timed frames (>= 200 recommended; default %(default)s)")
    p.add_argument("--warmup", type=int, default=20, help="untimed warm-up frames (default %(default)s)")
    p.add_argument("--calib", default=DEFAULT_CAMERA, help="calibration (crop, downscale, image size); default %(default)s")
    p.add_argument("--encoding", default="yuv422_yuy2", choices=sorted(_BYTES_PER_PX), help="input encoding")
    p.add_argument("--threads", type=int, default=2, help="OpenCV threads (default %(default)s)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")


def synthetic_frames(width: int, height: int, encoding: str, n: int, seed: int = 0) -> list[bytes]:
    """``n`` distinct raw frames of a smooth random scene in ``encoding`` (bytes, tight step)."""
    rng = np.random.default_rng(seed)
    out = []
    base = cv2.resize(rng.integers(0, 255, (height // 16, width // 16, 3), dtype=np.uint8), (width, height))
    for i in range(n):
        bgr = np.roll(base, 7 * i, axis=1)
        if encoding == "yuv422_yuy2":
            out.append(bgr_to_yuyv(bgr).tobytes())
        elif encoding == "rgb8":
            out.append(bgr[:, :, ::-1].tobytes())
        else:
            out.append(bgr.tobytes())
    return out


def run(args: argparse.Namespace) -> int:
    if args.frames < 1 or args.warmup < 0:
        raise ConfigError("bench", "--frames/--warmup", "need --frames >= 1 and --warmup >= 0")
    cv2.setNumThreads(args.threads)
    calib = load_calibration(args.calib)
    adapter = DriverAdapter(calib.crop, calib.image_width, calib.image_height)
    w, h = calib.image_width, calib.image_height
    step = w * _BYTES_PER_PX[args.encoding]
    frames = synthetic_frames(w, h, args.encoding, 16)
    timer = StageTimer()
    for i in range(args.warmup):
        adapter.from_raw(args.encoding, w, h, step, frames[i % len(frames)])
    for i in range(args.frames):
        with timer("adapter"):
            adapter.from_raw(args.encoding, w, h, step, frames[i % len(frames)])
    s = timer.summary()
    result = {
        "target": args.target,
        "input": f"{w}x{h} {args.encoding}",
        "output": f"{calib.crop.out_width}x{calib.crop.out_height} bgr8",
        "threads": args.threads,
        "fps": 1000.0 / s["adapter"]["median_ms"],
        "stages": s,
        "peak_rss_mb": peak_rss_mb(),
    }
    if args.json:
        json.dump(result, sys.stdout, indent=1)
        print()
        return 0
    print(f"bench {args.target}: {result['input']} -> {result['output']}, {args.frames} frames, {args.threads} threads")
    print(format_table(s))
    print(f"frames/s (median): {result['fps']:.1f}   peak RSS: {result['peak_rss_mb']:.0f} MiB")
    return 0
