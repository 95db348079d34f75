"""What the false cones within 40 m are (issue 26g): a breakdown per drive of `/cones` and `/cones/tracked`.

    .venv/bin/python docs/experiments/false_cones.py BAG [BAG ...] [--out DIR] [--tag T] [--calib-suffix S | --calib C ...] [--reuse]
        [--no-one-box] [-- REPLAY OPTIONS, e.g. --one-ray-range 0]

Each BAG is a `cone-perception synth bag` drive (BAG_calib.yaml, BAG_gt.jsonl beside it). The drive is replayed
with `cone-perception replay BAG --calib BAG_calib.yaml --gt-topic /cones_gt --track` and the REPLAY OPTIONS
(e.g. `--far-model band`, `--tracker spawn_max_m=2.5`): the same code and defaults as the issue's figures. The
replay is recorded per frame (the band's boxes, the strip's boxes, the merged boxes, the attitude used, each
box's cone; /cones/tracked) to DIR/NAME.pkl (`--reuse`: read it instead of replaying).

Each false cone of `/cones` (a detection on no true cone within the match gate, 0.5 m + 10 % of the range,
closer than 40 m; what `replay --gt-topic` counts) is put in one class, by the true cone its box is of (the
truth's rendered boxes in BAG_gt.jsonl: centres within half the taller box's height, heights within 2x, the
best such):

* ``duplicate``: its cone has another box in the frame (band+strip: one box from each; band+band or
  strip+strip: two from one detector);
* ``misplaced``: its cone's only box, unmatched; reported by the box's origin and range, split into the range
  error (along the ray) and bearing error (across it), the share within the gate whose cone another detection
  took (the greedy nearest-first matching along a row placed nearer), and by cause: the cone mapped from its
  RENDERED box with the attitude used (the attitude's part) and from the detected box with the TRUE attitude
  (``/attitude_gt``: the box's part);
* ``beyond``: its cone stands beyond 40 m (a far cone placed nearer);
* ``phantom``: no true cone's box there.

Each false cone of `/cones/tracked` within 40 m: ``duplicate`` (the nearest true cone within 6 m is matched to
another track), ``misplaced`` (that cone is matched by no track: this track is it, too far off), ``phantom``
(no true cone within 6 m); with the range and bearing offset to that cone.
"""
from __future__ import annotations

import argparse
import json
import pickle
import sys
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from cone_perception import pipeline as pipeline_mod
from cone_perception.attitude import Attitude
from cone_perception.cli import main
from cone_perception.data.bags import read_attitude_truth, read_ground_truth
from cone_perception.evaluation import match_cones
from cone_perception.evaluation.tracking import load_drive_truth
from cone_perception.geometry.calib import load_calibration
from cone_perception.mapping import ConeMapper
from cone_perception.records import BOX_DTYPE
from cone_perception.replay import run as replay_run

RANGE_M = 40.0
BANDS = ((0, 7), (7, 15), (15, 25), (25, 40))


def record(bag: str, calib: str, out: Path, replay_opts: list[str]) -> dict:
    """Replay ``bag`` (the replay command with ``replay_opts``) and record every frame."""
    frames, cur = {}, {}
    orig_merge, orig_run, orig_replay = pipeline_mod.merge_boxes, pipeline_mod.Pipeline._run, replay_run.offline_replay

    def merge(band, far, *a, **kw):
        cur["band"], cur["far"] = band.copy(), far.copy()
        return orig_merge(band, far, *a, **kw)

    def run(self, *a, **kw):
        cur.clear()
        r = orig_run(self, *a, **kw)
        stamp = a[3] if len(a) > 3 else kw.get("stamp_ns")
        # each merged box's cone (or -1: dropped by the mapping: above the horizon or beyond the range, flat, or
        # a second cone on one viewing ray); the mapper's counts left as the replay made them
        cone_of = np.full(len(r.boxes), -1)
        k = 0
        dropped = dict(self.mapper.dropped)
        mapped = np.zeros(len(r.boxes), bool)
        for i in range(len(r.boxes)):
            mapped[i] = len(self.mapper.map_boxes(r.boxes[i:i + 1], r.attitude)) == 1
        ray, self.mapper.one_ray_range_m = self.mapper.one_ray_range_m, 0.0  # the frame's cones before the rule
        all_cones = self.mapper.map_boxes(r.boxes[mapped], r.attitude)
        self.mapper.one_ray_range_m = ray
        _, kept = self.mapper.one_per_ray(all_cones)  # the one-ray rule keeps a subset of them, in order
        for n, i in enumerate(np.flatnonzero(mapped)):
            if kept[n]:
                cone_of[i] = k
                k += 1
        assert k == len(r.cones), (k, len(r.cones))
        self.mapper.dropped.clear()
        self.mapper.dropped.update(dropped)
        frames[stamp] = {"boxes": r.boxes.copy(), "cones": r.cones.copy(), "cone_of": cone_of, "attitude": r.attitude,
                         "band": cur.get("band"), "far": cur.get("far")}
        return r

    res_box = {}

    def replay(*a, **kw):
        res = orig_replay(*a, **kw)
        res_box["res"] = res
        return res

    pipeline_mod.merge_boxes, pipeline_mod.Pipeline._run, replay_run.offline_replay = merge, run, replay
    try:
        rc = main(["replay", bag, "--calib", calib, "--gt-topic", "/cones_gt", "--track", "--no-progress",
                   "--json", str(out.with_suffix(".json")), *replay_opts])
    finally:
        pipeline_mod.merge_boxes, pipeline_mod.Pipeline._run, replay_run.offline_replay = orig_merge, orig_run, orig_replay
    if rc != 0:
        raise SystemExit(f"replay of {bag} failed (rc {rc})")
    data = {"bag": bag, "calib": calib, "opts": replay_opts, "frames": frames, "tracked": res_box["res"].tracked}
    with open(out, "wb") as f:
        pickle.dump(data, f)
    return data


def load_gt_boxes(path: str) -> dict[int, dict]:
    """stamp ns -> true cones of the frame: xy (rear_axle m), class, rendered box, foot px, visible fraction."""
    out = {}
    with open(path, encoding="utf-8") as f:
        for line in f:
            d = json.loads(line)
            cs = d["cones"]
            out[int(d["image"])] = {
                "xy": np.array([[c["x_m"], c["y_m"]] for c in cs], float).reshape(-1, 2),
                "cls": np.array([c["class_id"] for c in cs], int),
                "box": np.array([c["box"] for c in cs], float).reshape(-1, 4),
                "foot": np.array([c["foot_px"] for c in cs], float).reshape(-1, 2),
                "vis": np.array([c.get("visible_fraction", 1.0) for c in cs], float),
            }
    return out


def cone_of_box(box, gt) -> int:
    """Index of the true cone ``box`` (u1, v1, u2, v2) is of, or -1 (the merge's `same_cone` test against the
    rendered boxes: centres within half the taller box's height, heights within 2x; the nearest centre)."""
    if len(gt["box"]) == 0:
        return -1
    tb = gt["box"]
    bc = np.array([(box[0] + box[2]) / 2, (box[1] + box[3]) / 2])
    tc = np.c_[(tb[:, 0] + tb[:, 2]) / 2, (tb[:, 1] + tb[:, 3]) / 2]
    bh, th = box[3] - box[1], tb[:, 3] - tb[:, 1]
    d = np.hypot(*(tc - bc).T)
    ok = (d <= 0.5 * np.maximum(bh, th)) & (bh <= 2 * th) & (th <= 2 * bh)
    if not ok.any():
        return -1
    return int(np.flatnonzero(ok)[np.argmin(d[ok])])


def radial_lateral(p, t):
    """Offset of ``p`` from ``t`` (m) along the ray to ``t`` (range error, + farther) and across it (bearing)."""
    r = np.hypot(*t)
    u = np.asarray(t) / max(r, 1e-9)
    d = np.asarray(p) - np.asarray(t)
    return float(d @ u), float(d[0] * -u[1] + d[1] * u[0])


def band_of(r):
    for lo, hi in BANDS:
        if lo <= r < hi:
            return f"{lo}-{hi} m"
    return ">= 40 m"


def origin_of(box, band, far) -> str:
    """``strip`` or ``band``: which detector gave this merged box (the strip's boxes are recorded per frame)."""
    if far is None or len(far) == 0:
        return "band"
    same = (np.abs(far["u1"] - box["u1"]) < 1e-3) & (np.abs(far["v1"] - box["v1"]) < 1e-3) & (np.abs(far["u2"] - box["u2"]) < 1e-3)
    return "strip" if same.any() else "band"


def max_matched(p_xy: np.ndarray, t_xy: np.ndarray) -> np.ndarray:
    """(diagnosis) which predictions a maximum one-to-one matching within the same gate pairs (then least distance)."""
    m = np.zeros(len(p_xy), bool)
    if len(p_xy) == 0 or len(t_xy) == 0:
        return m
    d = np.linalg.norm(p_xy[:, None] - t_xy[None], axis=2)
    cost = np.where(d <= 0.5 + 0.1 * np.hypot(*t_xy.T)[None], d, 1e6)
    r, c = linear_sum_assignment(cost)
    m[r[cost[r, c] < 1e6]] = True
    return m


def analyse(data: dict) -> dict:
    bag, calib = data["bag"], load_calibration(data["calib"])
    mapper = ConeMapper(calib)
    truth = read_ground_truth(bag, "/cones_gt")
    att_true = read_attitude_truth(bag)
    gtb = load_gt_boxes(f"{bag}_gt.jsonl")
    counts, rows = Counter(), []
    n_frames = opt_false = 0
    for stamp, fr in sorted(data["frames"].items()):
        if stamp not in truth:
            continue
        n_frames += 1
        t = truth[stamp]
        g = gtb[stamp]
        t_xy = np.c_[t["x"], t["y"]].astype(float)
        cones = fr["cones"]
        p_xy = np.c_[cones["x"], cones["y"]].astype(float)
        pairs = match_cones(p_xy, t_xy)
        opt_false += int((~max_matched(p_xy, t_xy) & (np.hypot(*p_xy.T) < RANGE_M)).sum()) if len(p_xy) else 0
        matched = np.zeros(len(cones), bool)
        matched[[i for i, _, _ in pairs]] = True
        # the truth topic and the gt file list the same cones; index the file's by position
        gt_to_t = np.array([int(np.argmin(np.hypot(*(t_xy - x).T))) for x in g["xy"]]) if len(t_xy) else np.zeros(0, int)
        t_matched = np.zeros(len(t_xy), bool)
        for _, j, _ in pairs:
            t_matched[j] = True
        box_cone = np.array([cone_of_box((b["u1"], b["v1"], b["u2"], b["v2"]), g) for b in fr["boxes"]], int)
        cone_box = {c: i for i, c in enumerate(fr["cone_of"]) if c >= 0}
        pt, rt = att_true.get(stamp, (0.0, 0.0))
        att = fr["attitude"]
        for ci in range(len(cones)):
            r = float(np.hypot(*p_xy[ci]))
            if matched[ci] or r >= RANGE_M:
                continue
            bi = cone_box[ci]
            box = fr["boxes"][bi]
            org = origin_of(box, fr["band"], fr["far"])
            gi = box_cone[bi]
            row = {"stamp": stamp, "range": r, "origin": org, "score": float(box["score"]),
                   "h_px": float(box["v2"] - box["v1"])}
            if gi < 0:
                row["kind"] = "phantom"
            else:
                others = [k for k in np.flatnonzero(box_cone == gi) if k != bi]
                tr = float(np.hypot(*g["xy"][gi]))
                row.update(true_range=tr, cls_ok=int(box["class_id"]) == int(g["cls"][gi]))
                dr, dl = radial_lateral(p_xy[ci], g["xy"][gi])
                row.update(dr=dr, dl=dl, err=float(np.hypot(dr, dl)), gate=0.5 + 0.1 * tr)
                if others:
                    o = others[0]
                    row["kind"] = "duplicate"
                    row["pair"] = "+".join(sorted([org, origin_of(fr["boxes"][o], fr["band"], fr["far"])]))
                    oc = fr["cone_of"][o]
                    row["other_matched"] = bool(oc >= 0 and matched[oc])
                    if oc >= 0:
                        row["sep"] = float(np.hypot(*(p_xy[oc] - p_xy[ci])))
                        row["sep_dr"], row["sep_dl"] = radial_lateral(p_xy[ci], p_xy[oc])
                        row["other_h_px"] = float(fr["boxes"][o]["v2"] - fr["boxes"][o]["v1"])
                        row["other_origin"] = origin_of(fr["boxes"][o], fr["band"], fr["far"])
                        row["other_score"] = float(fr["boxes"][o]["score"])
                elif tr >= RANGE_M:
                    row["kind"] = "beyond"
                else:
                    row["t_matched"] = bool(t_matched[gt_to_t[gi]]) if len(gt_to_t) else False
                    row["kind"] = "row shift" if row["t_matched"] and row["err"] <= row["gate"] else "misplaced"
                    # cause: the true foot with the attitude used; the detected foot with the true attitude
                    # the rendered box through the same foot rule (the truth file's foot_px follows another convention)
                    tb = np.zeros(1, BOX_DTYPE)
                    tb["u1"], tb["v1"], tb["u2"], tb["v2"] = g["box"][gi]
                    tb["class_id"], tb["score"] = g["cls"][gi], 1.0
                    foot_true = mapper.foot_points(tb)
                    foot_det = mapper.foot_points(box[None])
                    gt_att = Attitude(pt, rt)
                    g_used = mapper._ground_for(att)
                    g_true = mapper._ground_for(gt_att)
                    xy_att, ok1 = g_used.map_pixels(foot_true)
                    xy_box, ok2 = g_true.map_pixels(foot_det)
                    tf = g["xy"][gi]
                    row["att_err"] = float(np.hypot(*(mapper.foot_offsets(xy_att, [int(g["cls"][gi])])[0] - tf))) if ok1[0] else np.nan
                    row["box_err"] = float(np.hypot(*(mapper.foot_offsets(xy_box, [int(box["class_id"])])[0] - tf))) if ok2[0] else np.nan
                    row["foot_dv"] = float(foot_det[0, 1] - foot_true[0, 1])
                    row["dpitch"] = float(att.pitch_deg - pt)
                    row["droll"] = float(att.roll_deg - rt)
                    row["true_h_px"] = float(g["box"][gi][3] - g["box"][gi][1])
            counts[(row["kind"], row.get("pair", row["origin"]), band_of(r))] += 1
            rows.append(row)
    tracked = analyse_tracked(data, truth)
    return {"frames": n_frames, "counts": counts, "rows": rows, "tracked": tracked, "optimal_false": opt_false}


def analyse_tracked(data, truth) -> dict:
    """The breakdown of /cones/tracked's false cones (module doc): against every cone of the drive seen so far, as
    `replay --track --gt-topic` counts them (a tracked cone beside the car, out of view, is real)."""
    drive = load_drive_truth(f"{data['bag']}_gt.jsonl")
    counts, rows, n, opt_false = Counter(), [], 0, 0
    for stamp, tr in sorted(data["tracked"].items()):
        if stamp not in drive.frames:
            continue
        n += 1
        t_xy, _ = drive.world_in_frame(stamp)
        p = np.c_[tr["x"], tr["y"]].astype(float)
        pairs = match_cones(p, t_xy)
        opt_false += int((~max_matched(p, t_xy) & (np.hypot(*p.T) < RANGE_M)).sum()) if len(p) else 0
        m = np.zeros(len(p), bool)
        tm = np.full(len(t_xy), -1)
        for i, j, _ in pairs:
            m[i] = True
            tm[j] = i
        for i in np.flatnonzero(~m):
            r = float(np.hypot(*p[i]))
            if r >= RANGE_M:
                continue
            if len(t_xy) == 0:
                kind, row = "phantom", {}
            else:
                d = np.hypot(*(t_xy - p[i]).T)
                j = int(np.argmin(d))
                dr, dl = radial_lateral(p[i], t_xy[j])
                row = {"dr": dr, "dl": dl, "true_range": float(np.hypot(*t_xy[j]))}
                kind = "phantom" if d[j] > 6.0 else ("duplicate" if tm[j] >= 0 else "misplaced")
            row.update(kind=kind, range=r, stamp=stamp)
            counts[(kind, band_of(r))] += 1
            rows.append(row)
    return {"frames": n, "counts": counts, "rows": rows, "optimal_false": opt_false}


def med(v):
    v = [x for x in v if x is not None and np.isfinite(x)]
    return f"{np.median(v):.2f}" if v else "-"


def report_misplaced(kind: str, mis: list) -> None:
    if not mis:
        return
    print(f"\n{kind} ({len(mis)}): median |range error| {med([abs(r['dr']) for r in mis])} m, |bearing error| "
          f"{med([abs(r['dl']) for r in mis])} m, error / gate {med([r['err'] / r['gate'] for r in mis])}, "
          f"range error < 0 (placed nearer) {np.mean([r['dr'] < 0 for r in mis]):.2f}; "
          f"error from the attitude alone {med([r['att_err'] for r in mis])} m, from the box alone "
          f"{med([r['box_err'] for r in mis])} m; pitch error {med([r['dpitch'] for r in mis])} deg "
          f"(|.| {med([abs(r['dpitch']) for r in mis])}); box height / true {med([r['h_px'] / r['true_h_px'] for r in mis])}; "
          f"its cone matched by another detection {np.mean([r['t_matched'] for r in mis]):.2f}")
    att_dom = np.mean([r["att_err"] > r["box_err"] for r in mis if np.isfinite(r["att_err"]) and np.isfinite(r["box_err"])])
    print(f"  the attitude's part larger than the box's in {att_dom:.2f} of them; by origin: "
          + ", ".join(f"{o} {sum(r['origin'] == o for r in mis)}" for o in ("band", "strip")))


def report(name: str, a: dict) -> None:
    f = a["frames"]
    rows = a["rows"]
    print(f"\n## {name}: /cones, {len(rows)} false cones within {RANGE_M:g} m in {f} frames ({len(rows) / f:.2f} per frame)")
    print("| kind | boxes | 0-7 m | 7-15 m | 15-25 m | 25-40 m | per frame |")
    print("|---|---|---|---|---|---|---|")
    keys = sorted({(k, o) for k, o, _ in a["counts"]})
    for k, o in keys:
        c = [a["counts"][(k, o, band_of(lo))] for lo, _ in BANDS]
        print(f"| {k} | {o} | " + " | ".join(str(x) for x in c) + f" | {sum(c) / f:.2f} |")
    for kind in ("misplaced", "row shift"):
        report_misplaced(kind, [r for r in rows if r["kind"] == kind])
    print(f"\n(diagnosis) false cones per frame with a maximum one-to-one matching in the same gate instead of the "
          f"greedy nearest-first one: {a['optimal_false'] / f:.2f} (/cones/tracked: {a['tracked']['optimal_false'] / a['tracked']['frames']:.2f})")
    dup = [r for r in rows if r["kind"] == "duplicate"]
    if dup:
        s = [r for r in dup if "sep" in r]
        print(f"\nduplicates ({len(dup)}): the other box's cone matched {np.mean([r['other_matched'] for r in dup]):.2f}; "
              f"separation of the two cones {med([r['sep'] for r in s])} m (along the ray {med([abs(r['sep_dr']) for r in s])}, "
              f"across {med([abs(r['sep_dl']) for r in s])}); this box's height / the other's {med([r['h_px'] / r['other_h_px'] for r in s])}; "
              f"same class as the cone {np.mean([r['cls_ok'] for r in dup]):.2f}; "
              f"scores: this {med([r['score'] for r in dup])}, the other {med([r.get('other_score') for r in s])}")
    ph = [r for r in rows if r["kind"] == "phantom"]
    if ph:
        print(f"\nphantoms ({len(ph)}): median score {med([r['score'] for r in ph])}, height {med([r['h_px'] for r in ph])} px, "
              f"range {med([r['range'] for r in ph])} m")
    t = a["tracked"]
    tf = t["frames"]
    print(f"\n/cones/tracked: {len(t['rows'])} false cones within {RANGE_M:g} m ({len(t['rows']) / tf:.2f} per frame)")
    print("| kind | 0-7 m | 7-15 m | 15-25 m | 25-40 m | per frame | median range / bearing offset (m) |")
    print("|---|---|---|---|---|---|---|")
    for k in sorted({k for k, _ in t["counts"]}):
        c = [t["counts"][(k, band_of(lo))] for lo, _ in BANDS]
        rr = [r for r in t["rows"] if r["kind"] == k and "dr" in r]
        print(f"| {k} | " + " | ".join(str(x) for x in c) + f" | {sum(c) / tf:.2f} | "
              f"{med([r['dr'] for r in rr])} / {med([abs(r['dl']) for r in rr])} |")


if __name__ == "__main__":
    argv = sys.argv[1:]
    rest = []
    if "--" in argv:
        k = argv.index("--")
        argv, rest = argv[:k], argv[k + 1:]
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bags", nargs="+")
    ap.add_argument("--out", default="/tmp/26g/false_cones", help="where the recordings go (default %(default)s)")
    ap.add_argument("--tag", default="", help="added to each recording's name (one per set of replay options)")
    ap.add_argument("--calib-suffix", default="_calib.yaml", help="BAG + this is the calibration (default %(default)s)")
    ap.add_argument("--calib", action="append", default=[], help="the calibration of each BAG in turn (instead of the suffix)")
    ap.add_argument("--reuse", action="store_true", help="read the recordings instead of replaying")
    ap.add_argument("--no-one-box", action="store_true",
                    help="the pipeline without one_box_per_cone (the defaults before issue 26g), to compare back to back")
    args = ap.parse_args(argv)
    if args.no_one_box:
        pipeline_mod.one_box_per_cone = lambda boxes: boxes
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.calib and len(args.calib) != len(args.bags):
        raise SystemExit("--calib: one per BAG")
    for k, bag in enumerate(args.bags):
        name = Path(bag).name + (f"_{args.tag}" if args.tag else "")
        pkl = out / f"{name}.pkl"
        if args.reuse and pkl.exists():
            with open(pkl, "rb") as f:
                data = pickle.load(f)
        else:
            data = record(bag, args.calib[k] if args.calib else f"{bag}{args.calib_suffix}", pkl, rest)
        report(name, analyse(data))
