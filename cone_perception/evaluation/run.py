"""The ``cone-perception eval`` run: a prediction file against ground truth -> report.md, metrics.json and
plots (and the detector's box model with ``--box-model-out``); or a tracked bag against its drive's truth.
"""

from __future__ import annotations

import argparse
import logging
import sys

from ..detector.model_files import write_box_model
from ..errors import ConfigError
from ..evaluation.boxfit import format_box_model, measure_box_model
from ..evaluation.report import evaluate_predictions, format_summary, lowest_score_note, write_report
from ..evaluation.tracking import (
    evaluate_tracking_bag, format_drive_evaluation, load_drive_truth, write_tracking_report,
)


def run_eval(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(message)s")
    if args.out.exists() and not args.out.is_dir():
        raise ConfigError(str(args.out), None, "output exists and is not a directory")
    if args.tracked is not None:
        return _run_tracked(args)
    if not args.pred.is_file():
        raise ConfigError(str(args.pred), None, "prediction file not found")
    res = evaluate_predictions(args.pred, args.gt, args.gt_names, args.calib, args.conf, args.iou, args.only_predicted,
                               progress=not args.no_progress, band=args.band, min_height=args.min_height, max_range=args.max_range,
                               attitude=args.attitude, box_model=args.box_model, model=args.model,
                               far_model=args.far_model, far_box_model=args.far_box_model)

    low = lowest_score_note(res.images)
    if low:
        print(f"warning: {low}", file=sys.stderr)
    try:
        files = write_report(res, args.out, str(args.pred), str(args.gt), worst=max(0, args.worst))
    except OSError as e:
        raise ConfigError(str(args.out), None, f"cannot write: {e.strerror}") from None
    print(format_summary(res))
    print(f"wrote {', '.join(p.name for p in files.values())} to {args.out}")
    if args.box_model_out is not None:
        _write_box_model(args, res)
    return 0


def _write_box_model(args: argparse.Namespace, res) -> None:
    cmd = "cone-perception eval " + " ".join(sys.argv[2:]) if len(sys.argv) > 2 else ""
    try:
        bm = measure_box_model(res.images, args.conf, args.iou, args.band,
                               note=f"{args.pred.name} against {args.gt}, band {args.band}, conf {args.conf}, IoU {args.iou}")
    except ValueError as e:
        raise ConfigError(str(args.pred), None, f"--box-model-out: {e}") from None
    try:
        write_box_model(args.box_model_out, bm, cmd)
    except OSError as e:
        raise ConfigError(str(args.box_model_out), None, f"cannot write: {e.strerror}") from None
    print("box model (detected box against the labelled cone):")
    print(format_box_model(bm))
    print(f"wrote {args.box_model_out}")


def _run_tracked(args: argparse.Namespace) -> int:
    if not args.tracked.is_dir() and not args.tracked.is_file():
        raise ConfigError(str(args.tracked), None, "bag not found")
    if args.gt.suffix != ".jsonl":
        raise ConfigError(str(args.gt), None, "--tracked needs the drive's gt.jsonl of `cone-perception synth bag` as --gt")
    summary = evaluate_tracking_bag(args.tracked, load_drive_truth(args.gt))
    try:
        files = write_tracking_report(summary, args.out, str(args.tracked), str(args.gt))
    except OSError as e:
        raise ConfigError(str(args.out), None, f"cannot write: {e.strerror}") from None
    print(format_drive_evaluation(summary))
    print(f"wrote {', '.join(p.name for p in files.values())} to {args.out}")
    return 0
