"""A detector's box model measured at several scales of the same labelled frames (issue 27, the far sidecar's open
risk): per run, the medians of ``eval --box-model-out`` (height ratio, top low, bottom high; detections at score
>= 0.25 matched at IoU 0.5 to whole labelled cones inside the band) by the box height at the model input, and by the
box height in SOURCE px (the frames' native detail: the real clips are 640x360 video, restored to 1920 wide
for the car-sized copy, so 3 image px per source px there and 1 in the 640 px copy). A bucket at the model
input holds different cones at different scales; by source px the same cones can be compared across scales.

    N=blue_cone,large_orange_cone,orange_cone,yellow_cone
    cone-perception data restore-aspect ../shared/datasets/bgracing-real data/real_val_640 --width 640 --clips autox4,autox2,accel --names $N
    cone-perception detect data/real_val_1080 --crop 240,432 --downscale D --model models/cone_detector_far.pt --conf 0.001 --out runs/eval/real1080_far_dsD.jsonl
    cone-perception detect data/real_val_640 --crop 80,144 --downscale 1 --model models/cone_detector_far.pt --conf 0.001 --out runs/eval/real640_far.jsonl
    .venv/bin/python docs/experiments/box_model_scales.py --gt-names $N \
        "full res=runs/eval/real1080_far_ds1.jsonl,data/real_val_1080,240,432,3" \
        "native=runs/eval/real640_far.jsonl,data/real_val_640,80,144,1"

Each run: ``LABEL=PRED,GT,V0,V1,IMAGE_PX_PER_SOURCE_PX``.
"""
import argparse

import numpy as np

from cone_perception.data.predictions import read_predictions
from cone_perception.evaluation.boxfit import MAD_TO_SIGMA, box_samples
from cone_perception.evaluation.groundtruth import load_ground_truth, pair_with_predictions, restrict_to_band

INPUT_BUCKETS = (8.0, 12.0, 24.0, 48.0)
SOURCE_BUCKETS = (4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 48.0)


def rows(h: np.ndarray, s: dict, edges) -> list[str]:
    out = []
    e = list(edges) + [np.inf]
    for lo, hi in zip(e[:-1], e[1:]):
        m = (h >= lo) & (h < hi)
        if not m.any():
            out.append("-")
            continue
        out.append(f"{m.sum()}: {np.median(s['height_ratio'][m]):.3f} / {100 * np.median(s['top_low'][m]):+.1f} % / "
                   f"{100 * np.median(s['bottom_high'][m]):+.1f} %")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", help="LABEL=PRED,GT,V0,V1,IMAGE_PX_PER_SOURCE_PX")
    ap.add_argument("--gt-names", default=None)
    ap.add_argument("--conf", type=float, default=0.25)
    args = ap.parse_args()
    names = args.gt_names.split(",") if args.gt_names else None
    head_in = ["8-12", "12-24", "24-48", ">=48"]
    head_src = ["4-6", "6-8", "8-12", "12-16", "16-24", "24-48", ">=48"]
    print("cells: cones: height ratio / top low / bottom high")
    print("| run | spread | " + " | ".join(f"{x} input px" for x in head_in) + " |")
    print("|---|---|" + "---|" * len(head_in))
    by_src = []
    for run in args.runs:
        label, spec = run.split("=", 1)
        pred, gt, v0, v1, per_src = spec.split(",")
        band = (int(v0), int(v1))
        images, _ = pair_with_predictions(load_ground_truth(gt, names), list(read_predictions(pred)), pred)
        images, _ = restrict_to_band(images, band)
        s = box_samples(images, args.conf, 0.5, band)
        h_in = s["height_in"]
        h_src = h_in / s["input_scale"] / float(per_src)
        use = h_in >= INPUT_BUCKETS[0]
        t = s["top_low"][use]
        sigma = MAD_TO_SIGMA * float(np.median(np.abs(t - np.median(t))))
        print(f"| {label} | {sigma:.3f} | " + " | ".join(rows(h_in, s, INPUT_BUCKETS)) + " |")
        by_src.append((label, rows(h_src, s, SOURCE_BUCKETS)))
    print("\n| run | " + " | ".join(f"{x} source px" for x in head_src) + " |")
    print("|---|" + "---|" * len(head_src))
    for label, r in by_src:
        print(f"| {label} | " + " | ".join(r) + " |")


if __name__ == "__main__":
    main()
