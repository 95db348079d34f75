"""Detector parameters shared by the ``detection`` and ``pipeline`` nodes."""

from __future__ import annotations

import numpy as np
from rclpy.node import Node

from ..detector import Detector, default_model_path, round_up32


def load_detector(node: Node, band_wh: tuple[int, int] | None = None) -> Detector:
    """Declare the detector parameters on ``node``, load the model and warm it up.

    ``band_wh`` (W, H) is the size of the images the node will see, when known; warming up at
    that size makes the first real frame as fast as the rest.
    """
    model = node.declare_parameter("model", "").value or str(default_model_path())
    backend = node.declare_parameter("backend", "torch").value
    # fixed-size backends built from a checkpoint are built for the band's own size (no letterbox)
    imgsz = (round_up32(band_wh[0]), round_up32(band_wh[1])) if band_wh and backend != "torch" and model.endswith(".pt") else None
    det = Detector.load(
        model,
        backend=backend,
        imgsz=imgsz,
        device=node.declare_parameter("device", "cpu").value,
        fp16=bool(node.declare_parameter("fp16", False).value),
        conf=float(node.declare_parameter("conf", 0.25).value),
        iou=float(node.declare_parameter("iou", 0.45).value),
        max_det=int(node.declare_parameter("max_det", 100).value),
        threads=int(node.declare_parameter("threads", 0).value) or None,
    )
    if band_wh is None:
        det.warmup()
    else:
        for _ in range(3):
            det.infer(np.zeros((band_wh[1], band_wh[0], 3), np.uint8))
    node.get_logger().info(f"model {det.source} ({det.backend}, input {det.imgsz[0]}x{det.imgsz[1]}) loaded and warm")
    return det
