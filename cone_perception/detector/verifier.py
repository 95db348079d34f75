"""A second look at the far strip's doubtful boxes: a tiny classifier, cone or not, on a crop around each box.

The far strip's network finds cones 8-20 px tall at full resolution; at that size worn paint (short dashes of a
yellow line seen from afar) looks like a yellow cone to it, scored 0.25-0.75 (docs/benchmarks.md, "A second look
at the far strip's boxes"). :class:`BoxVerifier` cuts a square around each box in the strip's rows (the band's
and the strip's, :meth:`~cone_perception.detector.farband.FarBand.verify`) scored below its ``verify_below``,
``CTX`` times the box's height wide, resizes it to ``SIDE`` x ``SIDE`` px and asks a four-layer
network (:class:`VerifierNet`, about 60 k weights) whether a cone stands there; a box it gives less than ``min_p``
is dropped (counted). It sees the box's own pixels and context at a fixed scale, where the detector saw the box
among a whole strip's; it was trained on crops around rendered cones, rendered false detections of the far
model (paint, the verge) and real cones (``cone-perception data verifier-crops``, then ``train --data CROPS.npz``;
docs/training.md). Its file
holds the weights, the crop geometry and both thresholds (models/cone_verifier.md). ROS-free.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..crop import CTX, SIDE, crop_patch
from ..errors import ConfigError

#: What the ``far_verifier`` parameter / ``--far-verifier`` option may be besides a file: ``auto`` (the shipped
#: verifier, models/cone_verifier.pt; none where it is not installed) or ``none`` / empty (no second look).
VERIFIER_AUTO = "auto"
VERIFIER_OFF = ("", "none", "off")
DEFAULT_VERIFIER_NAME = "cone_verifier.pt"


def _net_class():
    import torch.nn as nn

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

    return VerifierNet


def new_net():
    """A fresh :class:`VerifierNet` (torch imported here: the package's --help stays light)."""
    return _net_class()()


def patches_tensor(patches: np.ndarray):
    """(N, SIDE, SIDE, 3) uint8 BGR -> (N, 3, SIDE, SIDE) float32 torch tensor 0..1."""
    import torch

    return torch.from_numpy(np.ascontiguousarray(patches)).permute(0, 3, 1, 2).float().div_(255.0)


def _ort_runner(net, source: str):
    """The network as an ONNX Runtime session on one thread (a batch of crops in a fifth of eager torch's time), or
    None where onnx / onnxruntime are not installed (eager torch then)."""
    try:
        import onnx  # noqa: F401 - torch's exporter needs it
        import onnxruntime  # noqa: F401
    except ImportError:
        return None
    import io
    import warnings

    import torch

    from .backends import ort_session

    buf = io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(net, (torch.zeros(1, 3, SIDE, SIDE),), buf, input_names=["x"], output_names=["y"],
                          dynamic_axes={"x": {0: "n"}, "y": {0: "n"}}, opset_version=17, dynamo=False)
    return ort_session(buf.getvalue(), "cpu", 1, source)


class BoxVerifier:
    """A loaded verifier (:func:`load_verifier`): ``probabilities(img, boxes)`` and ``drops(img, boxes, ...)``."""

    def __init__(self, net, verify_below: float, min_p: float, min_px: float, max_px: float, source: str = "",
                 session=None):
        self.net, self.source, self.session = net, source, session  # session: ONNX Runtime's, or None (torch)
        self.verify_below, self.min_p, self.min_px, self.max_px = verify_below, min_p, min_px, max_px
        self.counts = {"checked": 0, "dropped": 0}

    def probabilities(self, img: np.ndarray, xyxy: np.ndarray) -> np.ndarray:
        """(N,) probability that a cone stands in each box (N, 4) u1 v1 u2 v2 of ``img`` px."""
        if len(xyxy) == 0:
            return np.zeros(0)
        patches = np.stack([crop_patch(img, b) for b in xyxy])
        if self.session is not None:
            x = np.ascontiguousarray(patches.transpose(0, 3, 1, 2), dtype=np.float32) / np.float32(255.0)
            logits = self.session.run(None, {"x": x})[0].astype(np.float64)
            return 1.0 / (1.0 + np.exp(-logits))
        import torch

        with torch.inference_mode():
            return torch.sigmoid(self.net(patches_tensor(patches))).numpy().astype(np.float64)

    def drops(self, img: np.ndarray, boxes: np.ndarray, u0: float = 0.0, v0: float = 0.0,
              downscale: float = 1.0) -> np.ndarray:
        """(N,) bool: which ``BOX_DTYPE`` boxes (full-image px; ``img``: the image cut from column ``u0``, row ``v0``
        at ``downscale``, e.g. the far strip), scored below ``verify_below`` and ``min_px``-``max_px`` tall
        (full-image px), the network gives less than ``min_p`` (counted in :attr:`counts`)."""
        drop = np.zeros(len(boxes), bool)
        if len(boxes) == 0:
            return drop
        h = boxes["v2"] - boxes["v1"]
        ask = (boxes["score"] < self.verify_below) & (h >= self.min_px) & (h <= self.max_px)
        if not ask.any():
            return drop
        b = boxes[ask]
        xyxy = (np.c_[b["u1"], b["v1"], b["u2"], b["v2"]].astype(np.float64) - [u0, v0, u0, v0]) / downscale
        p = self.probabilities(img, xyxy)
        drop[np.flatnonzero(ask)] = p < self.min_p
        self.counts["checked"] += int(ask.sum())
        self.counts["dropped"] += int(drop.sum())
        return drop


def default_verifier_path() -> Path:
    from ..resources import models_dir

    return models_dir() / DEFAULT_VERIFIER_NAME


def verifier_path_for(choice) -> Path | None:
    """The verifier file of ``far_verifier`` / ``--far-verifier`` ``choice`` (None: the default, off): ``auto`` -> the
    shipped one where installed (else None), ``none`` / ``off`` / empty -> None, else ``Path(choice)``."""
    c = "" if choice is None else str(choice).strip()
    if c.lower() == VERIFIER_AUTO:
        p = default_verifier_path()
        return p if p.is_file() else None
    if c.lower() in VERIFIER_OFF:
        return None
    return Path(c)


#: The keys a verifier file holds besides the weights (written by ``train --data CROPS.npz``).
FILE_KEYS = ("verify_below", "min_p", "min_px", "max_px", "side", "ctx")


def save_verifier(path: str | Path, net, verify_below: float, min_p: float, min_px: float, max_px: float,
                  info: dict | None = None) -> None:
    import torch

    torch.save({"kind": "cone_verifier", "state_dict": net.state_dict(), "verify_below": float(verify_below),
                "min_p": float(min_p), "min_px": float(min_px), "max_px": float(max_px), "side": SIDE, "ctx": CTX,
                "info": dict(info or {})}, str(path))


def load_verifier(choice, source: str = "far_verifier") -> BoxVerifier | None:
    """The verifier of ``choice`` (:func:`verifier_path_for`), or None; ConfigError naming ``source`` and the file
    for a missing or unreadable file, one that is not a verifier, or one cut for another crop geometry."""
    path = verifier_path_for(choice)
    if path is None:
        return None
    import torch

    if not path.is_file():
        raise ConfigError(source, str(path), "no such verifier file (auto = the shipped one; none = no second look)")
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
    net.eval()
    return BoxVerifier(net, float(d["verify_below"]), float(d["min_p"]), float(d["min_px"]), float(d["max_px"]),
                       str(path), _ort_runner(net, source))
