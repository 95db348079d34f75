"""``cone-perception data``: dataset converters (FSOCO -> YOLO, 16:9 restore, far-strip crops, verifier crops)."""

from __future__ import annotations

import argparse
from functools import partial

from ..data.run import run_data
from ._args import size_arg


def _aspect(text: str) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in text.split(":"))
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"expected W:H like 16:9, got {text!r}") from e
    if a <= 0 or b <= 0:
        raise argparse.ArgumentTypeError(f"expected positive W:H, got {text!r}")
    return a, b


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    f = sub.add_parser("fsoco-to-yolo", help="FSOCO Supervisely JSON -> YOLO txt, logo border cropped, 80/20 split per team")
    f.add_argument("src", help="FSOCO folder: one sub-folder per team with ann/*.json and img/*")
    f.add_argument("out", help="output folder (images/{train,val}, labels/{train,val}, data.yaml)")
    f.add_argument("--val-fraction", type=float, default=0.2, help="share of each team's images for validation (default 0.2)")
    f.add_argument("--seed", type=int, default=0, help="split seed (default 0)")
    f.add_argument("--border", type=int, default=None, help="crop this many px on every side instead of detecting the black border")
    r = sub.add_parser("restore-aspect", help="resize a squeezed YOLO dataset back to its true aspect (labels unchanged)")
    r.add_argument("src", help="dataset folder with images/ and labels/")
    r.add_argument("out", help="output folder")
    r.add_argument("--aspect", type=_aspect, default=(16.0, 9.0), help="true aspect W:H (default 16:9); the width is kept")
    r.add_argument("--width", type=int, default=None, help="resize to this width instead of keeping it (e.g. 1920: frames of the car's size)")
    r.add_argument("--clips", default=None, help="keep only these clips, comma-separated (e.g. autox4,autox2,accel)")
    r.add_argument("--names", default=None,
                   help="the dataset's class names in id order, comma-separated, for the data.yaml written to OUT "
                        "(default: from SRC/data.yaml or SRC/classes.txt; bgracing-real: "
                        "blue_cone,large_orange_cone,orange_cone,yellow_cone)")
    c = sub.add_parser("far-crops", help="windows around small cones at the frames' native scale (training data of the far strip)",
                       description="Cut windows of --size px, not resized, around labelled cones of --min-height.."
                                   "--max-height px from one split of a data YAML (restore_aspect applied, clips "
                                   "filtered as the YAML says), with their clipped labels, into a YOLO dataset: "
                                   "the far strip's model trains on them (models/cone_detector_far.md). --around: "
                                   "windows around a model's false detections instead (hard negatives).")
    c.add_argument("data", help="data YAML (Ultralytics form, e.g. synth dataset's data.yaml, or our mixing form)")
    c.add_argument("out", help="output folder, new or empty (images/, labels/, data.yaml)")
    c.add_argument("--split", choices=("train", "val"), default="train", help="which split of the YAML to cut (default train)")
    c.add_argument("--size", type=partial(size_arg, option="--size", square=False), default=(960, 128),
                   help="window WxH px at the image's own scale; narrower or lower frames give their whole width or "
                        "height (default 960x128)")
    c.add_argument("--min-height", type=float, default=4.0, help="smallest cone box (px) a window is cut around (default 4)")
    c.add_argument("--max-height", type=float, default=24.0, help="largest cone box (px) a window is cut around (default 24)")
    c.add_argument("--per-image", type=int, default=2, help="windows per image at most (default 2)")
    c.add_argument("--seed", type=int, default=0, help="random seed of the choice and placement (default 0)")
    c.add_argument("--around", metavar="PRED", default=None,
                   help="hard negatives: cut the windows around the false detections of this `detect` prediction "
                        "file of the same images (boxes of --min-height..--max-height px on no cone; a rendered set's "
                        "gt.jsonl also names the cones its labels leave out) instead of around cones; every label a "
                        "window shows is kept")
    c.add_argument("--around-conf", type=float, default=0.25,
                   help="with --around: the score a detection needs to count (default 0.25)")
    v = sub.add_parser("verifier-crops", help="crops around the far strip's boxes, cone or not (training data of its verifier)",
                       description="Cut the training crops of the far strip's verifier (docs/training.md, The far "
                                   "strip's verifier): around the boxes of a `detect` file of a rendered set in each "
                                   "frame's strip rows, labelled by its gt.jsonl; random boxes of those rows on no "
                                   "cone; and the labelled small cones of a real YOLO folder. Then `cone-perception "
                                   "train --data OUT.npz` trains the verifier.")
    v.add_argument("out", help="output file (.npz)")
    v.add_argument("--rendered", nargs=2, action="append", default=[], metavar=("DIR", "PRED"),
                   help="a `synth dataset` folder and a `detect` file of its frames (the far model at full "
                        "resolution, --conf 0.1); repeat for more sets")
    v.add_argument("--real", default=None, metavar="DIR",
                   help="a real YOLO folder (images/, labels/) whose labelled cones of 4-20 px are kept as cones "
                        "(never the validation clips)")
    v.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    for q in (f, r, c, v):
        q.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    return run_data(args)
