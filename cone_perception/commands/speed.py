"""``cone-perception speed``: network-forward micro-benchmark per model size and backend."""

from __future__ import annotations

import argparse
import json

import torch

from ..bench.forward import gflops, time_forward
from ..detector import Detector
from ..model import MODEL_SIZES, ConeYOLO, model_config
from ..words import plural
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
    torch.set_num_threads(args.threads)
    rows = []
    cases = [(args.model, None)] if args.model else [(None, s) for s in args.sizes]
    for path, size in cases:
        runs = [(b, False) for b in args.backends] + ([("torch", True)] if args.bf16 else [])
        for backend, bf16 in runs:
            if path:
                det = Detector.load(path, backend=backend, imgsz=args.imgsz, threads=args.threads, bf16=bf16)
                name, gf, params = path, None, None
            else:
                torch.manual_seed(0)
                model = ConeYOLO(model_config(size))
                gf, params = gflops(model, args.imgsz), model.num_params()
                det = Detector.from_model(model, args.imgsz, backend, threads=args.threads, bf16=bf16)
                name = size
            r = time_forward(det, args.frames)
            rows.append({"model": name, "backend": backend + ("-bf16" if bf16 else ""), "imgsz": list(args.imgsz), "threads": args.threads,
                         "params": params, "gflops": gf, **r})
    if args.json:
        print(json.dumps(rows))
        return 0

    print(f"forward only, input {args.imgsz[0]}x{args.imgsz[1]}, {plural(args.threads, 'thread')}, "
          f"{plural(args.frames, 'frame')}")
    wm = max([12] + [len(str(r["model"])) + 2 for r in rows])  # a model path is longer than a size name
    print(f"{'model':<{wm}}{'backend':<13}{'params':>10}{'GFLOPs':>8}{'median ms':>11}{'p90 ms':>9}{'min-max ms':>16}{'fps':>8}")
    for r in rows:
        params = f"{r['params'] / 1e6:.2f}M" if r["params"] else "-"
        gf = f"{r['gflops']:.2f}" if r["gflops"] else "-"
        print(f"{str(r['model']):<{wm}}{r['backend']:<13}{params:>10}{gf:>8}{r['median_ms']:>11.2f}{r['p90_ms']:>9.2f}"
              f"{r['min_ms']:>8.2f}-{r['max_ms']:<7.2f}{1e3 / r['median_ms']:>8.1f}")
    return 0
