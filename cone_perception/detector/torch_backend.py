"""The detector's torch side: eager torch and TorchScript runners, a checkpoint built for a backend, and the ONNX
graph of a checkpoint that the ONNX cache keeps (:mod:`.onnx_cache`).

Imported only where torch is needed: backend ``torch`` / ``torchscript``, a checkpoint without a cached ONNX
graph (the first start, a changed model), training and export. A node on ONNX Runtime whose cache is warm never
imports this module, nor torch (issue 43).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from ..errors import ConfigError
from ..model.checkpoint import Checkpoint, load_checkpoint
from .backends import BACKEND_CHOICES, OrtRunner, ort_session
from .export import onnx_bytes, trace

#: oneDNN instruction-set caps (``ONEDNN_MAX_CPU_ISA``) without AVX512-BF16 or AMX: bfloat16 is emulated there
ONEDNN_ISAS_WITHOUT_BF16 = ("SSE41", "AVX", "AVX2", "AVX2_VNNI", "AVX2_VNNI_2", "AVX512_CORE", "AVX512_CORE_VNNI")


def native_bf16() -> bool:
    """Whether this CPU computes bfloat16 natively (x86 AVX512-BF16 or AMX), so bf16 autocast pays. A cap on
    oneDNN's instruction set below that (``ONEDNN_MAX_CPU_ISA``, or the older ``DNNL_MAX_CPU_ISA``, e.g.
    ``AVX512_CORE`` to act as a CPU without it) counts as none: the convolutions then emulate bfloat16."""
    cap = (os.environ.get("ONEDNN_MAX_CPU_ISA") or os.environ.get("DNNL_MAX_CPU_ISA") or "").strip().upper()
    if cap in ONEDNN_ISAS_WITHOUT_BF16:
        return False
    cpu = getattr(torch, "cpu", None)
    probes = ("_is_avx512_bf16_supported", "_is_amx_tile_supported")
    try:
        return any(bool(getattr(cpu, n)()) for n in probes if hasattr(cpu, n))
    except RuntimeError:
        return False


class TorchRunner:
    """Eager torch or TorchScript: (1, 3, H, W) float32 RGB 0..1 -> (4 + nc, N) float32 numpy."""

    def __init__(self, module: Callable, device: str, fp16: bool, channels_last: bool, bf16: bool = False):
        self.module, self.device, self.fp16, self.channels_last = module, torch.device(device), fp16, channels_last
        self.bf16 = bf16  # CPU bfloat16 autocast (weights stay fp32)

    def __call__(self, blob: np.ndarray) -> np.ndarray:
        x = torch.from_numpy(blob).to(self.device)
        if self.channels_last:
            x = x.contiguous(memory_format=torch.channels_last)
        if self.fp16:
            x = x.half()
        with torch.inference_mode(), torch.autocast("cpu", dtype=torch.bfloat16, enabled=self.bf16):
            y = self.module(x)
        if isinstance(y, (list, tuple)):
            y = y[0]
        return y[0].float().cpu().numpy()


def prepare_torch(device: str, threads: int | None, source: str) -> None:
    """Before a torch backend loads: a :class:`ConfigError` naming ``source`` for a CUDA ``device`` torch cannot
    reach; ``threads`` (None: torch's default) intra-op threads."""
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(source, "device", f"device {device!r} requested but CUDA is not available to torch")
    if threads:
        torch.set_num_threads(int(threads))


def load_torchscript(src: str, device: str, fp16: bool) -> tuple[TorchRunner, str]:
    """A TorchScript file as a runner on ``device`` and the text of its embedded ``config.txt`` ("" if none)."""
    extra = {"config.txt": ""}
    try:
        module = torch.jit.load(src, map_location=device, _extra_files=extra).eval()
    except (RuntimeError, ValueError) as e:
        raise ConfigError(src, None, f"not a readable TorchScript file: {e}") from e
    if fp16:
        module = module.half()
    return TorchRunner(module, device, fp16, False), extra["config.txt"]


def checkpoint_runner(ck: Checkpoint, backend: str, device: str, fp16: bool, size: tuple[int, int],
                      threads: int | None, bf16: bool) -> tuple[Callable[[np.ndarray], np.ndarray], bool]:
    """(the network of ``ck`` for ``backend`` at input ``size`` (W, H), whether its input size is fixed); backend
    ``onnx`` exports it in memory (no cache: :mod:`.onnx_cache` serves checkpoint files)."""
    model = ck.build_model()
    if backend == "onnx":
        return OrtRunner(ort_session(onnx_bytes(model, size), device, threads, ck.path, fp16)), True
    model = model.fuse().to(device)
    if fp16:
        model = model.half()
    if backend == "torchscript":
        return TorchRunner(trace(model, size, device=device, fp16=fp16), device, fp16, False), True
    if backend != "torch":
        raise ConfigError(ck.path, "backend", f"unknown backend {backend!r}; choose one of {', '.join(BACKEND_CHOICES)}")
    model = model.to(memory_format=torch.channels_last)
    return TorchRunner(model, device, fp16, True, bf16=bf16), False


def checkpoint_graph(path: str | Path, imgsz: tuple[int, int] | None) -> tuple[bytes, dict]:
    """(the ONNX graph of the checkpoint ``path`` at input ``imgsz`` (W, H; None: the checkpoint's), what the
    detector reads of the checkpoint besides: ``class_names``, ``imgsz`` [W, H], ``arch`` (ModelConfig.to_dict));
    the ONNX cache's export of a detector (:func:`~.onnx_cache.load_graph`). The checkpoint is validated
    (:func:`~cone_perception.model.checkpoint.load_checkpoint`)."""
    ck = load_checkpoint(path)
    size = (int(imgsz[0]), int(imgsz[1])) if imgsz else ck.imgsz
    info = {"class_names": list(ck.class_names), "imgsz": [int(size[0]), int(size[1])], "arch": ck.cfg.to_dict()}
    return onnx_bytes(ck.build_model(), size), info
