"""The ``cone-perception train`` run: data, model, trainer from the parsed options; the report at the end.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from dataclasses import replace

from ..errors import ConfigError
from ..train.augment import AugmentConfig
from ..train.distributed import world_from_env
from ..train.report import RUNS_DIR, next_run_dir
from ..train.trainer import TrainConfig, train


def run_train(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    if str(args.data).endswith(".npz"):  # crops of `data verifier-crops`: the far strip's verifier
        from ..train.verifier import train_verifier

        out = args.out or str(next_run_dir(RUNS_DIR, "verifier"))
        res = train_verifier(args.data, out, args.epochs, args.seed, args.threads, progress=not args.no_progress)
        print(f"train: wrote {out}/verifier.pt (held-out tenth, last epoch: {res})")
        return 0
    aug = AugmentConfig.off() if args.no_augment else replace(AugmentConfig(), mosaic=args.mosaic, copy_paste=args.copy_paste)

    rank = world_from_env()[0]
    if args.out is None:
        if args.resume:
            raise ConfigError("--resume", None, "needs --out: the folder of the run to continue")
        args.out = str(next_run_dir(RUNS_DIR, args.name))
    cfg = TrainConfig(
        data=args.data, out=args.out, model=args.model, epochs=args.epochs, batch=args.batch, imgsz=args.imgsz,
        optimizer=args.optimizer, lr0=args.lr0, patience=args.patience, workers=args.workers, threads=args.threads,
        seed=args.seed, close_mosaic=args.close_mosaic, max_batches=args.max_batches, augment=aug,
        precision=args.precision or "auto", device=args.device, backbone_weights=args.backbone_weights,
        backbone_lr=args.backbone_lr, freeze_backbone=args.freeze_backbone, freeze_bn=args.freeze_bn,
        teacher=args.teacher, distill=args.distill, init_from=args.init_from,
    )
    if rank == 0:
        print(f"train: run folder {args.out}", file=sys.stderr, flush=True)
    result = train(cfg, resume=args.resume, precision=args.precision, progress=not args.no_progress)
    if rank != 0:  # under torchrun only rank 0 reports
        return 0
    last = result["history"][-1] if result["history"] else {}
    summary = {"out": result["out"], "best_epoch": result["best_epoch"], "best_fitness": result["best_fitness"], "last": last}
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"done: best epoch {result['best_epoch']} of {len(result['history'])} (fitness "
              f"{result['best_fitness']:.4f}); best.pt, last.pt, results.csv, results.png in {result['out']}")
    return 0
