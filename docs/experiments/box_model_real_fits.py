"""Single-frame image fits on the real validation clips' detections, the rendered box table against each
model's box model (issue 27): the fit's outcome counts and the residuals' robust spread. Through a
calibration that is not these clips' camera (none is known), so the counts are indicative only.

    cone-perception detect data/real_val_1080 --model models/M.pt --crop 96,672 --downscale 2 --conf 0.1 \
        --out runs/eval/real_crop_half_M.jsonl      # M = cone_detector, cone_detector_n, cone_detector_mnv2
    .venv/bin/python docs/experiments/box_model_real_fits.py cone_detector cone_detector_n cone_detector_mnv2

With the far strip (``--strip FILE``: the far model's predictions in the strip rows at full resolution, cut boxes
dropped and merged with the band's as the pipeline merges them; each network's boxes through its own box model),
once per ``--far-range`` (the fit's ``far_max_range_m``; none: ``max_range_m`` for all):

    cone-perception detect data/real_val_1080 --crop 240,432 --downscale 1 --model models/cone_detector_far.pt \
        --conf 0.001 --out runs/eval/real_strip_far.jsonl
    .venv/bin/python docs/experiments/box_model_real_fits.py cone_detector --strip runs/eval/real_strip_far.jsonl --far-range none,25

The strip's boxes may come from another copy of the frames (their boxes are scaled to the calibration's image size):
the strip rows of the 640x360 copy (``data restore-aspect ... --width 640``) at downscale 1, where one model-input px
is one px of the clips' own detail, are read with ``--strip-scale 0.3333`` (model input px per calibration px);
``--far-box-model FILE`` reads them through another box model file than the far model's sidecar:

    cone-perception detect data/real_val_640 --crop 80,144 --downscale 1 --model models/cone_detector_far.pt \
        --conf 0.001 --out runs/eval/real640_far.jsonl
    .venv/bin/python docs/experiments/box_model_real_fits.py cone_detector --strip runs/eval/real640_far.jsonl \
        --strip-scale 0.3333 [--far-box-model FILE]
"""
import argparse
from dataclasses import replace

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
    ap.add_argument("--strip", default=None, help="the far model's strip predictions (full resolution), merged in")
    ap.add_argument("--strip-rows", default="240,432", help="the strip's rows (default %(default)s, the far card's)")
    ap.add_argument("--far-range", default="none,25", help="with --strip: far_max_range_m values (none: max_range_m)")
    ap.add_argument("--strip-scale", type=float, default=1.0,
                    help="with --strip: model input px per calibration px of the strip's boxes (default 1: the strip at full "
                         "resolution on car-sized frames; 0.3333: run on the 640 px copy)")
    ap.add_argument("--far-box-model", default=None, help="with --strip: a box model file to read the strip's boxes through "
                                                          "(default: the far model's sidecar)")
    ap.add_argument("--band-pred", default=None, help="without --strip: the band's predictions (default "
                                                      "runs/eval/real_crop_half_M.jsonl), e.g. of the 640 px copy")
    ap.add_argument("--band-scale", type=float, default=None,
                    help="without --strip: model input px per calibration px of the band's boxes (default: the box "
                         "model's own input_scale; 0.3333: the band run at downscale 1 on the 640 px copy)")
    ap.add_argument("--band-box-model", default=None, help="without --strip: a box model file to read the band's boxes "
                                                           "through (default: the model's sidecar)")
    args = ap.parse_args()
    calib = load_calibration(args.calib)
    if args.strip:
        return with_strip(args, calib)
    for m in args.models:
        own = _sidecar(args.band_box_model) if args.band_box_model else read_box_model(f"models/{m}.pt")
        if args.band_scale is not None:
            own = replace(own, input_scale=args.band_scale)
        for bm in (None, own):
            est = ConeMapper(calib).image_attitude(ImageAttitudeConfig(box_model=bm))
            scales, pitch = [], []
            for p in read_predictions(args.band_pred or f"runs/eval/real_crop_half_{m}.jsonl"):
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


def with_strip(args, calib) -> None:
    from types import SimpleNamespace

    from cone_perception.attitude.boxes import BoxReading
    from cone_perception.detector.farband import drawn_by_far, drop_cut_boxes, merge_boxes
    from cone_perception.mapping import one_box_per_cone
    from cone_perception.records import boxes_from_arrays
    from cone_perception.resources import default_far_model_path

    v0, v1 = (float(x) for x in args.strip_rows.split(","))
    strip = {p.image: p for p in read_predictions(args.strip)}
    if args.far_box_model:
        far_bm = _sidecar(args.far_box_model)
    else:
        far_bm = read_box_model(default_far_model_path())
    far_bm = replace(far_bm, input_scale=args.strip_scale)  # its buckets at the strip's model input
    print("far box model:", args.far_box_model or "the far model's sidecar", "read at input scale %g" % args.strip_scale)

    def records(p, conf):
        b = p.boxes[p.boxes["score"] >= conf]
        s = np.array([calib.image_width / p.width, calib.image_height / p.height] * 2)
        xy = np.column_stack([b["u1"], b["v1"], b["u2"], b["v2"]]) * s
        return boxes_from_arrays(xy, b["score"], b["class_id"])

    for m in args.models:
        frames = []
        for p in read_predictions(f"runs/eval/real_crop_half_{m}.jsonl"):
            band = records(p, args.conf)
            far = drop_cut_boxes(records(strip[p.image], args.conf), SimpleNamespace(v0=v0, v1=v1))
            merged = one_box_per_cone(merge_boxes(band, far))
            frames.append((merged, drawn_by_far(merged, far)))
        for rng in args.far_range.split(","):
            cfg = ImageAttitudeConfig(box_model=read_box_model(f"models/{m}.pt"), far_reading=BoxReading(far_bm),
                                      far_max_range_m=None if rng == "none" else float(rng))
            est = ConeMapper(calib).image_attitude(cfg)
            scales, pitch, n_far = [], [], []
            for merged, far in frames:
                b = np.column_stack([merged["u1"], merged["v1"], merged["u2"], merged["v2"]]).astype(np.float64)
                a = est.single_frame(b, merged["class_id"].astype(np.intp), far)
                n_far.append(int((est._select(est._read(b, far)[0], merged["class_id"].astype(np.intp), far=far) & far).sum()))
                if np.isfinite(est.last_scale):
                    scales.append(est.last_scale)
                if a.source == "image":
                    pitch.append(a.pitch_deg)
            print(m, "+ far strip, far_max_range_m", rng, est.counts.as_dict(), "strip boxes in the fit %d" % sum(n_far),
                  "residual spread median %.2f p90 %.2f" % (np.median(scales), np.percentile(scales, 90)),
                  "pitch of used fits median %+.2f (%d)" % (np.median(pitch) if pitch else np.nan, len(pitch)))


def _sidecar(path: str):
    import yaml

    from cone_perception.attitude import BoxModel

    return BoxModel.from_dict(yaml.safe_load(open(path))["box_model"], path)


if __name__ == "__main__":
    main()
