"""The ``cone-perception speed`` run: the forward pass of detector sizes and backends (:mod:`.forward`), as a table
or JSON.
"""

from __future__ import annotations

import argparse
import json

import torch

from ..detector import Detector
from ..model import ConeYOLO, model_config
from ..words import plural
from .forward import gflops, time_forward


def run_speed(args: argparse.Namespace) -> int:
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
