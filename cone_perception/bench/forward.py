"""Forward micro-benchmark of the detector: network forward only, per size and backend.

``cone-perception speed`` prints a table from :func:`time_forward` (the end-to-end
``cone-perception bench`` times the forward per frame inside the detector instead).
"""

from __future__ import annotations

import time

import numpy as np
import torch

from ..detector import Detector
from ..model import ConeYOLO


def time_forward(det: Detector, frames: int = 50, warmup: int = 5) -> dict:
    """Time ``frames`` forwards of a (1, 3, H, W) input at ``det.imgsz`` -> ms statistics."""
    w, h = det.imgsz
    blob = np.random.default_rng(0).random((1, 3, h, w), dtype=np.float32)
    for _ in range(warmup):
        det.raw(blob)
    ms = []
    for _ in range(frames):
        t0 = time.perf_counter()
        det.raw(blob)
        ms.append((time.perf_counter() - t0) * 1e3)
    a = np.asarray(ms)
    return {"median_ms": float(np.median(a)), "p90_ms": float(np.percentile(a, 90)), "min_ms": float(a.min()),
            "max_ms": float(a.max()), "frames": frames}


def gflops(model: ConeYOLO, imgsz: tuple[int, int]) -> float:
    """Multiply-accumulate count x 2 of one forward at (W, H), in GFLOPs (convolutions only)."""
    total = 0

    def hook(mod, inp, out):
        nonlocal total
        k = mod.kernel_size[0] * mod.kernel_size[1] * (mod.in_channels // mod.groups)
        total += out.numel() * k

    hs = [m.register_forward_hook(hook) for m in model.modules() if isinstance(m, torch.nn.Conv2d)]
    with torch.no_grad():
        model.eval()(torch.zeros(1, 3, imgsz[1], imgsz[0]))
    for h in hs:
        h.remove()
    return 2 * total / 1e9
