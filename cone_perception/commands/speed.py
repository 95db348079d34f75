"""``cone-perception speed``: network-forward micro-benchmark per model size and backend."""

from __future__ import annotations

import argparse

from ..bench.speed import run_speed
from ..model import MODEL_SIZES
from ._args import size_arg


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--sizes", nargs="+", default=list(MODEL_SIZES), help=f"model names (sizes; pretrained families as in train --help), random weights (default: {' '.join(MODEL_SIZES)})")
    p.add_argument("--model", default=None, help="time this checkpoint / exported model instead of --sizes")
    p.add_argument("--backends", nargs="+", default=["torch", "onnx"], choices=("torch", "torchscript", "onnx"), help="backends (default torch onnx)")
    p.add_argument("--bf16", action="store_true", help="also time backend torch with bfloat16 autocast (row 'torch-bf16')")
    p.add_argument("--imgsz", type=size_arg, default=(960, 288), help="input WxH px (default 960x288)")
    p.add_argument("--threads", type=int, default=1,
                   help="intra-op threads of the network (default 1, as the nodes and every other command)")
    p.add_argument("--frames", type=int, default=50, help="timed forwards per case (default 50)")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")


def run(args: argparse.Namespace) -> int:
    return run_speed(args)
