"""``cone-perception bench table``: the thesis's runtime table, redone (the command: ``commands/bench.py``).

For each model and each input setting (``full`` 1920x1080 -> 1920x1088, ``half`` 960x544,
``crop`` the band at full resolution, ``crop_half`` the band halved, see
:func:`crop_for_setting`):

1. speed: :func:`.pipeline.bench_pipeline` (the code of ``bench pipeline --input SETTING``) on
   rendered 1920x1080 YUYV frames with the calibration's band;
2. accuracy: the detector on real validation frames with the same crop and downscale, through
   :func:`cone_perception.detector.detect_one` (= ``detect --crop V0,V1 --downscale N``; the whole image for full /
   half), then :func:`cone_perception.evaluation.report.evaluate_predictions` (= ``eval``): mAP@0.5 and recall at ``--conf``.

Writes ``table.md``, ``table.json`` and the prediction files (``preds/``) to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..crop import CropSpec
from ..data.outfiles import json_safe
from ..data.predictions import write_prediction
from ..data.sources import iter_source
from ..detector import detect_one
from ..errors import ConfigError
from ..evaluation.groundtruth import load_ground_truth
from ..evaluation.report import evaluate_predictions
from ..words import plural
from .frames import rendered_frames
from .pipeline import bench_pipeline, load_for_crop

SRC = "bench table"

#: The thesis's runtime-table inputs: whole image or the band, each at full or half resolution.
INPUT_SETTINGS = ("full", "half", "crop", "crop_half")


def crop_for_setting(band: CropSpec, setting: str, image_width: int, image_height: int) -> CropSpec:
    """The crop of a runtime-table input ``setting`` (:data:`INPUT_SETTINGS`) for the camera's ``band``:
    ``full`` all rows and columns, downscale 1; ``half`` the same, downscale 2; ``crop`` the band
    (rows and columns), downscale 1; ``crop_half`` the band, downscale 2."""
    if setting not in INPUT_SETTINGS:
        raise ConfigError("input", None, f"unknown input setting {setting!r}; choose one of {', '.join(INPUT_SETTINGS)}")
    downscale = 2 if setting in ("half", "crop_half") else 1
    if setting in ("full", "half"):
        return CropSpec.full_image(image_width, image_height, downscale)
    return CropSpec(band.v0, band.v1, band.u0, band.u1, downscale)


def _need(args: argparse.Namespace) -> None:
    for opt in ("val", "band", "out"):
        if getattr(args, opt) is None:
            raise ConfigError(SRC, f"--{opt}", "required for bench table")
    if not args.val.is_dir():
        raise ConfigError(str(args.val), None, "validation folder not found")
    if args.out.exists() and not args.out.is_dir():
        raise ConfigError(str(args.out), None, "output exists and is not a directory")


def parse_settings(text: str) -> list[str]:
    settings = [s.strip() for s in text.split(",") if s.strip()]
    bad = [s for s in settings if s not in INPUT_SETTINGS]
    if bad or not settings:
        raise ConfigError(SRC, "--settings", f"unknown setting(s) {', '.join(bad) or '(none)'}; choose from {', '.join(INPUT_SETTINGS)}")
    return settings


def val_images_dir(val: Path) -> Path:
    return val / "images" if (val / "images").is_dir() else val


def boxes_outside_band(gt, heights: dict[str, int], band: CropSpec) -> tuple[int, int, int]:
    """Ground-truth boxes (centre row outside the band's rows, not entirely inside them, all)."""
    centre_out = cut = total = 0
    for im in gt.images:
        if len(im.boxes) == 0:
            continue
        b = im.boxes
        if im.height is None:  # normalised YOLO boxes
            h = heights.get(im.image) or heights.get(Path(im.image).name)
            if h is None:
                continue
            b = b * h  # only the rows are used
        cy = (b[:, 1] + b[:, 3]) / 2.0
        total += len(b)
        centre_out += int(((cy < band.v0) | (cy >= band.v1)).sum())
        cut += int(((b[:, 1] < band.v0) | (b[:, 3] > band.v1)).sum())
    return centre_out, cut, total


def _fmt(x: float | None, nd: int) -> str:
    return "-" if x is None or not np.isfinite(x) else f"{x:.{nd}f}"


def _pct(n: int, total: int) -> str:
    return f"{100 * n / max(1, total):.1f} %"


def format_markdown(doc: dict) -> str:
    head = doc["conditions"]
    lines = [
        "| model | setting | model input WxH | forward ms (median) | end to end ms (median) | end to end ms (p99) "
        "| Hz (end to end, median) | mAP@0.5 | recall at conf " + f"{head['conf']:g} | recall, boxes >= 12 px "
        "| mAP@0.5 in band | recall, boxes >= 12 px, in band |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in doc["rows"]:
        lines.append(f"| {r['model']} | {r['setting']} | {r['model_input']} | {_fmt(r['forward_ms'], 1)} | "
                     f"{_fmt(r['end_to_end_ms'], 1)} | {_fmt(r['end_to_end_p99_ms'], 1)} | {_fmt(r['hz'], 1)} | "
                     f"{_fmt(r['map50'], 3)} | {_fmt(r['recall'], 3)} | {_fmt(r.get('recall_min_height'), 3)} | "
                     f"{_fmt(r.get('map50_in_band'), 3)} | {_fmt(r.get('recall_min_height_in_band'), 3)} |")
    notes = [
        "",
        f"Command: `{head['command']}` ({head['date']}).",
        f"Speed: `bench pipeline --input SETTING` code path, {head['frames']} timed frames (+{head['warmup']} warm-up) of "
        f"rendered {head['bench_image']} YUYV scenes, band rows {head['bench_band']} of `{head['calibration']}`, "
        f"backend {head['backend']}, {plural(head['threads'], 'network thread')}, {head['cpu']}. End to end = YUYV frame in -> "
        "boxes and cones packed as PointCloud2.",
        f"Accuracy: {head['val_images']} real validation frames ({head['val']}, {head['val_size']}), "
        f"{head['val_boxes']} boxes; crop settings use rows {head['val_band']}, where "
        f"{head['val_boxes_outside_band']} boxes ({_pct(head['val_boxes_outside_band'], head['val_boxes'])}) have their "
        f"centre outside the band (misses) and {head['val_boxes_not_inside_band']} "
        f"({_pct(head['val_boxes_not_inside_band'], head['val_boxes'])}) reach beyond it (cut; misses unless the visible part "
        "still overlaps IoU >= 0.5); full / half see the whole image. "
        f"Detector threshold {head['det_conf']:g} for mAP@0.5 (COCO-style, all classes), recall at score >= {head['conf']:g}, IoU 0.5; "
        "'boxes >= 12 px' counts only boxes at least 12 px tall at the model input. 'In band' (crop settings): "
        "scored on what the band shows, as `eval --band`: boxes cut by it clipped to it, boxes less than 30 % inside ignored.",
    ]
    return "\n".join(lines + notes) + "\n"


def run_table(args: argparse.Namespace, calib) -> int:
    _need(args)
    settings = parse_settings(args.settings)
    models = [m.strip() for m in args.models.split(",") if m.strip()] if args.models else [None]
    names = [n.strip() for n in args.gt_names.split(",") if n.strip()] if args.gt_names else None
    gt = load_ground_truth(args.val, names)  # fails early on a bad --val / --gt-names
    img_dir = val_images_dir(args.val)
    (args.out / "preds").mkdir(parents=True, exist_ok=True)

    frames = rendered_frames(calib, max(1, args.scenes))
    rows, raw = [], []
    heights: dict[str, int] = {}
    val_size = None
    band = None
    runs = [(m, s) for m in models for s in settings]
    bar = tqdm(runs, desc="bench table", unit="run", file=sys.stderr, disable=getattr(args, "no_progress", False))
    for model, setting in bar:
        bar.set_postfix_str(f"{Path(model).stem if model else 'default'} {setting}")
        bench_calib = replace(calib, crop=crop_for_setting(calib.crop, setting, calib.image_width, calib.image_height))
        det = load_for_crop(model, args.backend, bench_calib.crop, args.threads, bf16=args.bf16)
        tag = f"{Path(det.source).stem}" + (f" ({det.checkpoint.cfg.name})" if det.checkpoint else "")
        b = bench_pipeline(bench_calib, det, frames, args.frames, args.warmup)

        # accuracy: same detector, low threshold, the val frames cut like the car's band
        det.conf = args.det_conf
        pred_path = args.out / "preds" / f"{Path(det.source).stem}_{setting}.jsonl"
        n = 0
        val_input = None
        with pred_path.open("w", encoding="utf-8") as fh:
            for name, img, err in iter_source(img_dir):
                if err:
                    raise ConfigError(f"{img_dir}/{name}", None, err)
                h, w = img.shape[:2]
                heights[name] = h
                if val_size is None:
                    val_size = (w, h)
                    v0, v1, u0, u1 = args.band if len(args.band) == 4 else (*args.band, 0, w)
                    band = CropSpec(v0, v1, u0, u1)
                    band.validate(w, h, "--band")
                c = crop_for_setting(band, setting, w, h)
                val_input = det.input_size_for(c.out_width, c.out_height)
                boxes, scale, _ = detect_one(det, img, name, (c.v0, c.v1, c.u0, c.u1), c.downscale)
                write_prediction(fh, name, w, h, boxes, input_scale=scale)
                n += 1
        res = evaluate_predictions(pred_path, args.val, args.gt_names, None, args.conf, 0.5, progress=False, verbose=False)
        in_band = None
        if setting.startswith("crop"):
            in_band = evaluate_predictions(pred_path, args.val, args.gt_names, None, args.conf, 0.5, progress=False,
                                           verbose=False, band=(band.v0, band.v1)).metrics
        d = res.metrics["detection"]
        op = d["operating_point"]["per_class"]["all"]
        st = b["stages"]
        mi = f"{b['model_input'][0]}x{b['model_input'][1]}"
        if val_input and tuple(val_input) != tuple(b["model_input"]):
            mi += f" (val {val_input[0]}x{val_input[1]})"
        rows.append({
            "model": tag, "setting": setting, "model_input": mi,
            "forward_ms": st["forward"]["median_ms"], "end_to_end_ms": st["end_to_end"]["median_ms"],
            "end_to_end_p99_ms": st["end_to_end"]["p99_ms"], "hz": b["fps"],
            "map50": d["map50"], "map50_95": d["map50_95"], "recall": op["recall"], "precision": op["precision"],
            "recall_min_height": res.metrics["by_box_height"]["at_least_min_height"]["recall"],
            "map50_in_band": in_band["detection"]["map50"] if in_band else None,
            "recall_min_height_in_band": in_band["by_box_height"]["at_least_min_height"]["recall"] if in_band else None,
            "predictions": str(pred_path),
        })
        raw.append({"model": tag, "setting": setting, "bench": b, "eval": res.metrics})

    outside, cut, total = boxes_outside_band(gt, heights, band)
    doc = {
        "conditions": {
            "command": "cone-perception " + " ".join(sys.argv[1:]) if sys.argv and "cone-perception" in sys.argv[0]
            else "cone-perception bench table ...",
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "cpu": f"{platform.machine()} {os.cpu_count()} cores",
            "backend": ", ".join(sorted({r["bench"]["backend"] for r in raw}))
            + (f" ({args.backend})" if args.backend == "auto" else ""), "threads": args.threads, "frames": args.frames, "warmup": args.warmup,
            "calibration": calib.source, "bench_image": f"{calib.image_width}x{calib.image_height}",
            "bench_band": f"{calib.crop.v0}-{calib.crop.v1}",
            "val": str(args.val), "val_images": len(heights), "val_size": f"{val_size[0]}x{val_size[1]}",
            "val_band": f"{band.v0}-{band.v1}", "val_boxes": total, "val_boxes_outside_band": outside,
            "val_boxes_not_inside_band": cut,
            "det_conf": args.det_conf, "conf": args.conf,
        },
        "rows": rows,
        "runs": raw,
    }
    md = format_markdown(doc)
    (args.out / "table.md").write_text(md, encoding="utf-8")
    (args.out / "table.json").write_text(json.dumps(json_safe(doc), indent=1) + "\n", encoding="utf-8")
    print(md)
    print(f"wrote {args.out / 'table.md'}, {args.out / 'table.json'} and {len(runs)} prediction files in {args.out / 'preds'}")
    return 0
