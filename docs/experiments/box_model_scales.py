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

Each run: ``LABEL=PRED,GT,V0,V1,IMAGE_PX_PER_SOURCE_PX``. The control for detail against context (the scene's size
at the model input): ``--make-blurred SRC OUT K`` writes a copy of a YOLO folder whose frames keep their size but
only 1/K of their detail (each resized down K times, INTER_AREA, and back up, INTER_LINEAR; labels copied):

    .venv/bin/python docs/experiments/box_model_scales.py --make-blurred data/real_val_640 data/real_val_640_b3 3
    cone-perception detect data/real_val_640_b3 --crop 80,144 --downscale 1 --model models/cone_detector_far.pt --conf 0.001 --out runs/eval/real640b3_far.jsonl
"""
import shutil
from pathlib import Path

import argparse

import numpy as np

from cone_perception.data.predictions import read_predictions
from cone_perception.evaluation.boxfit import MAD_TO_SIGMA, box_samples
from cone_perception.evaluation.groundtruth import load_ground_truth, pair_with_predictions, restrict_to_band

INPUT_BUCKETS = (8.0, 12.0, 24.0, 48.0)
SOURCE_BUCKETS = (4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 48.0)


def rows(h: np.ndarray, s: dict, edges, ci: bool = False) -> list[str]:
    out = []
    e = list(edges) + [np.inf]
    rng = np.random.default_rng(0)
    for lo, hi in zip(e[:-1], e[1:]):
        m = (h >= lo) & (h < hi)
        if not m.any():
            out.append("-")
            continue
        top = s["top_low"][m]
        cell = (f"{m.sum()}: {np.median(s['height_ratio'][m]):.3f} / {100 * np.median(top):+.1f} % / "
                f"{100 * np.median(s['bottom_high'][m]):+.1f} %")
        if ci:  # 95 % bootstrap interval of the median top offset (cones resampled)
            meds = np.median(rng.choice(top, (2000, len(top))), axis=1)
            cell += f" [{100 * np.percentile(meds, 2.5):+.1f}, {100 * np.percentile(meds, 97.5):+.1f}]"
        out.append(cell)
    return out


def make_blurred(src: Path, out: Path, k: float) -> None:
    import cv2

    (out / "images").mkdir(parents=True, exist_ok=True)
    shutil.copytree(src / "labels", out / "labels", dirs_exist_ok=True)
    shutil.copy(src / "data.yaml", out / "data.yaml")
    for f in sorted((src / "images").iterdir()):
        im = cv2.imread(str(f))
        h, w = im.shape[:2]
        small = cv2.resize(im, (round(w / k), round(h / k)), interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(out / "images" / f.name), cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR),
                    [cv2.IMWRITE_JPEG_QUALITY, 95])
    print("wrote", out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--make-blurred", nargs=3, metavar=("SRC", "OUT", "K"), default=None,
                    help="write a copy of the YOLO folder SRC to OUT with 1/K of its detail, then stop")
    ap.add_argument("runs", nargs="*", help="LABEL=PRED,GT,V0,V1,IMAGE_PX_PER_SOURCE_PX")
    ap.add_argument("--gt-names", default=None)
    ap.add_argument("--conf", type=float, default=0.25)
    ap.add_argument("--ci", action="store_true", help="also a 95 %% bootstrap interval of each median top offset")
    ap.set_defaults(runs=[])
    args = ap.parse_args()
    if args.make_blurred:
        return make_blurred(Path(args.make_blurred[0]), Path(args.make_blurred[1]), float(args.make_blurred[2]))
    names = args.gt_names.split(",") if args.gt_names else None
    head_in = ["8-12", "12-24", "24-48", ">=48"]
    head_src = ["4-6", "6-8", "8-12", "12-16", "16-24", "24-48", ">=48"]
    print("cells: cones: height ratio / top low / bottom high" + (" [95 % interval of top low]" if args.ci else ""))
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
        print(f"| {label} | {sigma:.3f} | " + " | ".join(rows(h_in, s, INPUT_BUCKETS, args.ci)) + " |")
        by_src.append((label, rows(h_src, s, SOURCE_BUCKETS, args.ci)))
    print("\n| run | " + " | ".join(f"{x} source px" for x in head_src) + " |")
    print("|---|" + "---|" * len(head_src))
    for label, r in by_src:
        print(f"| {label} | " + " | ".join(r) + " |")


if __name__ == "__main__":
    main()
