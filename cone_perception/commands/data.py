"""``cone-perception data``: dataset converters (FSOCO -> YOLO, 16:9 restore)."""

from __future__ import annotations

import argparse
import logging


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
    for q in (f, r):
        q.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from ..data import convert

    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
    if args.action == "fsoco-to-yolo":
        rep = convert.fsoco_to_yolo(args.src, args.out, args.val_fraction, args.seed, args.border,
                                    progress=not args.no_progress)
    else:
        clips = [c.strip() for c in args.clips.split(",") if c.strip()] if args.clips else None
        names = [n.strip() for n in args.names.split(",") if n.strip()] if args.names else None
        rep = convert.restore_aspect(args.src, args.out, args.aspect, width=args.width, clips=clips, names=names,
                                     progress=not args.no_progress)
    skipped = ", ".join(f"{k}: {v}" for k, v in sorted(rep.skipped.items())) or "none"
    from ..words import plural

    print(f"wrote {plural(rep.images, 'image')}, {plural(rep.boxes, 'box', 'boxes')} to {args.out} "
          f"{rep.per_split or ''}; skipped: {skipped}")
    return 0
