"""Export a detector to TorchScript or ONNX in the common YOLO layout, and verify it.

The exported graph takes (1, 3, H, W) float32 RGB in 0..1 and returns
(1, 4 + nc, N): cx, cy, w, h in input px, then class scores. A YAML sidecar
(``<stem>.yaml``) names the classes and the input size.
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np
import torch

from .errors import ConfigError
from .model import ConeYOLO

ONNX_OPSET = 17


def _example(imgsz: tuple[int, int], device: str = "cpu", fp16: bool = False) -> torch.Tensor:
    w, h = imgsz
    x = torch.rand(1, 3, h, w, generator=torch.Generator().manual_seed(0)).to(device)
    return x.half() if fp16 else x


def trace(model: ConeYOLO, imgsz: tuple[int, int], device: str = "cpu", fp16: bool = False) -> torch.jit.ScriptModule:
    """TorchScript trace of the (eval, preferably fused) model at input size (W, H), frozen."""
    model = model.eval()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        ts = torch.jit.trace(model, _example(imgsz, device, fp16), check_trace=False)
    return torch.jit.freeze(ts)


def onnx_bytes(model: ConeYOLO, imgsz: tuple[int, int]) -> bytes:
    """ONNX (opset 17, fixed input size (W, H)) of the model in eval mode."""
    try:
        import onnx  # noqa: F401 - torch's exporter needs it
    except ImportError as e:
        raise ConfigError("ONNX export", "onnx", "torch's ONNX exporter needs the onnx package: pip install onnx "
                          "(or use backend 'torch')") from e
    model = model.eval().float().cpu()
    buf = io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            model, (_example(imgsz),), buf, input_names=["images"], output_names=["output0"],
            opset_version=ONNX_OPSET, dynamo=False, do_constant_folding=True,
        )
    return buf.getvalue()


def export_model(model: ConeYOLO, imgsz: tuple[int, int], fmt: str, out: Path) -> Path:
    """Write the model as ``fmt`` ("torchscript" | "onnx") to ``out``; returns the path."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    model = model.eval()
    if fmt == "onnx":
        out.write_bytes(onnx_bytes(model, imgsz))
    elif fmt == "torchscript":
        fused = ConeYOLO(model.cfg)
        fused.load_state_dict(model.state_dict())
        trace(fused.eval().fuse(), imgsz).save(str(out))
    else:
        raise ValueError(f"unknown export format {fmt!r}")
    return out


def max_abs_diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64)))) if a.size else 0.0
