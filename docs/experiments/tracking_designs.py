"""Tracker designs for the 0.7x target of issue 16, measured on tuning drives (never 201-205).

Same inputs as tracking_error_decomposition.py (NAME, NAME_gt.jsonl, NAME_calib.yaml, NAME_out of
`replay --attitude fixed --out`); each design maps the replay's /cone_boxes again (so the foot
offset rule can change), drops 0 % and 20 % of the detections (seed 0, as `replay
--drop-detections`), tracks with the design's TrackerConfig and scores with DriveEvaluation:

    .venv/bin/python docs/experiments/tracking_designs.py tune101 tune102 tune103 tune111 tune112

One markdown row per design and drop share: raw / tracked median error 7-15 m per drive, the range
and the mean of the tracked / raw ratio, id switches per 100 frames (mean).
"""
import sys
import numpy as np
from cone_perception.data import bagio
from cone_perception.geometry.calib import load_calibration
from cone_perception.mapping import ConeMapper
from cone_perception.records import BOX_DTYPE, from_pointcloud2
from cone_perception.evaluation.tracking import DriveEvaluation, load_drive_truth
from cone_perception.replay import drop_detections
from cone_perception.tracking import TrackerConfig, TrackingStage


def main(names: list[str]) -> None:
    DESIGNS = {"as shipped": ({}, False, False), "true motion (exact twists as odometry)": ({}, False, True),
               "(a) more fading memory, process_std_m 0.08": ({"process_std_m": 0.08}, False, False),
               "(a) less fading memory, process_std_m 0.02": ({"process_std_m": 0.02}, False, False),
               "(c) robust update, robust_chi2 1": ({"robust_chi2": 1.0}, False, False),
               "(b) foot offset from the box width": ({}, True, False), "(b) + (c)": ({"robust_chi2": 1.0}, True, False)}
    for design, (kw, from_width, true_motion) in DESIGNS.items():
        for drop in (0.0, 0.2):
            ratios = []
            for name in names:
                calib = load_calibration(f"{name}_calib.yaml")
                calib.foot_offset_from_width = from_width
                mapper, truth = ConeMapper(calib), load_drive_truth(f"{name}_gt.jsonl")
                stage, ev, rng, last = TrackingStage(calib, TrackerConfig(**kw)), DriveEvaluation(truth), np.random.default_rng(0), None
                for m in bagio.read_messages(f"{name}_out", "/cone_boxes"):
                    stamp = bagio.stamp_ns(m.msg.header)
                    if true_motion and last is not None:
                        stage.add_twist(last, *truth.motion(last, stamp).twist((stamp - last) / 1e9))
                    last = stamp
                    cones = drop_detections(mapper.map_boxes(from_pointcloud2(m.msg, BOX_DTYPE)), drop, rng)
                    ev.add_raw(stamp, cones)
                    ev.add_tracked(stamp, stage.process(stamp, cones)[0])
                s = ev.summary()
                ratios.append((s["raw"]["median_err_7_15_m"], s["tracked"]["groups"]["far 7-15 m"]["median_err_m"],
                               s["tracked"]["err_7_15_ratio_to_raw"], s["tracked"]["id_switches_per_100_frames"]))
            r = np.array(ratios)
            print(f"| {design} | {drop:.0%} | " + " ".join(f"{a:.3f}/{b:.3f}" for a, b, _, _ in r) + f" | {r[:, 2].min():.2f}-{r[:, 2].max():.2f} | {r[:, 2].mean():.3f} | {r[:, 3].mean():.2f} |")


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0)
    main(sys.argv[1:])
