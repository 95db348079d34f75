"""``cone-perception detect``: run the detector over an image, a folder, a video or a rosbag -> JSON lines.

  cone-perception detect SOURCE --out FILE.jsonl [--model M] [--imgsz WxH] [--crop V0,V1[,U0,U1]]
                                 [--downscale N] [--backend B] [--save-vis DIR] [--every N]

One line per image (see ``cone_perception/data/predictions.py``), boxes in the image's own pixels.
A video's frames are named ``<video stem>_<frame index, 6 digits>`` (index from 0 in the file);
a bag's by their stamp in ns. No image read at all is an error (exit 2).
Without ``--crop`` each image is letterboxed to the model input (``--imgsz``, default the
model's); with ``--crop`` the band is cut (and downscaled by ``--downscale``) as the car does.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
from tqdm import tqdm

from ..crop import CropSpec
from ..data.sources import iter_source
from ..detector import BACKEND_CHOICES, DEFAULT_BACKEND, Detector, default_model_path, detect_one, resolve_backend
from ..detector.farband import FarBand
from ..errors import ConfigError
from ..params import DEFAULT_CONF, DEFAULT_IOU
from ._args import parse_crop, size_arg


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = ("Run the detector over an image, a folder of images, a video file (mp4, avi, mkv, ...) or a "
                     "rosbag's camera topic; write JSON lines.")
    p.add_argument("source", type=Path, help="image file, folder of images, video file, or rosbag2 directory")
    p.add_argument("--out", type=Path, required=True, help="JSON-lines output file")
    p.add_argument("--model", default=None, help="model file (default: the shipped default model)")
    p.add_argument("--backend", default=DEFAULT_BACKEND, choices=BACKEND_CHOICES,
                   help="inference backend (default %(default)s: ONNX Runtime on the CPU where installed, else torch)")
    p.add_argument("--bf16", action="store_true",
                   help="backend torch on the CPU: bfloat16 autocast (about 1.5-2x faster where the CPU has native bf16)")
    p.add_argument("--imgsz", type=size_arg, default=None, help="letterbox each image to this model input WxH")
    p.add_argument("--crop", type=parse_crop, default=None, help="band V0,V1[,U0,U1] in image px, cut before the model")
    p.add_argument("--downscale", type=int, default=1, choices=[1, 2, 4], help="with --crop: integer downscale")
    p.add_argument("--far-rows", default=None, metavar="V0,V1",
                   help="with --crop: also run image rows V0-V1 at full resolution, the whole width (the far band: "
                        "small, far cones), and merge its boxes (docs/detector.md 'Far band')")
    p.add_argument("--conf", type=float, default=DEFAULT_CONF, help="confidence threshold (default %(default)s)")
    p.add_argument("--iou", type=float, default=DEFAULT_IOU, help="NMS IoU threshold (default %(default)s)")
    p.add_argument("--topic", default=None, help="rosbag: camera topic (default: the only image topic)")
    p.add_argument("--save-vis", type=Path, default=None, metavar="DIR",
                   help="write annotated images here (with --crop the band is drawn too)")
    p.add_argument("--every", type=int, default=1, metavar="N",
                   help="video or bag: every N-th frame only (default 1: all); frame indices stay those of the source")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from ..data.predictions import write_prediction
    from ..vis import draw_band, draw_boxes

    if args.far_rows and not args.crop:
        raise ConfigError("--far-rows", None, "needs --crop: the far band adds to the car's band")
    model = args.model or default_model_path()
    backend = resolve_backend(args.backend, model, bf16=args.bf16)
    det = Detector.load(model, backend=backend, conf=args.conf, iou=args.iou,
                        imgsz=args.imgsz if backend != "torch" else None, bf16=args.bf16)
    # with --crop the detector is built for the band's own size (as the pipeline node does), so a
    # fixed-size backend never letterboxes the band into another input size
    by_band, far_by_size = {}, {}

    def band_for(w: int) -> CropSpec:  # --crop of an image w px wide (U0,U1 default to the whole width)
        return CropSpec(*(args.crop if len(args.crop) == 4 else (*args.crop, 0, w)), args.downscale)

    def detector_for(w: int, h: int):
        if not args.crop or args.imgsz:
            return det
        band = band_for(w)
        return detector_for_size((max(1, band.out_width), max(1, band.out_height)))

    def far_for(w: int, h: int):
        if not args.far_rows:
            return None
        if (w, h) not in far_by_size:
            far_by_size[(w, h)] = FarBand.load(model, args.far_rows, w, h, band_for(w), "--far-rows", backend=backend,
                                               conf=args.conf, iou=args.iou, bf16=args.bf16)
        return far_by_size[(w, h)]

    def detector_for_size(band):
        if band not in by_band:
            by_band[band] = Detector.load_for_band(model, band, backend=backend, conf=args.conf, iou=args.iou,
                                                   bf16=args.bf16)
        return by_band[band]
    try:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        fh = args.out.open("w", encoding="utf-8")
    except OSError as e:
        raise ConfigError(str(args.out), None, f"cannot write: {e.strerror}") from None
    if args.save_vis:
        args.save_vis.mkdir(parents=True, exist_ok=True)
    n, skipped = 0, []
    with fh:
        for name, img, err in tqdm(iter_source(args.source, args.topic, args.every), unit="img",
                                   disable=args.no_progress, file=sys.stderr):
            if err:
                skipped.append(f"{name}: {err}")
                continue
            h, w = img.shape[:2]
            boxes, scale = detect_one(detector_for(w, h), img, name, args.crop, args.downscale, args.imgsz,
                                      far_for(w, h))
            write_prediction(fh, name, w, h, boxes, input_scale=scale)
            n += 1
            if args.save_vis:
                out = args.save_vis / (Path(name).stem + ".jpg")
                vis = draw_boxes(img, boxes)
                if args.crop:
                    vis = draw_band(vis, args.crop, args.downscale)

                cv2.imwrite(str(out), vis)
    from ..words import plural

    print(f"detect: {plural(n, 'image')} -> {args.out}" + (f", {len(skipped)} skipped" if skipped else ""))
    for s in skipped[:20]:
        print(f"  skipped {s}", file=sys.stderr)
    if len(skipped) > 20:
        print(f"  ... {len(skipped) - 20} more skipped", file=sys.stderr)
    if n == 0:
        raise ConfigError(str(args.source), None, f"no image could be read ({plural(len(skipped), 'input')} skipped"
                                                  + (f", first: {skipped[0]}" if skipped else "") + ")")
    return 0
