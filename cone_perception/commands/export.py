"""``cone-perception export``: a checkpoint -> TorchScript or ONNX (common YOLO layout), verified;
with ``--int8`` also a statically quantised ONNX (``<stem>.int8.onnx``) calibrated on real frames."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..train.export import TOLERANCE, run_export
from ..train.quantize import ACTIVATION_TYPES, CALIB_METHODS, DEFAULT_CALIB_FRAMES, MIN_MATCHED, MIN_MEAN_IOU
from ._args import parse_crop, size_arg


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = (
        "Export a detector checkpoint to TorchScript or ONNX, verified against eager (max |diff| <= "
        f"{TOLERANCE}). With --int8 (ONNX only) the fp32 ONNX is then quantised with ONNX Runtime "
        "(static, QDQ, convolutions only; the box decoding stays float), calibrated on real frames "
        "preprocessed as the detector does at run time, written as <stem>.int8.onnx + <stem>.int8.yaml "
        f"and checked on real frames: at least {MIN_MATCHED:.0%} of the float model's boxes must have an "
        f"int8 box of the same class (IoU >= 0.5) and the pairs' mean IoU must be >= {MIN_MEAN_IOU}."
    )
    p.add_argument("--model", default=None, help="checkpoint (.pt) written by `cone-perception train` (with --cache: "
                                                 "the node's model parameter, default the shipped one)")
    p.add_argument("--format", choices=("torchscript", "onnx"), default=None, help="output format (needed but for --cache)")
    p.add_argument("--cache", action="store_true",
                   help="instead: write the ONNX cache (~/.cache/cone_perception/onnx, docs/robustness.md) with every "
                        "graph the pipeline node loads with the --param values, so that it starts without torch; "
                        "run it before driving, after a model changes")
    p.add_argument("--param", action="append", default=[], metavar="NAME:=VALUE",
                   help="with --cache: a pipeline node parameter as launched (repeatable), e.g. calibration:=CAM")
    p.add_argument("--imgsz", type=size_arg, default=None, help="input WxH px (default: the checkpoint's)")
    p.add_argument("--out", default=None, help="output file (default: next to the checkpoint, .torchscript / .onnx)")
    p.add_argument("--force", action="store_true", help="overwrite existing output files (the model and its sidecar <file>.yaml; with --int8 those of the int8 file too)")
    q = p.add_argument_group("int8 (ONNX only)")
    q.add_argument("--int8", action="store_true", help="also write <stem>.int8.onnx, statically quantised")
    q.add_argument("--calib-images", type=Path, default=None, metavar="DIR",
                   help="folder of real frames to calibrate on (searched recursively); frames of the validation "
                        "clips autox4, autox2, accel are always left out")
    q.add_argument("--calib-frames", type=int, default=DEFAULT_CALIB_FRAMES, metavar="N",
                   help="calibration frames, spread evenly over the folder (default %(default)s)")
    q.add_argument("--calib-clips", default=None, metavar="CLIPS", help="use only frames of these clips, comma-separated (e.g. autox3,autox6)")
    q.add_argument("--calib-crop", type=parse_crop, default=None, metavar="V0,V1[,U0,U1]",
                   help="cut this band (rows, optionally columns, in the frames' px) before the model, as the car's "
                        "adapter does (e.g. 32,224 in 640x360 frames = rows 96-672 of 1080); default: the whole frame, "
                        "letterboxed")
    q.add_argument("--calib-downscale", type=int, default=1, choices=[1, 2, 4], help="with --calib-crop: integer downscale")
    q.add_argument("--calib-method", choices=CALIB_METHODS, default="minmax",
                   help="activation ranges: min-max over the frames (default) or the 99.999th percentile "
                        "(keeps every activation of every frame in memory: ~55 MB a frame at 960x288)")
    q.add_argument("--int8-activations", choices=ACTIVATION_TYPES, default="uint8",
                   help="activation type (default %(default)s: x86 runs uint8 x int8 fastest)")
    q.add_argument("--per-tensor", action="store_true", help="one weight scale per conv instead of one per output channel")
    q.add_argument("--int8-head", action="store_true", help="quantise the last head convs too (default: kept float)")
    q.add_argument("--int8-ops", choices=("conv", "all"), default="conv",
                   help="conv: quantise convolutions only (default); all: every op ONNX Runtime can quantise "
                        "(SiLU, add, concat, pooling, resize) except the box decoding")
    q.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    return run_export(args)
