"""Same-class duplicates on the ground (issue 26, session 15): does the separation ALONG the viewing ray tell two
boxes of one cone from two cones? Then a screen of `mapping.one_cone_per_ray` on recorded replays.

    .venv/bin/python docs/experiments/false_cones_ray.py diag REC.pkl [REC.pkl ...]
    .venv/bin/python docs/experiments/false_cones_ray.py screen [--only TEXT] REC.pkl [REC.pkl ...]

Each REC.pkl is a recording of `false_cones.py BAG` (every frame's boxes, cones, each box's cone, the attitude).

``diag``: every pair of `/cones` of one class within 40 m of a frame, the other cone less than 0.5 m off the ray
through the better-scored one (from the camera's ground point), labelled by the true cones their BOXES are of
(`false_cones.cone_of_box`, the truth's rendered boxes): ``one`` (both boxes of one cone: a duplicate), ``two``
(two different cones), ``phantom`` (a box of no cone). Prints, per range band, how many pairs of each label lie
below each across-ray separation and each along-ray separation (fixed metres, and as a share of the range).

``screen``: the recorded boxes merged as the pipeline does (`one_box_per_cone`), mapped with the recorded attitude
and the default flat-box gate, then `one_cone_per_ray` at each design's settings; `/cones` and `/cones/tracked`
scored as `false_cones_designs.py` does (the tracker gets the rule's cones, or with ``cones only`` every cone).
"""
from __future__ import annotations

import argparse
import pickle
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from false_cones import cone_of_box, load_gt_boxes  # noqa: E402

from cone_perception.data.bags import read_ground_truth  # noqa: E402
from cone_perception.evaluation import match_cones  # noqa: E402
from false_cones_designs import one_box, run  # noqa: E402

from cone_perception.geometry.calib import load_calibration  # noqa: E402
from cone_perception.mapping import one_cone_per_ray  # noqa: E402
from cone_perception.params import DEFAULT_MIN_HEIGHT_RATIO  # noqa: E402

RANGE_M = 40.0
BANDS = ((0, 15), (15, 25), (25, 40))
ACROSS = (0.1, 0.15, 0.2, 0.3)
ALONG = (1.5, 2.0, 2.5, 3.0, 3.5, 4.0)
FRAC = (0.06, 0.08, 0.1, 0.12)


def pairs_of(data: dict) -> list[dict]:
    calib = load_calibration(data["calib"])
    cam = calib.camera_ground_xy()
    gtb = load_gt_boxes(f"{data['bag']}_gt.jsonl")
    truth_t = read_ground_truth(data["bag"], "/cones_gt")
    rows = []
    for stamp, fr in sorted(data["frames"].items()):
        if stamp not in gtb:
            continue
        cones = fr["cones"]
        if len(cones) < 2:
            continue
        box_of = {c: i for i, c in enumerate(fr["cone_of"]) if c >= 0}
        truth = [cone_of_box((fr["boxes"][box_of[k]]["u1"], fr["boxes"][box_of[k]]["v1"], fr["boxes"][box_of[k]]["u2"],
                              fr["boxes"][box_of[k]]["v2"]), gtb[stamp]) for k in range(len(cones))]
        xy = np.c_[cones["x"], cones["y"]].astype(float)
        matched = np.zeros(len(cones), bool)
        if stamp in truth_t:
            t = truth_t[stamp]
            matched[[i for i, _, _ in match_cones(xy, np.c_[t["x"], t["y"]].astype(float))]] = True
        ray = xy - cam
        rng = np.linalg.norm(ray, axis=1)
        for i in range(len(cones)):
            for j in range(i + 1, len(cones)):
                same = cones["class_id"][i] == cones["class_id"][j]
                a, b = (i, j) if cones["score"][i] >= cones["score"][j] else (j, i)
                if rng[a] >= RANGE_M:
                    continue
                u = ray[a] / rng[a]
                d = xy[b] - xy[a]
                along, across = float(d @ u), float(abs(d[0] * u[1] - d[1] * u[0]))
                if across >= 0.5:
                    continue
                ta, tb = truth[a], truth[b]
                label = "phantom" if ta < 0 or tb < 0 else ("one" if ta == tb else "two")
                if not same:
                    label = "x-" + label
                rows.append({"range": float(rng[a]), "along": along, "across": across, "label": label,
                             "matched": int(matched[a]) + int(matched[b]), "weak_false": not matched[b],
                             "ratio": float(cones["score"][b] / cones["score"][a])})
    return rows


def diag(recs: list[str]) -> None:
    rows = []
    for p in recs:
        with open(p, "rb") as f:
            rows += pairs_of(pickle.load(f))
    for lo, hi in BANDS:
        rr = [r for r in rows if lo <= r["range"] < hi]
        n = {k: sum(r["label"] == k for r in rr) for k in ("one", "two", "phantom", "x-one", "x-two")}
        print(f"\n### {lo}-{hi} m: pairs less than 0.5 m across the ray: same class: one cone {n['one']}, two cones "
              f"{n['two']}, with a phantom {n['phantom']}; two classes: one cone {n['x-one']}, two cones {n['x-two']}")
        for lab in ("one", "two", "x-one"):
            v = [r for r in rr if r["label"] == lab and r["across"] < 0.3]
            if v:
                q = np.percentile([abs(r["along"]) for r in v], [5, 25, 50, 75, 95])
                qa = np.percentile([r["across"] for r in v], [25, 50, 75])
                print(f"  {lab}: |along| (across < 0.3 m) percentiles 5/25/50/75/95: " + " / ".join(f"{x:.2f}" for x in q)
                      + " m; across 25/50/75: " + " / ".join(f"{x:.2f}" for x in qa) + " m; weaker/stronger score "
                      f"{np.median([r['ratio'] for r in v]):.2f}")
        print("  | across < | along < | same class: one / two / phantom | same class, both / one of them matched on "
              "/cones; weaker < 0.8x: both / one; < 0.7x: both / one | two classes: one / two |")
        print("  |---|---|---|---|---|")
        for A in ACROSS:
            for D in [f"{d} m" for d in ALONG] + [f"{f} x range" for f in FRAC]:
                lim = float(D.split()[0])
                c = defaultdict(int)
                for r in rr:
                    if r["across"] < A and abs(r["along"]) < (lim if D.endswith(" m") else lim * r["range"]):
                        c[r["label"]] += 1
                        if not r["label"].startswith("x-"):
                            for k in (1.0, 0.8, 0.7):
                                if r["ratio"] < k:
                                    c[(k, r["matched"])] += 1
                print(f"  | {A} | {D} | {c['one']} / {c['two']} / {c['phantom']} | "
                      + "; ".join(f"{c[(k, 2)]} / {c[(k, 1)]}" for k in (1.0, 0.8, 0.7))
                      + f" | {c['x-one']} / {c['x-two']} |")


def ray_rule(cam, across, along, frac=0.0, mode="keep", max_range=np.inf, any_class=False, min_range=0.0):
    """``any_class``: True (pairs of two classes at any range), False (one class only) or the range (m) from which
    pairs of two classes count (nearer: one class only)."""
    cross = {True: 0.0, False: np.inf}.get(any_class, any_class)

    def f(cones):
        return one_cone_per_ray(cones, cam, across, along, frac, mode, max_range, cross, min_range)[0]
    return f


DESIGNS = {"as shipped (no ray rule)": None}
for _a, _d, _f, _r in ((0.15, 2.0, 0.0, 25.0), (0.15, 1.5, 0.0, 25.0), (0.1, 2.0, 0.0, 25.0), (0.2, 2.0, 0.0, 25.0),
                       (0.15, 2.0, 0.0, 15.0), (0.15, 2.0, 0.0, 40.0), (0.1, 2.5, 0.0, 40.0), (0.2, 1.5, 0.0, 40.0),
                       (0.15, 0.0, 0.1, 25.0), (0.15, 0.0, 0.08, 40.0)):
    for _mode in ("drop", "keep", "merge"):
        DESIGNS[f"{_mode}, across < {_a} m, along < {_d if _d else f'{_f} x range'}"
                f"{' m' if _d else ''}, within {_r:g} m"] = (_a, _d, _f, _mode, True, _r)
for _mode in ("drop", "keep"):
    DESIGNS[f"{_mode}, across < 0.15 m, along < 2.0 m, within 25 m, cones only"] = (0.15, 2.0, 0.0, _mode, False, 25.0)
# round 2
for _a, _d, _r in ((0.15, 2.0, 30.0), (0.15, 1.5, 40.0), (0.2, 2.0, 40.0), (0.15, 2.5, 25.0), (0.2, 2.5, 25.0)):
    DESIGNS[f"r2 keep, across < {_a} m, along < {_d} m, within {_r:g} m"] = (_a, _d, 0.0, "keep", True, _r)
DESIGNS["r2 keep, across < 0.15 m, along < 2.0 m, within 40 m, cones only"] = (0.15, 2.0, 0.0, "keep", False, 40.0)
DESIGNS["r2 keep, across < 0.2 m, along < 1.5 m, within 40 m, cones only"] = (0.2, 1.5, 0.0, "keep", False, 40.0)
DESIGNS["r2 any class: keep, across < 0.15 m, along < 2.0 m, within 25 m"] = (0.15, 2.0, 0.0, "keep", True, 25.0, True)
DESIGNS["r2 any class: keep, across < 0.15 m, along < 2.0 m, within 40 m"] = (0.15, 2.0, 0.0, "keep", True, 40.0, True)
DESIGNS["r2 any class: keep, across < 0.1 m, along < 2.0 m, within 40 m"] = (0.1, 2.0, 0.0, "keep", True, 40.0, True)
# round 3: the near bands (the default of round 2 cost 7-15 m recall): only beyond a minimum range
for _anyc in (False, True):
    for _rmin in (0.0, 10.0, 15.0, 20.0):
        DESIGNS[f"r3 {'any class' if _anyc else 'one class'}: keep, across < 0.15 m, along < 2.0 m, {_rmin:g}-40 m"] = (
            0.15, 2.0, 0.0, "keep", True, 40.0, _anyc, _rmin)
for _x in (7.0, 10.0, 15.0):
    DESIGNS[f"r4 one class 0-40 m, two classes {_x:g}-40 m: keep, across < 0.15 m, along < 2.0 m"] = (
        0.15, 2.0, 0.0, "keep", True, 40.0, _x)


def screen(recs: list[str], only: str) -> None:
    datas = []
    for p in recs:
        with open(p, "rb") as f:
            datas.append((Path(p).stem, pickle.load(f)))
    print("| design | drive | /cones 15-25 / 25-40 m, false per frame < 40 m | /cones/tracked 15-25 / 25-40 m, false | "
          "0-7 / 7-15 m: /cones; tracked |")
    print("|---|---|---|---|---|")
    for name, spec in DESIGNS.items():
        if only not in name:
            continue
        res = []
        for dn, data in datas:
            if spec is None:
                post, pt = None, True
            else:
                a, d, fr, mode, pt, rmax, *more = spec
                post = ray_rule(load_calibration(data["calib"]).camera_ground_xy(), a, d, fr, mode, rmax, *more)
            r = run(data, one_box, {}, None, post, pt, DEFAULT_MIN_HEIGHT_RATIO)
            res.append(r)
            print(f"| {name} | {dn} | {r['raw'][0]:.3f} / {r['raw'][1]:.3f}, {r['raw'][2]:.2f} | "
                  f"{r['tracked'][0]:.3f} / {r['tracked'][1]:.3f}, {r['tracked'][2]:.2f} | "
                  "{:.3f} / {:.3f}; {:.3f} / {:.3f} |".format(*r["near"]), flush=True)
        m = {k: np.mean([r[k] for r in res], axis=0) for k in ("raw", "tracked", "near")}
        print(f"| **{name}** | mean of {len(res)} | {m['raw'][0]:.3f} / {m['raw'][1]:.3f}, {m['raw'][2]:.2f} | "
              f"{m['tracked'][0]:.3f} / {m['tracked'][1]:.3f}, {m['tracked'][2]:.2f} | "
              "{:.3f} / {:.3f}; {:.3f} / {:.3f} |".format(*m["near"]), flush=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("what", choices=("diag", "screen"))
    ap.add_argument("recs", nargs="+")
    ap.add_argument("--only", default="", help="screen: only the designs whose name holds this text")
    args = ap.parse_args()
    if args.what == "diag":
        diag(args.recs)
    else:
        screen(args.recs, args.only)
