"""The rendered validation at the default settings: each track's far strip placed from its own camera (issue 26).

    .venv/bin/python docs/experiments/strip_per_camera.py data/synth_val77 --out runs/eval/s77_percam \
        [--strip camera | --strip 370,466] [--max-range 40,25] [-- DETECT OPTIONS, e.g. --model M --far-model F]

`synth dataset --vary-mount` gives every track its own camera (focal length, mount height and pitch), written per
frame in gt.jsonl; its calib.yaml is the nominal camera only. The cards' rendered figures run every frame with the
strip rows of the nominal camera (`detect --far-rows 370,466`), which for most tracks is not where their far cones
stand. On the car the strip is placed from the calibration of the camera it runs (`far_rows: auto`,
`geometry/strip.plan_strip`).

This runs `cone-perception detect` over the frames of each camera with the strip rows `plan_strip` gives that
camera (`--strip camera`, at its rest attitude, the strip's margins included) or fixed rows (`--strip V0,V1`, the
cards' way), and the cards' band (`--crop 368,1080 --downscale 2`), which for a camera whose strip lies above row
368 starts at the strip's top, as its own calibration's band would; both ways use the same bands. Each camera's
frames are scored in its own band as `far_strip_recall.py` scores (IoU 0.5, score 0.25, box heights at the
model input: half the full-resolution px) and the counts are summed; scored again leaving out cones beyond
`--max-range` (default 40 m, issue 26's design range) as ignore regions. OUT/cam*.jsonl are the prediction files,
OUT/summary.json the counts.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from collections import defaultdict
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from cone_perception.data.predictions import read_predictions
from cone_perception.evaluation.groundtruth import load_ground_truth, pair_with_predictions, restrict_to_band
from cone_perception.geometry.camera import MountPose, PinholeCamera
from cone_perception.geometry.strip import plan_strip

sys.path.insert(0, str(Path(__file__).parent))
from far_strip_recall import _at  # noqa: E402  (the same scoring)

BINS = (0.0, 8.0, 12.0, 24.0, 1000.0)


def strip_rows(record: dict) -> tuple[int, int]:
    """The default strip's rows (V0, V1) for the camera of one gt.jsonl record."""
    c = record["camera"]
    cam = PinholeCamera(np.asarray(c["K"], dtype=np.float64), int(record["width"]), int(record["height"]),
                        MountPose(**c["mount"]), np.asarray(c.get("dist_coeffs") or [], dtype=np.float64))
    plan = plan_strip(cam, source=record["image"])
    return plan.top0, plan.top0 + plan.height


def _score(gt, preds, conf: float, max_range: float | None, strip_arg: str) -> dict:
    """Each camera's frames scored in its own band, the counts summed; printed and returned."""
    score = SimpleNamespace(scale=0.5, iou=0.5, max_range=max_range)
    n, found, tp, dets, rows = np.zeros(len(BINS) - 1, int), np.zeros(len(BINS) - 1, int), 0, 0, []
    within = "any range" if max_range is None else f"within {max_range:g} m"
    for (v0, v1), strip, band, frames, pred in preds:
        paired, _ = pair_with_predictions(gt, list(read_predictions(str(pred))), str(pred), True)
        paired, _ = restrict_to_band(paired, band)
        r = _at(paired, conf, list(BINS), score)
        for j, v in enumerate(r["bins"].values()):
            n[j] += v["cones"]
            found[j] += v["found"]
        tp += round(r["precision"] * r["detections"])
        dets += r["detections"]
        rows.append({"camera_strip": [v0, v1], "strip": strip, "band": list(band), "frames": frames, **r})
        small = r["bins"]["0-8"]
        print(f"camera strip {v0}-{v1}, strip {strip}, band {band[0]}-{band[1]}, {within}: {frames} frames, "
              f"0-8 px {small['found']}/{small['cones']}, precision {r['precision']:.3f}")
    out = {"strip": strip_arg, "max_range": max_range, "conf": conf, "precision": tp / max(dets, 1),
           "bins": {f"{BINS[j]:g}-{BINS[j + 1]:g}": {"cones": int(n[j]), "found": int(found[j]),
                                                     "recall": found[j] / n[j] if n[j] else None}
                    for j in range(len(BINS) - 1)}, "cameras": rows}
    print(f"all cameras, strip {strip_arg}, cones {within}: precision {out['precision']:.3f}")
    for k, v in out["bins"].items():
        print(f"  {k} px: {v['found']}/{v['cones']} recall {v['recall']:.3f}")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path, help="a `synth dataset` folder (gt.jsonl, images/)")
    ap.add_argument("--out", type=Path, required=True, help="output folder (prediction files, summary.json)")
    ap.add_argument("--strip", default="camera", help="camera (each camera's own strip) or V0,V1 (fixed rows)")
    ap.add_argument("--split", default="val", help="images/<split>/ (default val)")
    ap.add_argument("--band", default="368,1080", help="the band's rows, halved (default 368,1080: the cards')")
    ap.add_argument("--max-range", default="40", help="also score leaving out cones farther than these (m, comma list)")
    ap.add_argument("--conf", type=float, default=0.25)
    ap.add_argument("detect_opts", nargs="*", help="after --: more `detect` options (--model, --far-model)")
    args = ap.parse_args(argv)
    cli = str(Path(sys.executable).with_name("cone-perception"))
    groups: dict[tuple[int, int], list[Path]] = defaultdict(list)
    for line in (args.dataset / "gt.jsonl").read_text().splitlines():
        rec = json.loads(line)
        if f"/{args.split}/" in rec["image"]:
            groups[strip_rows(rec)].append(args.dataset / rec["image"])
    if not groups:
        ap.error(f"no {args.split} frames in {args.dataset / 'gt.jsonl'}")
    gt = load_ground_truth(str(args.dataset / "gt.jsonl"))
    b0, b1 = (int(v) for v in args.band.split(","))
    args.out.mkdir(parents=True, exist_ok=True)
    preds = []
    for i, ((v0, v1), images) in enumerate(sorted(groups.items())):
        band = (min(b0, v0 - v0 % 2), b1)  # a camera whose far cones stand above the band: its band reaches them
        strip = f"{v0},{v1}" if args.strip == "camera" else args.strip
        pred = args.out / f"cam{i}.jsonl"
        with tempfile.TemporaryDirectory() as tmp:
            for im in images:
                (Path(tmp) / im.name).symlink_to(im.resolve())
            subprocess.run([cli, "detect", tmp, "--crop", f"{band[0]},{band[1]}", "--downscale", "2",
                            "--far-rows", strip, "--conf", "0.001", "--out", str(pred), "--no-progress",
                            *args.detect_opts],
                           check=True, stdout=subprocess.DEVNULL)
        preds.append(((v0, v1), strip, band, len(images), pred))
    summary = {}
    for max_range in [None] + [float(v) for v in (args.max_range or "").split(",") if v]:
        summary["any" if max_range is None else f"{max_range:g}"] = _score(gt, preds, args.conf, max_range, args.strip)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
