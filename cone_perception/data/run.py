"""The ``cone-perception data`` run: the dataset converters (FSOCO -> YOLO, 16:9 restore) and their summary line.
"""

from __future__ import annotations

import argparse
import logging

from ..words import plural
from . import convert
from .farcrops import far_crops
from .verifiercrops import verifier_crops


def run_data(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
    if args.action == "verifier-crops":
        counts = verifier_crops(args.out, args.rendered, args.real, args.seed, progress=not args.no_progress)
        print(f"wrote {args.out}: " + "; ".join(f"{k}: {v['cones']} cones, {v['not_cones']} not" for k, v in counts.items()))
        return 0
    if args.action == "far-crops":
        rep = far_crops(args.data, args.out, args.split, args.size, args.min_height, args.max_height, args.per_image,
                        args.seed, progress=not args.no_progress, around=args.around, around_conf=args.around_conf)
        print(f"wrote {rep.line()} to {args.out}")
        return 0
    if args.action == "fsoco-to-yolo":
        rep = convert.fsoco_to_yolo(args.src, args.out, args.val_fraction, args.seed, args.border,
                                    progress=not args.no_progress)
    else:
        clips = [c.strip() for c in args.clips.split(",") if c.strip()] if args.clips else None
        names = [n.strip() for n in args.names.split(",") if n.strip()] if args.names else None
        rep = convert.restore_aspect(args.src, args.out, args.aspect, width=args.width, clips=clips, names=names,
                                     progress=not args.no_progress)
    skipped = ", ".join(f"{k}: {v}" for k, v in sorted(rep.skipped.items())) or "none"

    print(f"wrote {plural(rep.images, 'image')}, {plural(rep.boxes, 'box', 'boxes')} to {args.out} "
          f"{rep.per_split or ''}; skipped: {skipped}")
    return 0
