"""Designs against the bias of the image attitude fit, on tuning drives (docs/benchmarks.md, "Bias of the
image fit"): each drive's detector boxes are cached once (the shipped model through the pipeline,
attitude fixed: boxes do not depend on it), then every design re-runs the attitude estimate and the
mapping over the cached boxes and is scored as `replay --gt-topic` scores (median position error of
the cones at 7-15 m, median |pitch| / |roll| error against /attitude_gt), in `image` and `fused` (the
bag's /imu, --imu-rest 0,0).

    # tuning drives (never the held-out seeds 301-303), from the repository root, ~10 min on 2 cores:
    for s in 104 105 106 107 111 112 113; do
      .venv/bin/cone-perception synth bag --seed $s --seconds 10 --out /tmp/att/jit$s --quiet
      .venv/bin/cone-perception synth bag --seed $s --seconds 10 --car-motion --out /tmp/att/car$s --quiet
      .venv/bin/cone-perception synth bag --seed $s --seconds 10 --no-jitter --out /tmp/att/flat$s --quiet
    done
    .venv/bin/python docs/experiments/attitude_designs.py /tmp/att/*[0-9]

A bag's kind (flat, jit, car) is the start of its folder name.
"""
import pickle
import sys
from pathlib import Path

import numpy as np

from cone_perception.attitude import FusedAttitude, ImageAttitudeConfig, ImuAttitude, attitude_for_boxes
from cone_perception.geometry.calib import load_calibration
from cone_perception.evaluation import LocalisationReport
from cone_perception.mapping import ConeMapper


def cached(bag: str) -> dict:
    path = Path(bag + ".boxes.pkl")
    if not path.is_file():
        from cone_perception.detector import Detector, default_model_path
        from cone_perception.pipeline import Pipeline
        from cone_perception.data.bags import (
            find_image_topic, iter_frames, read_attitude_truth, read_ground_truth, read_imu
        )
        from cone_perception.replay import process_frame

        cal = load_calibration(bag + "_calib.yaml")
        pipe = Pipeline(cal, Detector.load_for_band(default_model_path(), (cal.crop.out_width, cal.crop.out_height)), "fixed")
        frames = [(fr.stamp_ns, process_frame(pipe, fr).boxes) for fr in iter_frames(bag, find_image_topic(bag)[0])]
        path.write_bytes(pickle.dumps({"frames": frames, "truth": read_ground_truth(bag, "/cones_gt"),
                                       "att": read_attitude_truth(bag), "imu": read_imu(bag)}))
        print(f"cached {bag}: {len(frames)} frames", file=sys.stderr)
    return pickle.loads(path.read_bytes())


def run_drive(bag: str, d: dict, make, use_imu: bool, rest_deg=(0.0, 0.0)) -> tuple[float, float, float]:
    """One cached drive through the estimator ``make(mapper, imu)``: (median error 7-15 m, median |pitch| and
    |roll| error in degrees). ``use_imu``: feed the bag's IMU samples up to each frame, relative to
    ``rest_deg`` (``--imu-rest``)."""
    m = ConeMapper(load_calibration(bag + "_calib.yaml"))
    imu = ImuAttitude(rest_deg)
    est = make(m, imu)
    rep, ep, er, k = LocalisationReport(max_range_m=m.calib.max_range_m), [], [], 0
    for st, boxes in d["frames"]:
        while use_imu and k < len(d["imu"]) and d["imu"][k][0] <= st:
            imu.add(*d["imu"][k])
            k += 1
        a = attitude_for_boxes(est, boxes, st)
        rep.add_frame(m.map_boxes(boxes, a), d["truth"][st])
        ep.append(abs(a.pitch_deg - d["att"][st][0]))
        er.append(abs(a.roll_deg - d["att"][st][1]))
    return rep.summary()["groups"]["far 7-15 m"]["median_err_m"], float(np.median(ep)), float(np.median(er))


def score(bag: str, d: dict, mode: str, cfg: dict, gate=None) -> tuple[float, float, float]:
    """``gate``: the fused mode's GroundGate (None: none, fused as of the sections of this script)."""
    def make(m, imu):
        est = m.image_attitude(ImageAttitudeConfig(**cfg))
        return FusedAttitude(est, imu, gate=gate) if mode == "fused" else est

    return run_drive(bag, d, make, mode == "fused")


def print_design_table(kinds: dict, designs, scorer) -> None:
    """One markdown row a design: mean of the per-drive 7-15 m medians per kind of drive, the worst drive,
    drives above 0.08 m, mean pitch / roll error. ``designs``: (name, design); ``scorer(bag, design)``
    -> (7-15 m, pitch err, roll err)."""
    print("| design | " + " | ".join(f"{k} 7-15 m" for k in kinds) + " | worst drive | drives > 0.08 m | pitch / roll err (deg) |")
    print("|---|" + "---|" * (len(kinds) + 3))
    for name, design in designs:
        r = {k: [scorer(b, design) for b in v] for k, v in kinds.items()}
        a = np.array([x for v in r.values() for x in v])
        print(f"| {name} | " + " | ".join(f"{np.mean([x[0] for x in r[k]]):.3f}" for k in kinds)
              + f" | {a[:, 0].max():.3f} | {int((a[:, 0] > 0.08).sum())} of {len(a)} | {a[:, 1].mean():.3f} / {a[:, 2].mean():.3f} |",
              flush=True)


BEFORE = {"top_bias_extra_px": (), "bias_tau_frames": 0, "still_frames": 0, "max_range_m": 25.0, "cauchy_c": 2.5}
TABLE = ImageAttitudeConfig().top_bias_extra_px
DESIGNS = [
    ("main before (none of these)", BEFORE),
    ("(a) bias state, pitch and roll (400 frames, prior 20)", {**BEFORE, "bias_tau_frames": 400, "bias_prior_frames": 20, "bias_pitch": True}),
    ("(a) bias state, roll only (1200 frames, prior 100)", {**BEFORE, "bias_tau_frames": 1200, "bias_prior_frames": 100}),
    ("(b) detector box-top table (half the residual)", {**BEFORE, "top_bias_extra_px": TABLE}),
    ("(b) at the full measured residual", {**BEFORE, "top_bias_extra_px": tuple((h, 2 * v) for h, v in TABLE)}),
    ("(c) still test (20 frames)", {**BEFORE, "still_frames": 20}),
    ("(a roll) + (b) + (c)", {"max_range_m": 25.0, "cauchy_c": 2.5}),
    ("kept: (a roll) + (b) + (c), range 20 m, Cauchy 1.5", {}),
    ("kept, (b) at the full residual", {"top_bias_extra_px": tuple((h, 2 * v) for h, v in TABLE)}),
    ("kept without (b)", {"top_bias_extra_px": ()}),
    ("kept without the roll bias state", {"bias_tau_frames": 0}),
    ("kept without the still test", {"still_frames": 0}),
]


def main(bags: list[str]) -> None:
    bags = [b.rstrip("/") for b in bags]
    kinds = {k: [b for b in bags if Path(b).name.startswith(k)] for k in ("flat", "jit", "car")}
    data = {b: cached(b) for b in bags}
    print(f"tuning drives: {', '.join(Path(b).name for b in bags)}")
    print("| design | mode | flat 7-15 m | jit 7-15 m | car 7-15 m | worst drive 7-15 m | pitch / roll err (deg) |")
    print("|---|---|---|---|---|---|---|")
    for name, cfg in DESIGNS:
        for mode in ("image", "fused"):
            r = {k: [score(b, data[b], mode, cfg) for b in v] for k, v in kinds.items()}
            a = np.array([x for v in r.values() for x in v])
            print(f"| {name} | {mode} | " + " | ".join(f"{np.mean([x[0] for x in r[k]]):.3f}" if r[k] else "-" for k in kinds)
                  + f" | {a[:, 0].max():.3f} | {a[:, 1].mean():.3f} / {a[:, 2].mean():.3f} |", flush=True)


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0)
    main(sys.argv[1:])
