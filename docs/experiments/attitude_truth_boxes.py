"""What bounds the image-only attitude: the fit on exact boxes against the fit on the shipped detector's.

Each synthetic bag is replayed offline twice in `--attitude image`: once with the shipped detector
(as `replay` does), once with a stand-in detector that returns the exact boxes of the cones at least
half visible (the bag's `_gt.jsonl`, full-resolution pixels; the detector's box-top correction table
off, as for exact boxes). Both are scored against /cones_gt and /attitude_gt; a third row maps the
exact boxes with the true attitude (the floor of the boxes themselves).

    .venv/bin/python docs/experiments/attitude_truth_boxes.py /tmp/ho2/jit32? /tmp/att/jit10?
"""
import json
import sys
from pathlib import Path

import numpy as np

from cone_perception.attitude import Attitude
from cone_perception.geometry.calib import load_calibration
from cone_perception.detector import Detector, default_model_path
from cone_perception.pipeline import Pipeline
from cone_perception.records import boxes_from_arrays
from cone_perception.replay import offline_replay
from cone_perception.data.bags import read_attitude_truth


class TruthDetector:
    """Exact boxes of the cones at least half visible, frame by frame from the bag's gt.jsonl."""

    timing: dict = {}

    def __init__(self, gt_path: Path):
        self.frames = iter([json.loads(x) for x in gt_path.read_text().splitlines()])

    def detect(self, band, crop):
        cones = [c for c in next(self.frames)["cones"] if c["visible_fraction"] >= 0.5]
        return boxes_from_arrays(np.array([c["box"] for c in cones]).reshape(-1, 4), np.ones(len(cones)),
                                 np.array([c["class_id"] for c in cones], dtype=int))


class TrueAttitude:
    """The bag's /attitude_gt for each frame (the attitude estimator's interface)."""

    def __init__(self, truth: dict, stamps: list):
        from cone_perception.attitude import AttitudeCounts

        self.it = iter([truth[s] for s in stamps])
        self.counts = AttitudeCounts()

    def update(self, boxes, class_ids):
        p, r = next(self.it)
        return Attitude(float(p), float(r), 0.01, 0.01, "image", 0)


def score(res) -> str:
    g = res.localisation["groups"]["far 7-15 m"]["median_err_m"]
    a = res.localisation.get("attitude", {})
    return f"{g:.3f} | {a.get('median_abs_err_pitch_deg', 0.0):.3f} / {a.get('median_abs_err_roll_deg', 0.0):.3f}"


def main(bags: list[str]) -> None:
    print("| bag | shipped detector, image attitude: 7-15 m / pitch, roll err | exact boxes, image attitude | exact boxes, true attitude |")
    print("|---|---|---|---|")
    for bag in (Path(b.rstrip("/")) for b in bags):
        cal = load_calibration(f"{bag}_calib.yaml")
        gt_path = Path(f"{bag}_gt.jsonl")
        det = Detector.load_for_band(default_model_path(), (cal.crop.out_width, cal.crop.out_height))
        shipped = offline_replay(bag, Pipeline(cal, det, "image"), gt_topic="/cones_gt")
        pipe = Pipeline(cal, TruthDetector(gt_path), "image")
        pipe.attitude.cfg.top_bias_extra_px = ()
        exact = offline_replay(bag, pipe, gt_topic="/cones_gt")
        truth = read_attitude_truth(bag)
        stamps = [json.loads(x)["stamp_ns"] for x in gt_path.read_text().splitlines()]
        pipe = Pipeline(cal, TruthDetector(gt_path), "image")
        pipe.attitude = TrueAttitude(truth, stamps)
        floor = offline_replay(bag, pipe, gt_topic="/cones_gt")
        print(f"| {bag.name} | {score(shipped)} | {score(exact)} | {score(floor)} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
