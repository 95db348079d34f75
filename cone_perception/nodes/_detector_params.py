"""Detector parameters shared by the ``detection`` and ``pipeline`` nodes."""

from __future__ import annotations

import numpy as np
from rclpy.node import Node

from ..detector import DEFAULT_BACKEND, RUNTIME_THREADS, Detector, default_model_path


class DetectorLoader:
    """Declares the detector parameters on a node once; :meth:`load` loads and warms a detector."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.model = node.declare_parameter("model", "").value or str(default_model_path())
        self.threads = int(node.declare_parameter("threads", RUNTIME_THREADS).value)  # 0 = library default
        self.kw = dict(
            backend=node.declare_parameter("backend", DEFAULT_BACKEND).value,
            device=node.declare_parameter("device", "cpu").value,
            fp16=bool(node.declare_parameter("fp16", False).value),
            bf16=bool(node.declare_parameter("bf16", False).value),
            conf=float(node.declare_parameter("conf", 0.25).value),
            iou=float(node.declare_parameter("iou", 0.45).value),
            max_det=int(node.declare_parameter("max_det", 100).value),
            threads=self.threads or None,
        )

    def load(self, band_wh: tuple[int, int] | None = None) -> Detector:
        """Load the model and warm it up. ``band_wh`` (W, H) is the size of the images the node will
        see, when known: a checkpoint is then built for the band's own size (no letterbox, also for
        fixed-size backends) and warmed at it, so the first real frame is as fast as the rest."""
        if band_wh:
            det = Detector.load_for_band(self.model, band_wh, **self.kw)
            for _ in range(3):
                det.infer(np.zeros((band_wh[1], band_wh[0], 3), np.uint8))
        else:
            det = Detector.load(self.model, **self.kw)
            det.warmup()
        self.node.get_logger().info(
            f"model {det.source} ({det.backend} {det.precision}, {self.threads or 'library default'} thread(s), "
            f"input {det.imgsz[0]}x{det.imgsz[1]}) loaded and warm")
        return det


def load_detector(node: Node, band_wh: tuple[int, int] | None = None) -> Detector:
    """Declare the detector parameters on ``node`` and load the detector (:class:`DetectorLoader`)."""
    return DetectorLoader(node).load(band_wh)
