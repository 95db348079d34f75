"""The ``cone-perception detect`` run: the detector over images, a folder, a video or a bag's camera topic
-> one JSON line per image (:mod:`cone_perception.data.predictions`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from types import SimpleNamespace

import cv2
from tqdm import tqdm

from ..crop import CropSpec
from ..data.predictions import write_prediction
from ..data.sources import iter_source
from ..resources import far_model_for, far_model_given
from ..detector import Detector, default_model_path, detect_one, resolve_backend
from ..detector.farband import (BAND_SPLIT_AUTO, BAND_SPLIT_OFF, FAR_ROWS_AUTO, FAR_ROWS_OFF, FarBand, SplitDetector,
                                band_split_for, far_rows_for)
from ..detector.verifier import load_verifier
from ..errors import ConfigError
from ..geometry.calib import load_calibration
from ..vis import draw_band, draw_boxes
from ..words import plural


def _car_band(args: argparse.Namespace) -> None:
    """``--calib``: set ``--crop``, ``--downscale`` and ``--far-rows`` (V0,V1 or None) from the calibration;
    without it ``--far-rows`` is rows or off (``auto`` needs a calibration)."""
    rows = None if args.far_rows is None else str(args.far_rows).strip()
    split = None if args.band_split is None else str(args.band_split).strip()
    if args.calib is None:
        if split is not None and split.lower() == BAND_SPLIT_AUTO:
            raise ConfigError("--band-split", None, "auto needs --calib: the split is placed from a calibration")
        if rows is not None and rows.lower() == FAR_ROWS_AUTO:
            raise ConfigError("--far-rows", None, "auto needs --calib: the far strip is placed from a calibration")
        args.far_rows = None if rows is None or rows.lower() in FAR_ROWS_OFF else rows
        return
    if args.crop or args.imgsz:
        raise ConfigError("--calib", None, "sets the band itself: leave out --crop / --imgsz")
    calib = load_calibration(args.calib)
    c = calib.crop
    args.crop, args.downscale = (c.v0, c.v1, c.u0, c.u1), c.downscale
    fr = far_rows_for(rows, calib, "--far-rows")
    print(f"detect: band rows {c.v0}-{c.v1} / {c.downscale} of {calib.source}; {fr.what}", file=sys.stderr)
    args.far_rows = f"{fr.crop.v0},{fr.crop.v1}" if fr.crop is not None else None
    sp = band_split_for(split, calib, "--band-split")
    if sp.upper is not None:
        print(f"detect: {sp.what}", file=sys.stderr)
    args.band_split = f"{sp.near.v0},{sp.upper.v1}" if sp.upper is not None else None


def run_detect(args: argparse.Namespace) -> int:
    _car_band(args)  # --calib: the calibration's band and far strip as --crop / --downscale / --far-rows
    if args.band_split and str(args.band_split).strip().lower() in BAND_SPLIT_OFF:
        args.band_split = None
    if args.band_split and not args.crop:
        raise ConfigError("--band-split", None, "needs --crop or --calib: it splits the car's band")
    if args.far_rows and not args.crop:
        raise ConfigError("--far-rows", None, "needs --crop or --calib: the far band adds to the car's band")
    if far_model_given(args.far_model) and not args.far_rows:
        raise ConfigError("--far-model", None, "needs a far band (--far-rows, or --calib with its far strip)")
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
        if args.band_split:
            return split_for(band)
        return detector_for_size((max(1, band.out_width), max(1, band.out_height)))

    def far_for(w: int, h: int):
        if not args.far_rows:
            return None
        if (w, h) not in far_by_size:
            far_model = far_model_for(args.far_model, model)
            far = FarBand.load(far_model, args.far_rows, w, h, band_for(w), "--far-rows", "--far-model",
                               verifier=load_verifier(args.far_verifier, "--far-verifier"),
                               backend=resolve_backend(args.backend, far_model, bf16=args.bf16), conf=args.conf,
                               iou=args.iou, bf16=args.bf16)
            far.check_classes(det)  # a far model of other classes: refused before its first image
            far_by_size[(w, h)] = far
        return far_by_size[(w, h)]

    def split_for(band: CropSpec):  # --band-split N0,U1 of this band: the band's detector in two parts
        if band not in by_band:
            sp = band_split_for(args.band_split, SimpleNamespace(crop=band, camera_matrix=None, source="--crop"),
                                "--band-split")
            by_band[band] = SplitDetector.load(model, sp, backend=backend, conf=args.conf, iou=args.iou, bf16=args.bf16)
        return by_band[band]

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
            boxes, scale, drawn = detect_one(detector_for(w, h), img, name, args.crop, args.downscale, args.imgsz,
                                             far_for(w, h))
            write_prediction(fh, name, w, h, boxes, input_scale=scale, far=drawn)
            n += 1
            if args.save_vis:
                out = args.save_vis / (Path(name).stem + ".jpg")
                vis = draw_boxes(img, boxes)
                if args.crop:
                    vis = draw_band(vis, args.crop, args.downscale)

                cv2.imwrite(str(out), vis)

    print(f"detect: {plural(n, 'image')} -> {args.out}" + (f", {len(skipped)} skipped" if skipped else ""))
    for s in skipped[:20]:
        print(f"  skipped {s}", file=sys.stderr)
    if len(skipped) > 20:
        print(f"  ... {len(skipped) - 20} more skipped", file=sys.stderr)
    if n == 0:
        raise ConfigError(str(args.source), None, f"no image could be read ({plural(len(skipped), 'input')} skipped"
                                                  + (f", first: {skipped[0]}" if skipped else "") + ")")
    return 0
