"""``cone-perception bench``: per-stage timings on real-size frames, through the code the nodes run.

  cone-perception bench adapter  [--frames 300] [--calib CAL] [--encoding yuv422_yuy2] [--json]
  cone-perception bench pipeline [--frames 300] [--calib CAL] [--model M] [--backend B] [--threads N] [--json]

``adapter``: 1920x1080 frames (size from the calibration) in the given encoding -> cropped,
downscaled BGR band, exactly as the ``driver_adapter`` node does it.
``pipeline``: rendered 1920x1080 YUYV scenes with cones through the fused pipeline (adapter,
model input, forward, decode + NMS, mapping) and the packing of ``cone_boxes`` and ``/cones``
into PointCloud2 messages, as the ``pipeline`` node runs them.
Warm-up frames are excluded; median, p90, p99, min-max (noise) and frames/s (from the median
end-to-end time) are reported, plus peak RSS.
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
    p.add_argument("target", choices=["adapter", "pipeline"], help="what to benchmark")
    p.add_argument("--frames", type=int, default=300, help="timed frames (>= 200 recommended; default %(default)s)")
    p.add_argument("--warmup", type=int, default=20, help="untimed warm-up frames (default %(default)s)")
    p.add_argument("--calib", default=DEFAULT_CAMERA, help="calibration (crop, downscale, image size); default %(default)s")
    p.add_argument("--encoding", default="yuv422_yuy2", choices=sorted(_BYTES_PER_PX), help="input encoding")
    p.add_argument("--threads", type=int, default=2, help="OpenCV, torch and ONNX Runtime threads (default %(default)s)")
    p.add_argument("--model", default=None, help="pipeline: model file (default: the shipped default model)")
    p.add_argument("--backend", default="torch", choices=["torch", "torchscript", "onnx"], help="pipeline: inference backend")
    p.add_argument("--scenes", type=int, default=16, help="pipeline: distinct rendered scenes, cycled (default %(default)s)")
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


def rendered_frames(calib, n: int, seed: int = 4242) -> list[bytes]:
    """``n`` YUYV frames of rendered scenes with cones, at the calibration's image size."""
    from ..synth.outputs import SynthConfig
    from ..synth.scene import random_pose

    cfg = SynthConfig(width=calib.image_width, height=calib.image_height, seed=seed, jitter=False)
    renderer, rng = cfg.renderer(), np.random.default_rng(seed)
    out = []
    for i in range(n):
        if i % 8 == 0:
            track, look = cfg.track(i, rng), renderer.new_look(rng)
        img, _ = renderer.render(track, random_pose(track, rng, False), look, rng)
        out.append(bgr_to_yuyv(img).tobytes())
    return out


def _bench_pipeline(args: argparse.Namespace, calib) -> dict:
    import time

    from .. import bagio
    from ..detector import Detector, default_model_path
    from ..pipeline import Pipeline
    from ..records import to_pointcloud2

    det = Detector.load(args.model or default_model_path(), backend=args.backend, threads=args.threads)
    pipe = Pipeline(calib, det)
    w, h = calib.image_width, calib.image_height
    frames = rendered_frames(calib, max(1, args.scenes))
    timer = StageTimer()
    n_boxes = 0
    for i in range(args.warmup + args.frames):
        data = frames[i % len(frames)]
        t0 = time.perf_counter()
        res = pipe.process_raw("yuv422_yuy2", w, h, 2 * w, data)
        t1 = time.perf_counter()
        hdr = bagio.header(i, "camera")
        to_pointcloud2(res.boxes, hdr, bagio.PointCloud2, bagio.PointField)
        to_pointcloud2(res.cones, bagio.header(i, calib.frame_id), bagio.PointCloud2, bagio.PointField)
        t2 = time.perf_counter()
        if i < args.warmup:
            continue
        for k, v in res.timing_ms.items():
            timer.add(k, v / 1e3)
        timer.add("packing", t2 - t1)
        timer.add("end_to_end", t2 - t0)
        n_boxes += len(res.boxes)
    s = timer.summary()
    return {
        "target": "pipeline",
        "input": f"{w}x{h} yuv422_yuy2 (rendered scenes)",
        "output": f"band {calib.crop.out_width}x{calib.crop.out_height}, boxes + cones",
        "model": det.source,
        "backend": args.backend,
        "threads": args.threads,
        "fps": 1000.0 / s["end_to_end"]["median_ms"],
        "boxes_per_frame": n_boxes / args.frames,
        "non_forward_median_ms": s["end_to_end"]["median_ms"] - s["forward"]["median_ms"],
        "stages": s,
        "peak_rss_mb": peak_rss_mb(),
    }


def run(args: argparse.Namespace) -> int:
    if args.frames < 1 or args.warmup < 0:
        raise ConfigError("bench", "--frames/--warmup", "need --frames >= 1 and --warmup >= 0")
    cv2.setNumThreads(args.threads)
    calib = load_calibration(args.calib)
    if args.target == "pipeline":
        result = _bench_pipeline(args, calib)
        if args.json:
            json.dump(result, sys.stdout, indent=1)
            print()
            return 0
        print(f"bench pipeline: {result['input']} -> {result['output']}; model {result['model']} "
              f"({result['backend']}, {result['threads']} threads), {args.frames} frames, "
              f"{result['boxes_per_frame']:.1f} boxes/frame")
        print(format_table(result["stages"]))
        print(f"frames/s (median end to end): {result['fps']:.1f}   everything but the forward: "
              f"{result['non_forward_median_ms']:.2f} ms   peak RSS: {result['peak_rss_mb']:.0f} MiB")
        return 0
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
