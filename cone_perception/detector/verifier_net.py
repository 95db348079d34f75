"""The far strip's verifier, torch's side (:mod:`.verifier` holds the rest): its network, its file (read, written),
its ONNX export for the ONNX cache, and eager torch's probabilities where ONNX Runtime is not installed.

Imported only to train, write or export a verifier, or to run it on torch: a node on ONNX Runtime whose ONNX cache
is warm never imports it, nor torch (issue 43).
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn

from ..crop import CTX, SIDE
from ..errors import ConfigError
from .backends import ONNX_OPSET

#: The keys a verifier file holds besides the weights (written by ``train --data CROPS.npz``): the thresholds
#: (:data:`~.verifier.THRESHOLDS`, what :class:`~.verifier.BoxVerifier` takes besides the network), the crop geometry.
FILE_KEYS = ("verify_below", "min_p", "min_px", "max_px", "side", "ctx")


class VerifierNet(nn.Module):
    """(N, 3, SIDE, SIDE) BGR 0..1 -> (N,) logits of "a cone stands here"."""

    def __init__(self):
        super().__init__()

        def block(i: int, o: int):
            return nn.Sequential(nn.Conv2d(i, o, 3, padding=1, bias=False), nn.BatchNorm2d(o), nn.ReLU(inplace=True))

        self.f = nn.Sequential(block(3, 16), nn.MaxPool2d(2), block(16, 32), nn.MaxPool2d(2), block(32, 64),
                               block(64, 64), nn.AdaptiveAvgPool2d(1))
        self.head = nn.Linear(64, 1)

    def forward(self, x):
        return self.head(self.f(x).flatten(1)).squeeze(1)


def new_net() -> VerifierNet:
    """A fresh :class:`VerifierNet`."""
    return VerifierNet()


def patches_tensor(patches: np.ndarray) -> torch.Tensor:
    """(N, SIDE, SIDE, 3) uint8 BGR -> (N, 3, SIDE, SIDE) float32 torch tensor 0..1."""
    return torch.from_numpy(np.ascontiguousarray(patches)).permute(0, 3, 1, 2).float().div_(255.0)


def probabilities(net: nn.Module, patches: np.ndarray) -> np.ndarray:
    """(N,) float64 probability of a cone in each of ``patches`` (N, SIDE, SIDE, 3) uint8 BGR, eager torch."""
    with torch.inference_mode():
        return torch.sigmoid(net(patches_tensor(patches))).numpy().astype(np.float64)


def save_verifier(path: str | Path, net, verify_below: float, min_p: float, min_px: float, max_px: float,
                  info: dict | None = None) -> None:
    torch.save({"kind": "cone_verifier", "state_dict": net.state_dict(), "verify_below": float(verify_below),
                "min_p": float(min_p), "min_px": float(min_px), "max_px": float(max_px), "side": SIDE, "ctx": CTX,
                "info": dict(info or {})}, str(path))


def read_verifier(path: Path, source: str) -> tuple[VerifierNet, dict]:
    """(the network in eval mode, its thresholds (``verify_below``, ``min_p``, ``min_px``, ``max_px``) as floats) of a verifier file; ConfigError
    naming ``source`` and the file for an unreadable file, one that is not a verifier, or one cut for another
    crop geometry."""
    try:
        d = torch.load(str(path), map_location="cpu", weights_only=True)
    except Exception as e:  # a truncated or foreign file: say so, naming it
        raise ConfigError(source, str(path), f"cannot read it as a verifier file: {type(e).__name__}: {e}") from None
    if not isinstance(d, dict) or d.get("kind") != "cone_verifier" or "state_dict" not in d:
        raise ConfigError(source, str(path), "not a cone verifier file (train one with `cone-perception train "
                                             "--data CROPS.npz`)")
    missing = [k for k in FILE_KEYS if k not in d]
    if missing:
        raise ConfigError(source, str(path), f"the verifier file lacks {', '.join(missing)}")
    if int(d["side"]) != SIDE or float(d["ctx"]) != CTX:
        raise ConfigError(source, str(path), f"cut for {d['side']} px crops of {d['ctx']}x the box; this package "
                                             f"cuts {SIDE} px of {CTX}x")
    net = new_net()
    try:
        net.load_state_dict(d["state_dict"])
    except RuntimeError as e:
        raise ConfigError(source, str(path), f"its weights do not fit the verifier network: {e}") from None
    return net.eval(), {k: float(d[k]) for k in FILE_KEYS[:4]}


def onnx_graph(net: nn.Module) -> bytes:
    """The network as ONNX (input ``x`` (n, 3, SIDE, SIDE), output ``y`` (n,); the batch dynamic)."""
    buf = io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(net, (torch.zeros(1, 3, SIDE, SIDE),), buf, input_names=["x"], output_names=["y"],
                          dynamic_axes={"x": {0: "n"}, "y": {0: "n"}}, opset_version=ONNX_OPSET, dynamo=False)
    return buf.getvalue()


def verifier_graph(path: Path, source: str) -> tuple[bytes, dict]:
    """(the ONNX graph of the verifier file ``path``, its thresholds): the ONNX cache's export of a verifier."""
    net, thresholds = read_verifier(path, source)
    return onnx_graph(net), thresholds
