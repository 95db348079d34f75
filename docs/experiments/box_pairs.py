"""Two boxes of one cone, and far cones' range cues (issue 41, part 3, session 22), from `false_cones.py` recordings.

    .venv/bin/python docs/experiments/false_cones.py runs/tune_bags/tune-* --out DIR [--tag T -- --attitude image]
    .venv/bin/python docs/experiments/box_pairs.py DIR/tune-*.pkl --merge | --parts | --height | --rigidity

Each recording holds per frame the band's and the strip's boxes as their detectors drew them (before the merge), the
boxes kept, each kept box's cone, the attitude used; the truth comes from the drive beside it (`BAG_gt.jsonl`, the
rendered boxes; `/cones_gt`, `/attitude_gt`, `/odom`).

* `--merge`: every pair of a band box and a strip box of one cone (`farband.same_cone`) whose strip box outscores half
  the band box's (the merge before issue 41 kept the strip's), by the band box's height: the median IoU of each
  against the rendered box of that cone (the one the band box overlaps most), and how often the strip's is worse or
  better by more than 0.1 (`farband.FAR_MAX_BAND_PX`).
* `--parts`: the boxes as the pipeline kept them before issue 41 (the old merge, `one_box_per_cone` without the part
  rule) searched for parts of a taller box's cone (`mapping.part_of`); for each pair whether the taller box is the
  better box of the cone (IoU against the rendered box), for the taller box's least height and score ratio screened
  (`mapping.PART_MIN_PX`, `PART_WEAKER`).
* `--height`: the strip's kept boxes of cones 25-40 m away (truth): the range error of the cone as mapped (its foot and
  the attitude used) against the range at which the box's height fits the cone model there (`model_heights`).
* `--rigidity`: per drive, the pitch offset that makes the static cones' mapped steps between frames agree best with
  the odometry's motion (nearest-neighbour association), against the attitude's true pitch error.
"""

from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

import numpy as np

from cone_perception.data.bags import read_attitude_truth, read_twists
from cone_perception.detector.farband import FAR_PREFER, merge_boxes, same_cone
from cone_perception.geometry.calib import load_calibration
from cone_perception.mapping import ConeMapper, one_box_per_cone, part_of
from cone_perception.records import BoxColumns, xyxy_iou

sys.path.insert(0, str(Path(__file__).parent))
from false_cones import cone_of_box, load_gt_boxes, origin_of  # noqa: E402


def xyxy(b: np.ndarray) -> np.ndarray:
    return np.asarray(BoxColumns.of(b).xyxy, np.float64)


def merge_pairs(recs: list[dict]) -> None:
    rows = []
    for d in recs:
        gtb = load_gt_boxes(d["bag"] + "_gt.jsonl")
        for st, fr in d["frames"].items():
            b, f, g = fr["band"], fr["far"], gtb[st]["box"]
            if b is None or f is None or not len(b) or not len(f) or not len(g):
                continue
            for i, j in zip(*np.nonzero(same_cone(b, f))):
                if f["score"][j] < FAR_PREFER * b["score"][i]:
                    continue
                ib = xyxy_iou(xyxy(b[i:i + 1]), g)[0]
                k = int(ib.argmax())
                rows.append((b["v2"][i] - b["v1"][i], ib[k], xyxy_iou(xyxy(f[j:j + 1]), g[k:k + 1])[0, 0]))
    r = np.array(rows, float).reshape(-1, 3)
    for lo, hi in ((0, 16), (16, 24), (24, 32), (32, 48), (48, 64), (64, 96), (96, np.inf)):
        m = (r[:, 0] >= lo) & (r[:, 0] < hi)
        if m.any():
            print(f"band box {lo}-{hi} px: pairs {m.sum():5d}, median IoU band {np.median(r[m, 1]):.3f} strip "
                  f"{np.median(r[m, 2]):.3f}; strip worse by > 0.1 {np.mean(r[m, 2] < r[m, 1] - 0.1):.3f}, "
                  f"better by > 0.1 {np.mean(r[m, 2] > r[m, 1] + 0.1):.3f}")


def parts(recs: list[dict]) -> None:
    rows = []
    for d in recs:
        gtb = load_gt_boxes(d["bag"] + "_gt.jsonl")
        for st, fr in d["frames"].items():
            g = gtb[st]["box"]
            b = fr["band"] if fr["far"] is None else merge_boxes(fr["band"], fr["far"], max_band_px=np.inf)
            b = one_box_per_cone(b, part_inside=2.0)  # the boxes kept before issue 41
            if len(b) < 2 or not len(g):
                continue
            x = xyxy(b)
            for i, j in zip(*np.nonzero(part_of(x, min_px=0.0))):
                rows.append((x[i, 3] - x[i, 1], b["score"][i] / b["score"][j],
                             xyxy_iou(x[i:i + 1], g).max() >= xyxy_iou(x[j:j + 1], g).max()))
    r = np.array(rows, float).reshape(-1, 3)
    for min_px in (0, 32, 48, 64):
        for k in (0.0, 0.5, 0.6, 0.7, 0.8):
            m = (r[:, 0] >= min_px) & (r[:, 1] >= k)
            print(f"taller box >= {min_px:2d} px, scored >= {k}x the part's: pairs {m.sum():4d}, the taller the better "
                  f"{int((m & (r[:, 2] > 0)).sum()):4d}, the part the better {int((m & (r[:, 2] == 0)).sum()):3d}")


def height(recs: list[dict]) -> None:
    foot, size = [], []
    for d in recs:
        calib = load_calibration(d["calib"])
        model, gtb = ConeMapper(calib).image_attitude(), load_gt_boxes(d["bag"] + "_gt.jsonl")
        for st, fr in d["frames"].items():
            g, c = gtb.get(st), fr["cones"]
            if g is None:
                continue
            for bi, ci in enumerate(fr["cone_of"]):
                b = fr["boxes"][bi]
                if ci < 0 or origin_of(b, fr["band"], fr["far"]) != "strip":
                    continue
                k = cone_of_box([b["u1"], b["v1"], b["u2"], b["v2"]], g)
                if k < 0 or not 25 <= np.hypot(*g["xy"][k]) < 40:
                    continue
                xy = np.array([[c["x"][ci], c["y"][ci]]], float)
                rf, rt = float(np.hypot(*xy[0])), float(np.hypot(*g["xy"][k]))
                rh = rf * model.model_heights(xy, np.array([int(c["class_id"][ci])]))[0] / float(b["v2"] - b["v1"])
                foot.append(rf - rt)
                size.append(rh - rt)
    f, h = np.array(foot), np.array(size)
    print(f"{len(f)} strip cones 25-40 m: median |range error| by the foot {np.median(abs(f)):.2f} m (bias "
          f"{np.median(f):+.2f}), by the height {np.median(abs(h)):.2f} m (bias {np.median(h):+.2f}), their mean "
          f"{np.median(abs(f + h) / 2):.2f} m")


def rigidity(recs: list[dict]) -> None:
    for d in recs:
        calib = load_calibration(d["calib"])
        mp = calib.mount_pose
        cam, h = np.array([mp.x_m, mp.y_m]), mp.height_m
        tw, att = np.array(read_twists(d["bag"], "/odom")), read_attitude_truth(d["bag"])
        st = sorted(d["frames"])
        steps = []
        for a, b in zip(st[:-1], st[1:]):
            i = min(np.searchsorted(tw[:, 0], (a + b) / 2), len(tw) - 1)
            dt, (vx, vy, wz) = (b - a) * 1e-9, tw[i, 1:]
            c0, c1 = d["frames"][a]["cones"], d["frames"][b]["cones"]
            if len(c0) and len(c1):
                steps.append((np.c_[c0["x"], c0["y"]].astype(float), np.c_[c1["x"], c1["y"]].astype(float),
                              wz * dt, np.array([vx * dt, vy * dt])))

        def cost(k: float) -> float:  # positions r' -> r'/(1 - k r') about the camera's ground point
            def fix(p):
                q = p - cam
                r = np.hypot(q[:, 0], q[:, 1])
                return cam + q / np.clip(1 - k * r, 0.2, None)[:, None]
            total = 0.0
            for p0, p1, psi, t in steps:
                rot = np.array([[np.cos(psi), np.sin(psi)], [-np.sin(psi), np.cos(psi)]])
                pred, now = (fix(p0) - t) @ rot.T, fix(p1)
                dist = np.linalg.norm(pred[:, None] - now[None], axis=2)
                j = dist.argmin(1)
                r = np.hypot(*(now[j] - cam).T)
                ok = (dist[np.arange(len(j)), j] < 0.5 + 0.08 * r) & (r > 5) & (r < 40)
                along = ((pred - now[j]) * (now[j] - cam) / r[:, None]).sum(1)
                total += np.minimum((along[ok] / (0.02 + 0.002 * r[ok] ** 2)) ** 2, 9.0).sum()
            return total
        ks = np.linspace(-0.012, 0.012, 97)
        kb = ks[int(np.argmin([cost(k) for k in ks]))]
        err = [fr["attitude"].pitch_deg - att[s][0] for s, fr in d["frames"].items() if s in att]
        print(f"{Path(d['bag']).name:28s} the steps' pitch offset {np.degrees(kb * h):+.3f} deg; the attitude's true "
              f"pitch error median {np.median(err):+.3f} deg")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("recordings", nargs="+", type=Path, help="false_cones.py recordings (.pkl)")
    what = ap.add_mutually_exclusive_group(required=True)
    for name in ("merge", "parts", "height", "rigidity"):
        what.add_argument(f"--{name}", action="store_true")
    args = ap.parse_args()
    recs = []
    for p in args.recordings:
        with open(p, "rb") as f:
            recs.append(pickle.load(f))
    {"merge": merge_pairs, "parts": parts, "height": height, "rigidity": rigidity}[
        next(n for n in ("merge", "parts", "height", "rigidity") if getattr(args, n))](recs)


if __name__ == "__main__":
    main()
