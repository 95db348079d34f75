"""Export a detector to TorchScript or ONNX in the common YOLO layout, and verify it.

The exported graph takes (1, 3, H, W) float32 RGB in 0..1 and returns
(1, 4 + nc, N): cx, cy, w, h in input px, then class scores. The file itself
carries its description (:func:`export_metadata`: ONNX ``metadata_props``,
TorchScript ``config.txt``), in the keys other YOLO tools use (``names`` as
"{0: 'blue', ...}", ``imgsz`` as [h, w]), so :meth:`Detector.load` needs no
sidecar; the YAML sidecar ``<file name>.yaml`` says the same for people.
"""

from __future__ import annotations

import io
import json
import warnings
from pathlib import Path

import numpy as np
import torch

from .. import __version__
from ..errors import ConfigError
from ..model import ConeYOLO
from ..model.checkpoint import FORMAT, VERSION
from .backends import ONNX_OPSET


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


def export_metadata(class_names: list[str], imgsz: tuple[int, int], stride: int, source: str | None = None,
                    extra: dict | None = None) -> dict[str, str]:
    """What an exported file carries about itself, as strings: ``names`` ("{0: 'blue', ...}"), ``imgsz``
    ("[H, W]", Ultralytics' order), ``stride``, ``model_version`` (checkpoint format and version),
    ``exporter`` (this package's version), ``source`` (the checkpoint), ``layout``, ``task``."""
    meta = {
        "names": repr({i: str(n) for i, n in enumerate(class_names)}),
        "imgsz": f"[{int(imgsz[1])}, {int(imgsz[0])}]",
        "stride": str(int(stride)),
        "model_version": f"{FORMAT} v{VERSION}",
        "exporter": f"cone_perception {__version__}",
        "task": "detect",
        "layout": "(1, 4 + nc, N): cx cy w h input px, class scores; input (1, 3, H, W) RGB 0..1",
    }
    if source is not None:
        meta["source"] = str(source)
    meta.update({k: str(v) for k, v in (extra or {}).items()})
    return meta


def with_onnx_metadata(model_bytes: bytes, meta: dict[str, str]) -> bytes:
    """The ONNX model with ``meta`` in its ``metadata_props`` (replacing keys of the same name)."""
    import onnx  # optional dependency (ONNX export only)

    proto = onnx.load_from_string(model_bytes)
    keep = [(p.key, p.value) for p in proto.metadata_props if p.key not in meta]
    del proto.metadata_props[:]
    for k, v in keep + list(meta.items()):
        prop = proto.metadata_props.add()
        prop.key, prop.value = k, v
    return proto.SerializeToString()


def export_model(model: ConeYOLO, imgsz: tuple[int, int], fmt: str, out: Path, meta: dict[str, str] | None = None) -> Path:
    """Write the model as ``fmt`` ("torchscript" | "onnx") to ``out``, with ``meta`` (:func:`export_metadata`)
    embedded (ONNX ``metadata_props``; TorchScript ``config.txt`` as JSON); returns the path."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    model = model.eval()
    if fmt == "onnx":
        data = onnx_bytes(model, imgsz)
        out.write_bytes(with_onnx_metadata(data, meta) if meta else data)
    elif fmt == "torchscript":
        fused = ConeYOLO(model.cfg)
        fused.load_state_dict(model.state_dict())
        ts = trace(fused.eval().fuse(), imgsz)
        torch.jit.save(ts, str(out), _extra_files={"config.txt": json.dumps(meta)} if meta else None)
    else:
        raise ValueError(f"unknown export format {fmt!r}")
    return out


def max_abs_diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64)))) if a.size else 0.0


def worst_diff_to_eager(exported, eager, imgsz: tuple[int, int]) -> float:
    """Largest ``|exported - eager|`` of the raw network output (two :class:`~cone_perception.detector.Detector`
    objects) on a random and a grey ``(1, 3, H, W)`` input of ``imgsz`` (W, H): ``export``'s check."""
    rng = np.random.default_rng(0)
    w, h = imgsz
    worst = 0.0
    for blob in (rng.random((1, 3, h, w), dtype=np.float32), np.full((1, 3, h, w), 114 / 255, np.float32)):
        worst = max(worst, max_abs_diff(exported.raw(blob), eager.raw(blob)))
    return worst

