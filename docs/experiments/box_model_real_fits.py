"""Single-frame image fits on the real validation clips' detections, the rendered box table against each
model's box model (issue 27): the fit's outcome counts and the residuals' robust spread. Through a
calibration that is not these clips' camera (none is known), so the counts are indicative only.

    cone-perception detect data/real_val_1080 --model models/M.pt --crop 96,672 --downscale 2 --conf 0.1 \
        --out runs/eval/real_crop_half_M.jsonl      # M = cone_detector, cone_detector_n, cone_detector_mnv2
    .venv/bin/python docs/experiments/box_model_real_fits.py cone_detector cone_detector_n cone_detector_mnv2
"""
import argparse

import numpy as np

from cone_perception.attitude import ImageAttitudeConfig
from cone_perception.data.predictions import read_predictions
from cone_perception.detector.model_files import read_box_model
from cone_perception.geometry.calib import load_calibration
from cone_perception.mapping import ConeMapper


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("models", nargs="+", help="model names under models/ (their runs/eval/real_crop_half_M.jsonl)")
    ap.add_argument("--calib", default="calib/example_mainhoop.yaml")
    ap.add_argument("--conf", type=float, default=0.25)
    args = ap.parse_args()
    calib = load_calibration(args.calib)
    for m in args.models:
        for bm in (None, read_box_model(f"models/{m}.pt")):
            est = ConeMapper(calib).image_attitude(ImageAttitudeConfig(box_model=bm))
            scales, pitch = [], []
            for p in read_predictions(f"runs/eval/real_crop_half_{m}.jsonl"):
                b = p.boxes[p.boxes["score"] >= args.conf]
                s = np.array([calib.image_width / p.width, calib.image_height / p.height] * 2)
                boxes = np.column_stack([b["u1"], b["v1"], b["u2"], b["v2"]]) * s
                a = est.single_frame(boxes, b["class_id"].astype(np.intp))
                if np.isfinite(est.last_scale):
                    scales.append(est.last_scale)
                if a.source == "image":
                    pitch.append(a.pitch_deg)
            print(m, "box model" if bm else "rendered table", est.counts.as_dict(),
                  "residual spread median %.2f p90 %.2f" % (np.median(scales), np.percentile(scales, 90)),
                  "pitch of used fits median %+.2f" % (np.median(pitch) if pitch else np.nan))


if __name__ == "__main__":
    main()
