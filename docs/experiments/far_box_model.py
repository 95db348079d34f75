"""How each network's boxes sit on the rendered cones, by box height, and what the image attitude makes of them
(issue 26f: the far model's own box table).

Each bag is run once through the band (its own model, halved) and the calibration's far strip at full
resolution, the strip run twice on the same pixels: with the far model (`models/cone_detector_far.pt`) and
with the band's model. Attitude fixed (the strip at the calibration's rows), boxes cached in
``--cache DIR`` (``NAME.farboxes.pkl``). Then, per source (band; strip, far model; strip, band's model):

* ``boxes``: detections at score >= 0.25 matched (own class, IoU >= 0.5) to a rendered cone whole in the
  image and in the rows that network saw (the bag's ``_gt.jsonl``, visible fraction >= 0.99): median height
  ratio, top low and bottom high (fractions of the rendered box's height; the sidecar's quantities), by the
  detected height in full-image px;
* ``residual``: the boxes the image fit would use (its selection: whole, near enough, standing) with the
  fit's cone model at the true attitude (``/attitude_gt``): median predicted minus observed top row (px),
  the rendered box-top table being half of it (docs/benchmarks.md, "Bias of the image fit"), with only
  ``top_bias_px`` (no table) applied;
* ``designs``: the image attitude (image mode, the shipped config) re-run over the cached boxes merged as the
  pipeline merges them, with the strip's boxes read through a table of their own or the band's, scored as
  ``replay --gt-topic`` scores (median error of matched cones 7-15 / 15-25 m, median |pitch| error).

    .venv/bin/python docs/experiments/far_box_model.py --cache /tmp/26f /tmp/a27/tune/djit104 /tmp/a27/tune/djit105 /tmp/a27/tune/djit106
"""
import argparse
import json
import pickle
import sys
from pathlib import Path

import numpy as np

from cone_perception.attitude import ImageAttitudeConfig
from cone_perception.geometry.calib import load_calibration
from cone_perception.mapping import ConeMapper

BINS = (8, 12, 16, 20, 24, 32, 48, 96, 1e9)
SOURCES = ("band", "strip_far", "strip_band")


def record(bag: str, cache: Path) -> dict:
    path = cache / (Path(bag).name + ".farboxes.pkl")
    if path.is_file():
        return pickle.loads(path.read_bytes())
    from cone_perception.data.bags import find_image_topic, iter_frames, read_attitude_truth, read_ground_truth
    from cone_perception.detector import Detector, default_model_path
    from cone_perception.detector.farband import FarBand, drop_cut_boxes
    from cone_perception.pipeline import Pipeline
    from cone_perception.replay import process_frame
    from cone_perception.resources import default_far_model_path

    cal = load_calibration(bag + "_calib.yaml")
    band = Detector.load_for_band(default_model_path(), (cal.crop.out_width, cal.crop.out_height))
    far = FarBand.for_calibration(default_far_model_path(), "auto", cal)
    other = Detector.load_for_band(default_model_path(), (far.crop.out_width, far.crop.out_height))
    rec = {}

    def detect(strip, crop=None, _orig=far.detect):
        crop = crop or far.crop
        a = _orig(strip, crop)
        rec["strip_far"], rec["strip_band"], rec["crop"] = a, drop_cut_boxes(other.detect(strip, crop), crop), (crop.v0, crop.v1)
        return a

    far.detect = detect

    def band_detect(img, crop, _orig=band.detect):
        rec["band"] = _orig(img, crop)
        return rec["band"]

    band.detect = band_detect
    pipe = Pipeline(cal, band, "fixed", far=far)
    frames = []
    for fr in iter_frames(bag, find_image_topic(bag)[0]):
        rec.clear()
        res = process_frame(pipe, fr)
        frames.append({"stamp": fr.stamp_ns, **rec, "merged": res.boxes})
    gt = {int(j["image"]): j for j in map(json.loads, Path(bag + "_gt.jsonl").read_text().splitlines())}
    d = {"frames": frames, "gt": gt, "truth": read_ground_truth(bag, "/cones_gt"), "att": read_attitude_truth(bag),
         "crop": (cal.crop.v0, cal.crop.v1)}
    path.write_bytes(pickle.dumps(d))
    print(f"cached {bag}: {len(frames)} frames", file=sys.stderr)
    return d


def _iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ix = np.clip(np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None)
    iy = np.clip(np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None)
    inter = ix * iy
    area = lambda x: (x[:, 2] - x[:, 0]) * (x[:, 3] - x[:, 1])  # noqa: E731
    return inter / (area(a)[:, None] + area(b)[None, :] - inter)


def xyxy(r: np.ndarray) -> np.ndarray:
    return np.column_stack([r["u1"], r["v1"], r["u2"], r["v2"]]).astype(np.float64)


def box_samples(d: dict, source: str, conf: float = 0.25, edge: float = 2.0) -> np.ndarray:
    """(n, 4): detected height (full px), height ratio, top low, bottom high against the rendered boxes."""
    out = []
    for f in d["frames"]:
        b = f[source]
        b = b[b["score"] >= conf]
        rows = d["crop"] if source == "band" else f["crop"]
        cones = [c for c in d["gt"][f["stamp"]]["cones"] if c["visible_fraction"] >= 0.99]
        if not len(b) or not cones:
            continue
        g = np.array([c["box"] for c in cones], dtype=np.float64)
        gc = np.array([c["class_id"] for c in cones])
        whole = (g[:, 1] > rows[0] + edge) & (g[:, 3] < rows[1] - edge) & (g[:, 0] > edge) & (g[:, 2] < 1920 - edge)
        p = xyxy(b)
        iou = _iou(p, g)
        iou[:, ~whole] = 0
        iou[b["class_id"][:, None] != gc[None, :]] = 0
        for i in range(len(p)):
            j = int(np.argmax(iou[i]))
            if iou[i, j] < 0.5:
                continue
            lh = g[j, 3] - g[j, 1]
            out.append((p[i, 3] - p[i, 1], (p[i, 3] - p[i, 1]) / lh, (p[i, 1] - g[j, 1]) / lh, (g[j, 3] - p[i, 3]) / lh))
    return np.array(out).reshape(-1, 4)


def residual_samples(bag: str, d: dict, source: str) -> np.ndarray:
    """(n, 2): box height (full px), top-row residual at the true attitude (px; only ``top_bias_px`` applied)."""
    est = ConeMapper(load_calibration(bag + "_calib.yaml")).image_attitude(ImageAttitudeConfig(top_bias_extra_px=()))
    out = []
    for f in d["frames"]:
        b = f[source]
        if not len(b):
            continue
        p, cls = xyxy(b), b["class_id"].astype(np.intp)
        sel = est._select(p, cls)
        if not sel.any():
            continue
        rays, vt, c = est._prepare(p[sel], cls[sel])
        r = est.residuals(np.asarray(d["att"][f["stamp"]], dtype=np.float64), rays, vt, c)
        out += list(zip(p[sel, 3] - p[sel, 1], r))
    return np.array(out).reshape(-1, 2)


def designs(band_table: tuple, res_far: dict) -> list:
    """(name, strip source, far reading or None) of the designs scored; ``res_far``: bin lower edge -> (bin
    centre px, median residual px) of the far model's strip boxes."""
    from cone_perception.attitude.boxes import BoxReading

    half = tuple((h, 0.5 * r) for h, r in res_far.values())
    full = tuple((h, r) for h, r in res_far.values())
    return [("band only (no strip)", None, None),
            ("band's model in the strip", "strip_band", None),
            ("far model, its boxes through the band's table (before)", "strip_far", None),
            ("far model, no table for its boxes", "strip_far", BoxReading(None, ())),
            ("far model, its own table: half its residual", "strip_far", BoxReading(None, half)),
            ("far model, its own table: its full residual", "strip_far", BoxReading(None, full))], half, full


def score_design(bag: str, d: dict, source, reading) -> tuple[float, float, float]:
    """(median error 7-15 m, 15-25 m, median |pitch| error deg) of the image attitude over the cached boxes."""
    from cone_perception.attitude import attitude_for_boxes
    from cone_perception.detector.farband import drawn_by_far, merge_boxes
    from cone_perception.evaluation import LocalisationReport

    m = ConeMapper(load_calibration(bag + "_calib.yaml"))
    est = m.image_attitude(ImageAttitudeConfig(far_reading=reading))
    rep, ep = LocalisationReport(max_range_m=m.calib.max_range_m), []
    for f in d["frames"]:
        boxes, far = f["band"], None
        if source is not None:
            boxes = merge_boxes(f["band"], f[source])
            far = drawn_by_far(boxes, f[source])
        a = attitude_for_boxes(est, boxes, f["stamp"], far)
        rep.add_frame(m.map_boxes(boxes, a), d["truth"][f["stamp"]])
        ep.append(abs(a.pitch_deg - d["att"][f["stamp"]][0]))
    s = rep.summary()
    return s["groups"]["far 7-15 m"]["median_err_m"], s["extra_groups"]["15-25 m"]["median_err_m"], float(np.median(ep))


def binned(h: np.ndarray, cols: list[np.ndarray]) -> list:
    rows = []
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        m = (h >= lo) & (h < hi)
        rows.append((lo, hi, int(m.sum()), [float(np.median(c[m])) if m.any() else float("nan") for c in cols]))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bags", nargs="+")
    ap.add_argument("--cache", required=True, type=Path, help="folder for the cached boxes (NAME.farboxes.pkl)")
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    bags = [b.rstrip("/") for b in args.bags]
    data = {b: record(b, args.cache) for b in bags}
    print(f"drives: {', '.join(Path(b).name for b in bags)}\n")
    print("| source | box height (full px) | boxes matched | height ratio | top low | bottom high | fit's boxes | median top residual at the true attitude (px) |")
    print("|---|---|---|---|---|---|---|---|")
    for s in SOURCES:
        bx = np.concatenate([box_samples(data[b], s) for b in bags])
        rs = np.concatenate([residual_samples(b, data[b], s) for b in bags])
        rb = {r[0]: r for r in binned(rs[:, 0], [rs[:, 1]])}
        for lo, hi, n, (ratio, top, bot) in binned(bx[:, 0], [bx[:, 1], bx[:, 2], bx[:, 3]]):
            r = rb[lo]
            if n == 0 and r[2] == 0:
                continue
            name = f"{lo:g}-{hi:g}" if hi < 1e8 else f">= {lo:g}"
            print(f"| {s} | {name} | {n} | {ratio:.3f} | {100 * top:+.1f} % | {100 * bot:+.1f} % | {r[2]} | {r[3][0]:+.2f} |")
        if s == "strip_far":
            res_far = {lo: (0.5 * (lo + min(hi, 2 * lo)), v[0]) for lo, hi, n, v in binned(rs[:, 0], [rs[:, 1]]) if n >= 50}
    table_designs, half, full = designs(ImageAttitudeConfig().top_bias_extra_px, res_far)
    print(f"\nthe far model's table at half its residual: {tuple((round(h, 1), round(v, 2)) for h, v in half)}")
    print(f"at its full residual: {tuple((round(h, 1), round(v, 2)) for h, v in full)}\n")
    print("| design | " + " | ".join(f"{Path(b).name} 7-15 m / 15-25 m / pitch err" for b in bags) + " | mean 7-15 m | mean 15-25 m |")
    print("|---|" + "---|" * (len(bags) + 2))
    for name, source, reading in table_designs:
        r = [score_design(b, data[b], source, reading) for b in bags]
        print(f"| {name} | " + " | ".join(f"{a:.3f} / {b:.3f} / {c:.3f}" for a, b, c in r)
              + f" | {np.mean([x[0] for x in r]):.3f} | {np.mean([x[1] for x in r]):.3f} |", flush=True)


if __name__ == "__main__":
    main()
