"""Recall of the small cones against the precision of all detections, threshold by threshold (issue 26).

    .venv/bin/python docs/experiments/small_cone_pr.py OUT.png GT "LABEL=PRED.jsonl" ... [--gt-names A,B,..]
        [--band V0,V1] [--scale 0.33333] [--heights 6,12] [--at-precision 0.703]

Each PRED.jsonl is a `cone-perception detect ... --conf 0.001` file over the frames of GT. For each score
threshold 0.02, 0.03, .. 0.90 it counts, as `far_strip_recall.py` does (its `_at`), the precision of all detections
in the band and the recall of the labelled cones whose box height (times --scale: the real clips' 1920-px frames
to their 640x360 source) is within --heights, and draws recall against precision, one curve per LABEL, with a
vertical line at --at-precision (issue 26 compares at the band alone's precision, 0.703). Prints, per LABEL, the
recall at that precision and at score 0.25.

A curve above another at every precision finds more small labelled cones for the same share of unmatched
detections; where the unmatched ones are themselves cones the labels leave out (docs/benchmarks.md, "What the
real clips' false detections are"), the precision axis says how complete the labels are as much as how good the
detector is.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from far_strip_recall import _at  # noqa: E402

from cone_perception.data.predictions import read_predictions  # noqa: E402
from cone_perception.evaluation.groundtruth import load_ground_truth, pair_with_predictions, restrict_to_band  # noqa: E402

THRESHOLDS = np.round(np.arange(2, 91) / 100, 2)


def curve(images, lo: float, hi: float, opts) -> list[tuple[float, float, float]]:
    """(threshold, precision, recall of the cones lo..hi px) per threshold."""
    out = []
    for c in THRESHOLDS:
        r = _at(images, float(c), [0.0, lo, hi, 1e9], opts)
        b = r["bins"][f"{lo:g}-{hi:g}"]
        if r["detections"]:  # no detection left: no precision to plot
            out.append((float(c), r["precision"], b["found"] / max(b["cones"], 1)))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out")
    p.add_argument("gt")
    p.add_argument("runs", nargs="+", metavar="LABEL=PRED.jsonl")
    p.add_argument("--gt-names", default=None)
    p.add_argument("--band", default=None, help="V0,V1 as eval --band")
    p.add_argument("--scale", type=float, default=1.0)
    p.add_argument("--heights", default="6,12", help="LO,HI: the cones counted, px (after --scale)")
    p.add_argument("--at-precision", type=float, default=0.703)
    p.add_argument("--iou", type=float, default=0.5)
    a = p.parse_args(argv)
    a.max_range = None  # what far_strip_recall's _at reads
    lo, hi = (float(v) for v in a.heights.split(","))
    gt = load_ground_truth(a.gt, a.gt_names.split(",") if a.gt_names else None)
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for run in a.runs:
        label, path = run.split("=", 1)
        images, _ = pair_with_predictions(gt, list(read_predictions(path)), path, False)
        if a.band:
            images, _ = restrict_to_band(images, tuple(int(v) for v in a.band.split(",")))
        pts = curve(images, lo, hi, a)
        _, prec, rec = zip(*pts)
        line, = ax.plot(prec, rec, label=label)
        at = next(((c, pr, r) for c, pr, r in pts if pr >= a.at_precision), None)
        q = next((x for x in pts if x[0] == 0.25), None)
        ax.plot([q[1]], [q[2]], "o", color=line.get_color())
        print(f"{label}: at precision >= {a.at_precision:g}: "
              + (f"recall {at[2]:.3f} (score >= {at[0]:.2f}, precision {at[1]:.3f})" if at else "never reached")
              + f"; at score 0.25: recall {q[2]:.3f}, precision {q[1]:.3f}")
    ax.axvline(a.at_precision, color="grey", ls="--", lw=1)
    ax.set_xlabel("precision of all detections in the band")
    ax.set_ylabel(f"recall of labelled cones {lo:g}-{hi:g} px tall")
    ax.set_title("small cones: recall against precision (dots: score 0.25)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(a.out, dpi=110)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
