"""A second look at the far strip's doubtful boxes: a tiny classifier, cone or not, on a crop around each box.

The far strip's network finds cones 8-20 px tall at full resolution; at that size worn paint (short dashes of a
yellow line seen from afar) looks like a yellow cone to it, scored 0.25-0.75 (docs/benchmarks.md, "A second look
at the far strip's boxes"). :class:`BoxVerifier` cuts a square around each box in the strip's rows (the band's
and the strip's, :meth:`~cone_perception.detector.farband.FarBand.verify`) scored below its ``verify_below``,
``CTX`` times the box's height wide, resizes it to ``SIDE`` x ``SIDE`` px and asks a four-layer
network (:class:`~.verifier_net.VerifierNet`, about 60 k weights) whether a cone stands there; a box it gives less than ``min_p``
is dropped (counted). It sees the box's own pixels and context at a fixed scale, where the detector saw the box
among a whole strip's; it was trained on crops around rendered cones, rendered false detections of the far
model (paint, the verge) and real cones (``cone-perception data verifier-crops``, then ``train --data CROPS.npz``;
docs/training.md). Its file
holds the weights, the crop geometry and both thresholds (models/cone_verifier.md). ROS-free; torch-free (the
network, its file and its export: :mod:`.verifier_net`, imported where torch is needed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..crop import CTX, SIDE, crop_patch
from ..errors import ConfigError
from ..resources import models_dir
from .backends import ONNX_OPSET, installed, ort_session
from .onnx_cache import VERIFIER, load_graph

#: What the ``far_verifier`` parameter / ``--far-verifier`` option may be besides a file: ``auto`` (the shipped
#: verifier, models/cone_verifier.pt; none where it is not installed) or ``none`` / empty (no second look).
VERIFIER_AUTO = "auto"
VERIFIER_OFF = ("", "none", "off")
DEFAULT_VERIFIER_NAME = "cone_verifier.pt"


def _torch():
    """:mod:`.verifier_net` (torch), imported to read or export a verifier file or run it on torch; never on a warm
    start on ONNX Runtime."""
    import cone_perception.detector.verifier_net as verifier_net  # torch: heavy, absent from a warm ONNX start

    return verifier_net


def _session_problem(session, info: dict) -> str | None:
    """What is wrong with a cached verifier graph: not (n, 3, SIDE, SIDE) in ``x``, or its thresholds missing."""
    if not all(isinstance(info.get(k), (int, float)) for k in THRESHOLDS):
        return "its description lacks the verifier's thresholds"
    inp = session.get_inputs()[0]
    shape = list(inp.shape)
    if inp.name != "x" or len(shape) != 4 or shape[1:] != [3, SIDE, SIDE]:
        return f"its input is {inp.name} {shape}, expected x [n, 3, {SIDE}, {SIDE}]"
    return None


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
        return _torch().probabilities(self.net, patches)

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


#: The thresholds a verifier file holds besides the weights and the crop geometry (``verifier_net.FILE_KEYS``).
THRESHOLDS = ("verify_below", "min_p", "min_px", "max_px")


def load_verifier(choice, source: str = "far_verifier") -> BoxVerifier | None:
    """The verifier of ``choice`` (:func:`verifier_path_for`), or None; ConfigError naming ``source`` and the file
    for a missing or unreadable file, one that is not a verifier, or one cut for another crop geometry. Where ONNX
    Runtime is installed it runs the verifier's graph from the ONNX cache (:func:`~.onnx_cache.load_graph`; torch
    only to export it where the cache misses), on one thread (a batch of crops in a fifth of eager torch's time);
    else eager torch."""
    path = verifier_path_for(choice)
    if path is None:
        return None
    if not path.is_file():
        raise ConfigError(source, str(path), "no such verifier file (auto = the shipped one; none = no second look)")
    if installed("onnxruntime") and installed("onnx"):
        session, info, _ = load_graph(path, VERIFIER, {"opset": ONNX_OPSET, "side": SIDE, "ctx": CTX},
                                      lambda: _torch().verifier_graph(path, source),
                                      lambda graph: ort_session(graph, "cpu", 1, source), _session_problem, source)
        return BoxVerifier(None, *(float(info[k]) for k in THRESHOLDS), str(path), session)
    net, t = _torch().read_verifier(path, source)
    return BoxVerifier(net, *(t[k] for k in THRESHOLDS), str(path))
