"""Gates against boxes on no cone, screened on recorded drives (session 16; docs/benchmarks.md "Yellow paint").

    .venv/bin/python docs/experiments/false_cones_gates.py PKL [PKL ...] [--strip-rows 380,456] [--sheet OUT.jpg]

Each PKL is a recording of `docs/experiments/false_cones.py BAG --out DIR --tag T` (DIR/BAG_T.pkl): every
frame's boxes (band, strip, merged), `/cones` and each cone's box. Screens, each after the fact on `/cones`
(a cone taken out is simply gone; the replay's other steps are not rerun), summed over the PKLs:

* ``threshold``: a higher score threshold for the strip's and the band's cones: recall per range group and false
  cones within 40 m per frame (the match of `replay --gt-topic`);
* ``strip veto``: band boxes wholly inside the strip's rows (`--strip-rows`, the example calibration's strip
  370-466 less the 10 px the attitude moves it) that the strip did not find: true / false by range and score;
* ``too tall``: cones whose box is taller than R x the height a cone has where its foot maps
  (`ConeMapper.height_ratios`, the flat gate's ratio the other way): true / false by range and score.

`--sheet OUT.jpg`: a contact sheet of the phantoms (false_cones.py's class: a box on no true cone's box), each
patch with the true boxes in green and the phantom in red (the first PKL only; 24 spread over the drive).
"""
from __future__ import annotations

import argparse
import importlib.util
import pickle
from pathlib import Path

import cv2
import numpy as np

from cone_perception.data.bags import read_bag_images, read_ground_truth
from cone_perception.evaluation import match_cones
from cone_perception.geometry.calib import load_calibration
from cone_perception.mapping import ConeMapper

_spec = importlib.util.spec_from_file_location("false_cones", Path(__file__).with_name("false_cones.py"))
fc = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fc)

BANDS = ((0, 7), (7, 15), (15, 25), (25, 40))


def cone_rows(data: dict) -> list[dict]:
    """One row per `/cones` cone of every frame with truth: range, its box's origin, score, class, height ratio,
    whether the box lies wholly inside ``strip`` rows, matched; plus the frame's true cones for recall."""
    truth = read_ground_truth(data["bag"], "/cones_gt")
    mapper = ConeMapper(load_calibration(data["calib"]))
    frames = []
    for stamp, fr in sorted(data["frames"].items()):
        if stamp not in truth:
            continue
        t = truth[stamp]
        c = fr["cones"]
        box_of = np.full(len(c), -1)
        for bi, ci in enumerate(fr["cone_of"]):
            if ci >= 0:
                box_of[ci] = bi
        boxes = fr["boxes"][box_of]
        xy = np.c_[c["x"], c["y"]].astype(float)
        frames.append({
            "t_xy": np.c_[t["x"], t["y"]].astype(float), "t_vis": np.asarray(t["score"]) >= 0.5, "xy": xy,
            "score": boxes["score"].astype(float), "v1": boxes["v1"].astype(float), "v2": boxes["v2"].astype(float),
            "strip": np.array([fc.origin_of(b, fr["band"], fr["far"]) == "strip" for b in boxes], bool),
            "ratio": mapper.height_ratios(boxes, xy) if len(boxes) else np.zeros(0),
        })
    return frames


def _matched(p_xy: np.ndarray, t_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(which detections, which true cones) the match of `replay --gt-topic` pairs."""
    mp, mt = np.zeros(len(p_xy), bool), np.zeros(len(t_xy), bool)
    for i, j, _ in match_cones(p_xy, t_xy):
        mp[i], mt[j] = True, True
    return mp, mt


def score_frames(frames: list[dict], keep_fn) -> tuple[np.ndarray, float, int, int]:
    """(recall per BANDS group of cones at least half visible, false cones within 40 m per frame, cones taken out
    that matched before, taken out that did not) with the cones ``keep_fn(frame) -> bool mask`` keeps."""
    tot, hit, false, out_true, out_false = np.zeros(4), np.zeros(4), 0, 0, 0
    for f in frames:
        keep = keep_fn(f)
        within = np.hypot(*f["xy"].T) < 40 if len(f["xy"]) else np.zeros(0, bool)
        m_all, _ = _matched(f["xy"], f["t_xy"])
        out_true += int((~keep & m_all & within).sum())
        out_false += int((~keep & ~m_all & within).sum())
        mp, mt = _matched(f["xy"][keep], f["t_xy"])
        tr = np.hypot(*f["t_xy"].T) if len(f["t_xy"]) else np.zeros(0)
        for k, (lo, hi) in enumerate(BANDS):
            s = f["t_vis"] & (tr >= lo) & (tr < hi)
            tot[k] += s.sum()
            hit[k] += (mt & s).sum()
        false += int((~mp & within[keep]).sum())
    return hit / np.maximum(tot, 1), false / max(len(frames), 1), out_true, out_false


def phantom_sheet(data: dict, out: str, most: int = 24) -> int:
    a = fc.analyse(data)
    ph = [r for r in a["rows"] if r["kind"] == "phantom"]
    n = len(ph)
    ph = ph[::max(1, -(-n // most))][:most]  # spread over the drive
    imgs = read_bag_images(data["bag"], {r["stamp"] for r in ph})
    gtb = fc.load_gt_boxes(f"{data['bag']}_gt.jsonl")
    s, tiles = 60, []
    for r in ph:
        fr = data["frames"][r["stamp"]]
        b = [x for x in fr["boxes"] if abs(float(x["score"]) - r["score"]) < 1e-6
             and abs(float(x["v2"] - x["v1"]) - r["h_px"]) < 1e-4][0]
        img = imgs[r["stamp"]].copy()
        for tb in gtb[r["stamp"]]["box"]:
            cv2.rectangle(img, (int(tb[0]), int(tb[1])), (int(tb[2]), int(tb[3])), (0, 255, 0), 1)
        cv2.rectangle(img, (int(b["u1"]), int(b["v1"])), (int(b["u2"]), int(b["v2"])), (0, 0, 255), 1)
        cu, cv_ = int((b["u1"] + b["u2"]) / 2), int((b["v1"] + b["v2"]) / 2)
        y0, x0 = max(cv_ - s, 0), max(cu - 2 * s, 0)
        p = img[y0:y0 + 2 * s, x0:x0 + 4 * s]
        p = cv2.copyMakeBorder(p, 0, 2 * s - p.shape[0], 0, 4 * s - p.shape[1], cv2.BORDER_CONSTANT)
        p = cv2.resize(p, (4 * s, 2 * s), interpolation=cv2.INTER_AREA)
        cv2.putText(p, f"{r['origin']} {r['range']:.0f} m score {r['score']:.2f} class {int(b['class_id'])}", (4, 16),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.35, (255, 255, 255), 1)
        tiles.append(p)
    if tiles:
        cols = 4
        tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % cols)
        cv2.imwrite(out, np.vstack([np.hstack(tiles[i:i + cols]) for i in range(0, len(tiles), cols)]), [cv2.IMWRITE_JPEG_QUALITY, 85])
    return n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("pkls", nargs="+")
    ap.add_argument("--strip-rows", default="380,456", help="V0,V1: a band box wholly inside is the veto's (default %(default)s)")
    ap.add_argument("--sheet", default=None, help="contact sheet (JPEG) of the first PKL's phantoms")
    args = ap.parse_args()
    v0, v1 = (float(x) for x in args.strip_rows.split(","))
    datas = [pickle.load(open(p, "rb")) for p in args.pkls]
    frames = [f for d in datas for f in cone_rows(d)]
    print(f"{len(args.pkls)} recordings, {len(frames)} frames; recall 0-7 / 7-15 / 15-25 / 25-40 m, false cones per frame")
    rng = lambda f: np.hypot(*f["xy"].T) if len(f["xy"]) else np.zeros(0)  # noqa: E731
    print("\nthreshold (strip, band)")
    for ts, tb in ((0.25, 0.25), (0.3, 0.3), (0.35, 0.35), (0.4, 0.4), (0.5, 0.5), (0.4, 0.25), (0.25, 0.4)):
        rec, fpf, ot, of = score_frames(frames, lambda f: f["score"] >= np.where(f["strip"], ts, tb))
        print(f"  {ts:.2f} / {tb:.2f}: recall {' '.join(f'{x:.3f}' for x in rec)}  false {fpf:.3f}  (taken out: {ot} true, {of} false)")
    print(f"\nstrip veto (band boxes wholly in rows {v0:g}-{v1:g} the strip did not find, from 15 m)")
    for s in (0.5, 1.01):
        keep = lambda f: ~((~f["strip"]) & (f["v1"] >= v0) & (f["v2"] <= v1) & (f["score"] < s) & (rng(f) >= 15))  # noqa: E731
        rec, fpf, ot, of = score_frames(frames, keep)
        print(f"  score below {s:g}: recall {' '.join(f'{x:.3f}' for x in rec)}  false {fpf:.3f}  (taken out: {ot} true, {of} false)")
    print("\nnear threshold (cones nearer than 15 m need this score)")
    for s in (0.4, 0.5):
        rec, fpf, ot, of = score_frames(frames, lambda f: ~((rng(f) < 15) & (f["score"] < s)))
        print(f"  {s:g}: recall {' '.join(f'{x:.3f}' for x in rec)}  false {fpf:.3f}  (taken out: {ot} true, {of} false)")
    print("\ntoo tall (box height over R x a cone's there, boxes scoring under 0.5)")
    for r in (1.3, 1.4, 1.5):
        rec, fpf, ot, of = score_frames(frames, lambda f: ~((f["ratio"] > r) & (f["score"] < 0.5)))
        print(f"  R {r:g}: recall {' '.join(f'{x:.3f}' for x in rec)}  false {fpf:.3f}  (taken out: {ot} true, {of} false)")
    if args.sheet:
        print(f"\n{phantom_sheet(datas[0], args.sheet)} phantoms of {args.pkls[0]} -> {args.sheet}")


if __name__ == "__main__":
    main()
