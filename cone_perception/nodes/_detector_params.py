"""Detector parameters shared by the ``detection`` and ``pipeline`` nodes."""

from __future__ import annotations

import numpy as np
from rclpy.node import Node

from ..detector import DEFAULT_BACKEND, RUNTIME_THREADS, Detector, default_model_path


def load_detector(node: Node, band_wh: tuple[int, int] | None = None) -> Detector:
    """Declare the detector parameters on ``node``, load the model and warm it up.

    ``band_wh`` (W, H) is the size of the images the node will see, when known; warming up at
    that size makes the first real frame as fast as the rest.
    """
    model = node.declare_parameter("model", "").value or str(default_model_path())
    threads = int(node.declare_parameter("threads", RUNTIME_THREADS).value)  # 0 = library default
    # with a known band, a checkpoint is built for the band's own size (no letterbox, also for
    # fixed-size backends); the detection node learns the band only later and uses the model's size
    load = (lambda path, **kw: Detector.load_for_band(path, band_wh, **kw)) if band_wh else Detector.load
    det = load(
        model,
        backend=node.declare_parameter("backend", DEFAULT_BACKEND).value,
        device=node.declare_parameter("device", "cpu").value,
        fp16=bool(node.declare_parameter("fp16", False).value),
        bf16=bool(node.declare_parameter("bf16", False).value),
        conf=float(node.declare_parameter("conf", 0.25).value),
        iou=float(node.declare_parameter("iou", 0.45).value),
        max_det=int(node.declare_parameter("max_det", 100).value),
        threads=threads or None,
    )
    if band_wh is None:
        det.warmup()
    else:
        for _ in range(3):
            det.infer(np.zeros((band_wh[1], band_wh[0], 3), np.uint8))
    node.get_logger().info(f"model {det.source} ({det.backend} {det.precision}, "
                           f"{threads or 'library default'} thread(s), input {det.imgsz[0]}x{det.imgsz[1]}) loaded and warm")
    return det
