"""Tracker settings for far cones (issue 26, item 3) on synthetic drives: one detector pass, many trackers.

    .venv/bin/python docs/experiments/weak_confirm.py [--far-rows auto|off|384,576] [--only TEXT] BAG [BAG ...]

Each BAG is a `cone-perception synth bag` drive (BAG_calib.yaml, BAG_gt.jsonl beside it). The pipeline
(default model, attitude as `replay`'s default, the calibration's range raised to 40 m) runs once per
bag at score 0.1, split at 0.25 (FrameResult.weak_cones); then each tracker design below gets the same
frames (only /cones, or /cones + the weak ones; `--only TEXT`: the designs whose name holds TEXT) and is scored as `replay --track --gt-topic` scores
/cones/tracked (DriveEvaluation). Prints one markdown row per design and bag: recall per range band
(cones >= half visible) / false cones per frame in the band, and false cones per frame within 40 m.
"""
import argparse
from dataclasses import replace

import numpy as np

from cone_perception.attitude import ImuAttitude
from cone_perception.data.bags import find_image_topic, iter_frames, read_imu
from cone_perception.detector import Detector, default_model_path
from cone_perception.detector.farband import FarBand
from cone_perception.evaluation.tracking import DriveEvaluation, load_drive_truth
from cone_perception.geometry.calib import load_calibration
from cone_perception.pipeline import Pipeline
from cone_perception.replay.offline import process_frame
from cone_perception.tracking import TrackerConfig, TrackingStage

DESIGNS = {
    "tracker as shipped (20 m)": (False, {}),
    "range 40 m": (False, {"max_range_m": 40.0}),
    "range 40 m + weak 0.10-0.25": (True, {"max_range_m": 40.0, "strong_score": 0.25}),
    "range 40 m + weak < 0.45 (score_neutral)": (True, {"max_range_m": 40.0, "strong_score": 0.45}),
    "range 40 m + weak < 0.45, ratio 1.6": (True, {"max_range_m": 40.0, "strong_score": 0.45, "weak_likelihood_ratio": 1.6}),
    "(diagnosis) range 40 m, publish from certainty 0.2": (False, {"max_range_m": 40.0, "publish_min_certainty": 0.2}),
    "(diagnosis) range 40 m, miss ratio 0.8": (False, {"max_range_m": 40.0, "miss_likelihood_ratio": 0.8}),
    "range 40 m, spawn_max_m 2": (False, {"max_range_m": 40.0, "spawn_max_m": 2.0}),
    "range 40 m, spawn_max_m 1": (False, {"max_range_m": 40.0, "spawn_max_m": 1.0}),
    "range 40 m, spawn_max_m 3": (False, {"max_range_m": 40.0, "spawn_max_m": 3.0}),
    "range 40 m, spawn_max_m 2, min_hits 2": (False, {"max_range_m": 40.0, "spawn_max_m": 2.0, "min_hits": 2}),
    "range 40 m, spawn_max_m 2 + weak 0.10-0.25": (True, {"max_range_m": 40.0, "spawn_max_m": 2.0, "strong_score": 0.25}),
    "range 40 m, spawn_max_m 2 + weak < 0.45": (True, {"max_range_m": 40.0, "spawn_max_m": 2.0, "strong_score": 0.45}),
    # issue 26e: no range of the tracker's own (the calibration's, 40 m here)
    "calib range, spawn_max_m 2": (False, {"max_range_m": float("inf"), "spawn_max_m": 2.0}),
    "calib range, spawn_max_m 2.5": (False, {"max_range_m": float("inf"), "spawn_max_m": 2.5}),
    "calib range, spawn_max_m 1.75": (False, {"max_range_m": float("inf"), "spawn_max_m": 1.75}),
    "calib range, spawn_max_m 2.25": (False, {"max_range_m": float("inf"), "spawn_max_m": 2.25}),
    "calib range, spawn_max_m 3": (False, {"max_range_m": float("inf"), "spawn_max_m": 3.0}),
    "calib range, spawn_max_m 2, publish_min_certainty 0.6": (False, {"max_range_m": float("inf"), "spawn_max_m": 2.0,
                                                                     "publish_min_certainty": 0.6}),
    "calib range, spawn_max_m 2, min_hits 3": (False, {"max_range_m": float("inf"), "spawn_max_m": 2.0, "min_hits": 3}),
    "calib range, spawn_max_m 2 + weak 0.10-0.25": (True, {"max_range_m": float("inf"), "spawn_max_m": 2.0,
                                                         "strong_score": 0.25}),
}

ap = argparse.ArgumentParser()
ap.add_argument("bags", nargs="+")
ap.add_argument("--far-rows", default=None, help="auto (default: the calibration's strip), off, or V0,V1")
ap.add_argument("--only", default="", help="only the designs whose name holds this text")
args = ap.parse_args()
DESIGNS = {k: v for k, v in DESIGNS.items() if args.only in k}
print("| design | bag | " + " | ".join(["0-7 m", "7-15 m", "15-25 m", "25-40 m"]) + " | false / frame < 40 m |")
print("|---|---|---|---|---|---|---|")
for bag in args.bags:
    calib = replace(load_calibration(f"{bag}_calib.yaml"), max_range_m=40.0)
    det = Detector.load_for_band(default_model_path(), (calib.crop.out_width, calib.crop.out_height), conf=0.1, threads=1)
    far = FarBand.for_calibration(det.source, args.far_rows, calib, "--far-rows", conf=0.1, threads=1)
    imu = ImuAttitude((0.0, 0.0))
    pipe = Pipeline(calib, det, None, imu, far, cones_conf=0.25)
    imu_msgs, k, frames = read_imu(bag), 0, []
    for fr in iter_frames(bag, find_image_topic(bag, None)[0]):
        while k < len(imu_msgs) and imu_msgs[k][0] <= fr.stamp_ns:
            imu.add(*imu_msgs[k])
            k += 1
        r = process_frame(pipe, fr)
        frames.append((fr.stamp_ns, r.cones, r.weak_cones, r.attitude))
    truth = load_drive_truth(f"{bag}_gt.jsonl")
    for name, (use_weak, kw) in DESIGNS.items():
        stage, ev = TrackingStage(calib, TrackerConfig(**kw)), DriveEvaluation(truth)
        for stamp, cones, weak, att in frames:
            z = np.concatenate([cones, weak]) if use_weak and len(weak) else cones
            tracked, _ = stage.process(stamp, z, att)
            ev.add_tracked(stamp, tracked)
        t = ev.summary()["tracked"]
        f = sum(b["false_cones"] for b in t["bands"].values()) / t["frames"]
        print(f"| {name} | {bag.rsplit('/', 1)[-1]} | " + " | ".join(f"{b['recall']:.3f} / {b['false_per_frame']:.2f}"
                                                                   for b in t["bands"].values())
              + f" | {f:.2f} |", flush=True)
