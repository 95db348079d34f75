"""Training on several processes (``torchrun``) and on CUDA: what the trainer needs, kept out of its loop.

One process per GPU (or per CPU worker with gloo), PyTorch DDP: each process takes its own slice of
every global batch (:class:`ShardedSampler`), gradients are averaged, only rank 0 validates and writes.
Without ``torchrun`` (no ``WORLD_SIZE`` in the environment) everything here is a no-op: world size 1.

The slices are chosen so that a run on W processes with ``--batch B`` (B / W images per process) sees
exactly the images, in the same order and with the same augmentation, that one process with batch B
sees; the loss is scaled by W so the averaged gradient has the single-process scale. What still
differs: batch-norm statistics per process (B / W images, not B) and floating-point summation order.
"""

from __future__ import annotations

import datetime
import gc
import os
from dataclasses import dataclass

import numpy as np
import torch
import torch.distributed as dist
from torch.utils.data import Sampler

from ..errors import ConfigError


@dataclass(frozen=True)
class DistInfo:
    """Where this process runs: rank, world size, local rank and its torch device."""

    rank: int = 0
    world: int = 1
    local_rank: int = 0
    device: torch.device = torch.device("cpu")

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    @property
    def ddp(self) -> bool:
        return self.world > 1


def resolve_device(device: str, local_rank: int = 0) -> torch.device:
    """``auto`` -> the process's GPU where CUDA is there, else the CPU; ``cpu``; ``cuda`` / ``cuda:N``."""
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if device.startswith("cuda"):
        if not torch.cuda.is_available():
            raise ConfigError("train", "device", f"{device} asked for, but torch sees no CUDA device")
        return torch.device(device if ":" in device else f"cuda:{local_rank}")
    if device != "cpu":
        raise ConfigError("train", "device", f"unknown device {device!r}; choose auto, cpu, cuda or cuda:N")
    return torch.device("cpu")


def world_from_env() -> tuple[int, int, int]:
    """(rank, world size, local rank) as ``torchrun`` sets them; (0, 1, 0) without it."""
    return int(os.environ.get("RANK", 0)), int(os.environ.get("WORLD_SIZE", 1)), int(os.environ.get("LOCAL_RANK", 0))


def setup(device: str = "auto", batch: int | None = None) -> DistInfo:
    """Join the process group ``torchrun`` prepared (NCCL on GPUs, gloo on the CPU) and pick the device.
    ``batch`` (the global batch) must divide by the world size: checked before anything else."""
    rank, world, local = world_from_env()
    if batch is not None and world > 1 and batch % world:
        raise ConfigError("--batch", None, f"the global batch {batch} does not divide by the {world} processes of "
                                           f"torchrun: give a multiple of {world} (each process takes batch / {world})")
    dev = resolve_device(device, local)
    if world > 1:
        if dev.type == "cuda":
            torch.cuda.set_device(dev)
        if not dist.is_initialized():
            dist.init_process_group("nccl" if dev.type == "cuda" else "gloo", timeout=datetime.timedelta(minutes=30))
    return DistInfo(rank, world, local, dev)


def cleanup(info: DistInfo) -> None:
    """Leave the process group (after a last barrier). What is left of the run (its DDP wrapper, which may
    sit in reference cycles) is collected first, while the interpreter is whole: Gloo objects left for the
    interpreter's exit to free are a known way a rank aborts there (pytorch/pytorch PR 179291), and a rank
    of the 2-process test once aborted after its last epoch ("terminate called without an active exception")."""
    if info.ddp:
        gc.collect()
        if dist.is_initialized():
            dist.barrier()
            dist.destroy_process_group()


def mean_over_ranks(t: torch.Tensor, info: DistInfo) -> torch.Tensor:
    """The mean of ``t`` over all processes (``t`` itself with one process)."""
    if not info.ddp:
        return t

    t = t.detach().clone().to(info.device if info.device.type == "cuda" else "cpu")
    dist.all_reduce(t)
    return (t / info.world).cpu()


def from_main(value, info: DistInfo):
    """Rank 0's ``value`` on every process (any picklable object)."""
    if not info.ddp:
        return value

    box = [value]
    dist.broadcast_object_list(box, src=0)
    return box[0]


class ShardedSampler(Sampler):
    """This process's share of every global batch of an epoch sampler: global batch ``i`` holds items
    ``[i * B, (i + 1) * B)`` of the epoch order, and rank ``r`` takes ``[i * B + r * b, i * B + (r + 1) * b)``,
    b = B / world. Incomplete last global batches are dropped (as one process with ``drop_last`` does)."""

    def __init__(self, base, rank: int, world: int, batch: int):
        self.base, self.rank, self.world, self.batch = base, rank, world, batch
        self.per_rank = batch // world

    def set_epoch(self, epoch: int) -> None:
        self.base.set_epoch(epoch)

    def __len__(self) -> int:
        return (len(self.base) // self.batch) * self.per_rank

    def __iter__(self):
        items = list(iter(self.base))
        n_batches = len(items) // self.batch
        if n_batches == 0:
            raise ConfigError("train", "batch", f"an epoch holds {len(items)} samples, fewer than one global batch "
                                                f"of {self.batch}: lower --batch")
        idx = np.arange(n_batches)[:, None] * self.batch + self.rank * self.per_rank + np.arange(self.per_rank)[None]
        return iter([items[int(k)] for k in idx.ravel()])
