"""Designs of the image fit for the real frames' box behaviour (issue 27, item 5), on tuning drives with the
held-out camera's lens distortion: each drive's detector boxes are cached once (attitude_designs.py's cache),
given the real behaviour of the shipped model's box model (synth/boxlook.py: medians, the top scattered by the
measured spread or by ``--jitter``; seeded per drive), then each fit design re-runs the image attitude (through
the model's box model) and the mapping; scored as `replay --gt-topic` scores them (median error of the cones at
7-15 m, median |pitch| / |roll| error against /attitude_gt).

    # tuning drives (not the seeds the figures of docs/benchmarks.md come from), ~2 min on 2 cores:
    for s in 104 105 106; do
      .venv/bin/cone-perception synth bag --seed $s --seconds 10 --k1 -0.126 --out /tmp/a27/tune/djit$s --no-progress
    done
    .venv/bin/python docs/experiments/attitude_real_boxes.py /tmp/a27/tune/djit10? [--jitter 0.035]
"""
import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from attitude_designs import cached, run_drive  # noqa: E402

from cone_perception.attitude import ImageAttitudeConfig  # noqa: E402
from cone_perception.attitude.box_files import read_box_model  # noqa: E402
from cone_perception.resources import default_model_path  # noqa: E402
from cone_perception.synth.boxlook import BoxBehaviour  # noqa: E402

DESIGNS = [
    ("shipped (range 20 m, sigma_px 1.5, Cauchy 1.5)", {}),
    ("range 25 m", {"max_range_m": 25.0}),
    ("range 30 m", {"max_range_m": 30.0}),
    ("sigma_px 1.0", {"sigma_px": 1.0}),
    ("Cauchy 2.5", {"cauchy_c": 2.5}),
    ("range 25 m, sigma_px 1.0", {"max_range_m": 25.0, "sigma_px": 1.0}),
    ("process sigma 0.4 deg", {"process_sigma_deg": 0.4}),
    ("process sigma 0.9 deg", {"process_sigma_deg": 0.9}),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bags", nargs="+")
    ap.add_argument("--jitter", type=float, default=None, help="top spread (default: the box model's)")
    args = ap.parse_args()
    bm = read_box_model(default_model_path())
    bags = [b.rstrip("/") for b in args.bags]
    data = {}
    for i, b in enumerate(bags):
        d = dict(cached(b))
        look = BoxBehaviour(bm, args.jitter, seed=i)
        d["frames"] = [(st, look(boxes)) for st, boxes in d["frames"]]
        data[b] = d
    print(f"drives {', '.join(Path(b).name for b in bags)}; real boxes, top spread "
          f"{bm.sigma_rel if args.jitter is None else args.jitter}")
    print("| design | 7-15 m per drive | mean | pitch / roll err (deg) |")
    print("|---|---|---|---|")
    for name, cfg in DESIGNS:
        config = replace(ImageAttitudeConfig(box_model=bm), **cfg)
        r = np.array([run_drive(b, data[b], lambda m, imu: m.image_attitude(config), False) for b in bags])
        print(f"| {name} | " + " / ".join(f"{x:.3f}" for x in r[:, 0]) + f" | {r[:, 0].mean():.3f} | "
              f"{r[:, 1].mean():.3f} / {r[:, 2].mean():.3f} |", flush=True)


if __name__ == "__main__":
    main()
