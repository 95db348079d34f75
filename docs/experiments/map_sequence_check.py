"""Issue 27's offline protocol on rendered drives: `detect --calib` over a drive's frames, then `map --boxes` over the
prediction file (one attitude filter, frames in order), scored against the drive's truth the way `replay --gt-topic`
scores (`evaluation.localisation.LocalisationReport`: greedy nearest-first matching in a gate of 0.5 m + 10 % of the
range, cones at least half visible), plus the median range error in % of the range (the held-out set's figure).

Modes: ``fixed`` (the calibration's H), ``image`` (the image attitude; the far strip's boxes, which `detect` marks,
read through the far model's box model, as the node reads them) and ``image-unmarked`` (the same boxes with the
marks taken out: every box read as the band model's, as `map --boxes` did before the marks).

    .venv/bin/python docs/experiments/map_sequence_check.py /tmp/a27/djit341 /tmp/a27/djit342 [--box-model rendered]

Each drive's prediction file is made once (``--work``, default /tmp/map_sequence_check) and reused.
"""
import argparse
import contextlib
import io
import json
import sys
from pathlib import Path

import numpy as np

from cone_perception.cli import main
from cone_perception.evaluation.localisation import GT_MIN_VISIBLE, LocalisationReport
from cone_perception.records import CONE_DTYPE

BANDS = ("7-15 m", "15-25 m", "25-40 m")


def run_cli(argv: list[str]) -> tuple[str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(argv)
    if rc != 0:
        sys.exit(f"{' '.join(argv)}: exit {rc}\n{err.getvalue()}")
    return out.getvalue(), err.getvalue()


def truth_of(gt_path: Path) -> dict[str, np.ndarray]:
    frames = {}
    for line in gt_path.read_text().splitlines():
        d = json.loads(line)
        c = d["cones"]
        t = np.zeros(len(c), CONE_DTYPE)
        t["x"] = [k["x_m"] for k in c]
        t["y"] = [k["y_m"] for k in c]
        t["class_id"] = [k["class_id"] for k in c]
        t["score"] = [k["visible_fraction"] for k in c]
        frames[d["image"]] = t
    return frames


def score(map_out: str, truth: dict[str, np.ndarray]) -> dict:
    by_image: dict[str, list] = {k: [] for k in truth}
    for line in map_out.splitlines():
        image, x, y, cls = line.split(",")[:4]
        by_image[image].append((float(x), float(y), int(cls)))
    rep = LocalisationReport(max_range_m=40.0, min_visible=GT_MIN_VISIBLE)
    rel = {b: [] for b in BANDS}
    for image, t in truth.items():
        p = np.zeros(len(by_image[image]), CONE_DTYPE)
        if len(p):
            p["x"], p["y"], p["class_id"] = np.array(by_image[image]).T
        for i, j, _ in rep.add_frame(p, t):
            r_true = float(np.hypot(t["x"][j], t["y"][j]))
            r_pred = float(np.hypot(p["x"][i], p["y"][i]))
            for b in BANDS:
                lo, hi = (float(v) for v in b.removesuffix(" m").split("-"))
                if lo <= r_true < hi and t["score"][j] >= GT_MIN_VISIBLE:
                    rel[b].append(abs(r_pred - r_true) / r_true)
    s = rep.summary()["extra_groups"]
    return {b: (s[b]["median_err_m"], 100 * float(np.median(rel[b])) if rel[b] else float("nan"), s[b]["recall"],
                s[b]["false_per_frame"]) for b in BANDS}


def main_(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bags", nargs="+", type=Path)
    ap.add_argument("--work", type=Path, default=Path("/tmp/map_sequence_check"))
    ap.add_argument("--box-model", choices=("model", "rendered"), default="rendered",
                    help="how map reads the boxes (rendered: the drives' detector on rendered frames; default)")
    a = ap.parse_args(argv)
    a.work.mkdir(parents=True, exist_ok=True)
    print("| drive | mode | " + " | ".join(f"{b}: median m / range % / recall / false per frame" for b in BANDS) + " |")
    print("|---|---|" + "---|" * len(BANDS))
    for bag in a.bags:
        calib = bag.parent / f"{bag.name}_calib.yaml"
        pred = a.work / f"{bag.name}.jsonl"
        if not pred.exists():
            run_cli(["detect", str(bag), "--calib", str(calib), "--out", str(pred), "--no-progress"])
        unmarked = a.work / f"{bag.name}_unmarked.jsonl"
        unmarked.write_text("".join(json.dumps({k: v for k, v in json.loads(ln).items() if k != "far"}) + "\n"
                                    for ln in pred.read_text().splitlines()))
        truth = truth_of(bag.parent / f"{bag.name}_gt.jsonl")
        for mode, path, att in (("fixed", pred, "fixed"), ("image", pred, "image"), ("image-unmarked", unmarked, "image")):
            out, _ = run_cli(["map", "--calib", str(calib), "--boxes", str(path), "--attitude", att,
                              "--box-model", a.box_model])
            s = score(out, truth)
            print(f"| {bag.name} | {mode} | " + " | ".join(
                f"{m:.3f} / {r:.1f} / {rc:.3f} / {f:.2f}" for m, r, rc, f in (s[b] for b in BANDS)) + " |", flush=True)


if __name__ == "__main__":
    main_()
