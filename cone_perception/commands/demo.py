"""``cone-perception demo``: the main job on a built-in sample (what ``make demo`` runs).

1. renders a seeded synthetic drive (default 10 s at 20 Hz, 1920x1080 YUYV) into a rosbag with
   the true cone positions on ``/cones_gt`` (cached in OUT/ for the same seed and length);
2. plays it through the live ROS 2 pipeline (node processes, shared-memory DDS) with the shipped
   default model and calibration;
3. prints frames, Hz, latency, cones per frame, detection recall and localisation error per
   distance group, and writes OUT/birdseye.png (cones vs truth), OUT/frames.png (annotated
   frames), OUT/summary.json and OUT/summary.md.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np

from ..benchmark import format_table, summarize
from ..calib import DEFAULT_CAMERA, load_calibration, resolve_calibration_path
from ..evaluation import LocalisationReport, format_localisation


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = "The main job on a built-in sample: synthetic drive -> live ROS 2 pipeline -> summary and pictures."
    p.add_argument("--out", type=Path, default=Path("demo_out"), help="output folder (default %(default)s)")
    p.add_argument("--seed", type=int, default=2026, help="scene seed (default %(default)s)")
    p.add_argument("--seconds", type=float, default=10.0, help="length of the drive (default %(default)s)")
    p.add_argument("--fps", type=float, default=20.0, help="camera rate (default %(default)s)")
    p.add_argument("--speed", type=float, default=8.0, help="car speed in m/s (default %(default)s)")
    p.add_argument("--jitter", action=argparse.BooleanOptionalAction, default=True,
                   help="suspension pitch/roll jitter of about +-1 deg (default on: the real error source)")
    p.add_argument("--mode", choices=["fused", "separate"], default="fused",
                   help="one pipeline node, or driver_adapter + detection + mapping (default %(default)s)")
    p.add_argument("--calib", default=DEFAULT_CAMERA, help="calibration (default: shipped %(default)s)")
    p.add_argument("--model", default=None, help="model file (default: the shipped default model)")
    p.add_argument("--offline", action="store_true", help="replay offline (no ROS processes) instead of live")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def _bag(args) -> tuple[Path, Path]:
    from ..synth.outputs import SynthConfig, bag_side_paths, write_scene_bag

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


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from ..detector import default_model_path
    from ..replay import find_image_topic, read_ground_truth

    calib = load_calibration(args.calib)
    model = Path(args.model) if args.model else default_model_path()
    if not model.is_file():
        from ..checkpoint import RESTORE_HINT
        from ..errors import ConfigError

        raise ConfigError(str(model), None, f"model file not found; {RESTORE_HINT}")
    args.out.mkdir(parents=True, exist_ok=True)
    bag, _ = _bag(args)
    truth = read_ground_truth(bag, "/cones_gt")
    progress = lambda it, total: tqdm(it, total=total, unit="frame", disable=args.no_progress, file=sys.stderr)  # noqa: E731

    if args.offline:
        print("[2/3] offline replay through the pipeline code (no ROS processes)")
        from ..detector import Detector
        from ..pipeline import Pipeline
        from ..replay import offline_replay

        det = Detector.load(model)
        det.warmup()
        res = offline_replay(bag, Pipeline(calib, det), progress=progress)
        cones, boxes, wall = res.cones, res.boxes, res.wall_s
        latency = res.timer.summary().get("end_to_end", {"n": 0})
        sent, lost = res.stats.ok + res.stats.dropped_total, res.stats.dropped_total
        how = "offline"
    else:
        print(f"[2/3] live ROS 2 replay: {args.mode} node(s), shared-memory DDS, lockstep")
        from ..nodes.live_replay import live_replay

        params = {"calibration": str(resolve_calibration_path(args.calib)), "model": str(model.resolve())}
        res = live_replay(bag, mode=args.mode, params=params, progress=progress)
        cones, boxes, wall = res.cones, res.boxes, res.wall_s
        latency = summarize([v / 1e3 for v in res.latency_ms.values()])
        sent, lost = res.sent, len(res.lost)
        how = f"live {args.mode}"

    from ..mapping import ConeMapper

    rep, mapper = LocalisationReport(max_range_m=calib.max_range_m), ConeMapper(calib)
    for stamp in sorted(cones):
        if stamp in truth:
            rep.add_frame(cones[stamp], expected_truth(truth[stamp], calib, mapper))
    loc = rep.summary()
    n = len(cones)
    per_frame = np.array([len(c) for c in cones.values()]) if cones else np.zeros(1)
    print("[3/3] summary")
    print(f"  drive: seed {args.seed}, {args.seconds:g} s at {args.fps:g} Hz, jitter {'on' if args.jitter else 'off'}; "
          f"model {model.name}; calibration {calib.camera}; {how}")
    print(f"  frames: {sent} sent, {n} with /cones, {lost} lost; {n / wall if wall else 0:.1f} frames/s; "
          f"cones per frame: mean {per_frame.mean():.1f}, max {per_frame.max()}")
    print(format_table({"latency": latency}))
    print(format_localisation(loc))

    from ..vis import birdseye_plot

    stamps = sorted(cones)
    picks = [stamps[int(i)] for i in np.linspace(0, len(stamps) - 1, 4)] if stamps else []
    panels = [(f"t = {(s - stamps[0]) / 1e9:.2f} s", cones[s], truth.get(s)) for s in picks]
    be = birdseye_plot(panels, args.out / "birdseye.png", x_max_m=calib.max_range_m)
    fr = _frames_png(bag, boxes, picks, calib, args.out / "frames.png", truth, stamps[0] if stamps else None)
    summary = {"drive": {"seed": args.seed, "seconds": args.seconds, "fps": args.fps, "jitter": args.jitter},
               "mode": how, "model": str(model), "calibration": calib.source, "frames_sent": sent,
               "frames_with_cones": n, "lost": lost, "fps": n / wall if wall else 0.0, "latency_ms": latency,
               "cones_per_frame_mean": float(per_frame.mean()), "localisation": loc}
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    (args.out / "summary.md").write_text(
        f"# cone_perception demo\n\n{how}, seed {args.seed}\n\n```\n{format_table({'latency': latency})}\n\n"
        f"{format_localisation(loc)}\n```\n\n![bird's-eye]({be.name})\n\n![frames]({fr.name})\n")
    print(f"  wrote {be}, {fr}, {args.out / 'summary.json'}, {args.out / 'summary.md'}")
    return 0


def expected_truth(truth: np.ndarray, calib, mapper=None) -> np.ndarray:
    """True cones a detector is expected to find: at least half visible (``score`` of ``/cones_gt``
    holds the visible fraction) and standing inside the camera's band and range.
    ``mapper``: the calibration's :class:`~cone_perception.mapping.ConeMapper`, if already built."""
    from ..mapping import ConeMapper

    keep = truth["score"] >= 0.5
    uv = (mapper or ConeMapper(calib)).ground_to_pixels(np.c_[truth["x"], truth["y"]])
    c = calib.crop
    inside = (uv[:, 0] >= c.u0) & (uv[:, 0] < c.u1) & (uv[:, 1] >= c.v0) & (uv[:, 1] < c.v1)
    return truth[keep & inside & (np.hypot(truth["x"], truth["y"]) <= calib.max_range_m)]


def _frames_png(bag: Path, boxes: dict, stamps: list[int], calib, path: Path, truth: dict | None = None,
                t0_ns: int | None = None) -> Path:
    """The picked frames in a 2-column grid: detections (class colour, score), the true cones' foot points
    (class-coloured rings, from ``/cones_gt`` through the calibration), the band, a time stamp per tile and
    a legend strip below."""
    import cv2

    from ..classes import CLASS_BGR
    from ..mapping import ConeMapper
    from ..replay import find_image_topic, frame_bgr, iter_frames
    from ..vis import draw_boxes, frame_strip, legend_strip, outlined_text

    topic, _ = find_image_topic(bag)
    mapper = ConeMapper(calib)
    want, imgs = set(stamps), []
    t0 = stamps[0] if t0_ns is None and stamps else t0_ns
    for f in iter_frames(bag, topic):
        if f.stamp_ns in want and f.msg is not None:
            bgr = frame_bgr(f)
            k = max(1, bgr.shape[1] // 960)  # line and font size for a tile shown at 960 px
            img = draw_boxes(bgr, boxes.get(f.stamp_ns, np.zeros(0)), thickness=k + 1, font_scale=0.45 * k,
                             min_label_height=14 * k)
            t = (truth or {}).get(f.stamp_ns)
            if t is not None and len(t):
                t = t[t["score"] >= 0.5]  # at least half visible (score of /cones_gt: the visible fraction)
                uv = mapper.ground_to_pixels(np.c_[t["x"], t["y"]])
                for (u, v), c in zip(uv, t["class_id"]):
                    if np.isfinite(u) and np.isfinite(v) and 0 <= u < img.shape[1] and 0 <= v < img.shape[0]:
                        cv2.circle(img, (int(round(u)), int(round(v))), 5 * k, (0, 0, 0), 3 * k, cv2.LINE_AA)
                        cv2.circle(img, (int(round(u)), int(round(v))), 5 * k, CLASS_BGR[int(c)], k, cv2.LINE_AA)
            c = calib.crop
            cv2.rectangle(img, (c.u0, c.v0), (c.u1 - 1, c.v1 - 1), (255, 255, 255), k)
            n = len(boxes.get(f.stamp_ns, ()))
            outlined_text(img, f"t = {(f.stamp_ns - t0) / 1e9:.2f} s   {n} detection{'s' if n != 1 else ''}",
                          (12 * k, 34 * k), (255, 255, 255), 0.9 * k, 2 * k)
            imgs.append(img)
    if not imgs:
        cv2.imwrite(str(path), np.zeros((8, 8, 3), np.uint8))
        return path
    grid = frame_strip(imgs, width=960, cols=2)
    legend = legend_strip(grid.shape[1], [
        ("box + class score: detection (score shown on boxes >= 14 px tall at 960 px)", (230, 230, 230)),
        ("ring: foot point of a true cone at least half visible (/cones_gt)", (230, 230, 230)),
        ("white frame: the band fed to the detector", (255, 255, 255)),
        *[(name.replace("_", " "), CLASS_BGR[i]) for i, name in enumerate(("blue", "yellow", "orange", "large_orange"))],
    ])
    cv2.imwrite(str(path), np.vstack([grid, legend]))
    return path
