"""Detector parameters shared by the ``detection`` and ``pipeline`` nodes."""

from __future__ import annotations

import numpy as np
from rclpy.node import Node

from ..detector import Detector, default_model_path
from ..detector.parallel import ForwardPlan
from ._params import declare


class DetectorLoader:
    """Declares the detector parameters on a node once; :meth:`load` loads and warms a detector."""

    #: The detector settings a node changes at run time (``ros2 param set``): :meth:`set_threshold`.
    RUNTIME = ("conf", "iou", "max_det")

    def __init__(self, node: Node) -> None:
        self.node = node
        self.model = declare(node, "model") or str(default_model_path())
        self.threads = int(declare(node, "threads"))  # 0 = library default
        self.kw = dict(
            backend=declare(node, "backend"),
            device=declare(node, "device"),
            fp16=bool(declare(node, "fp16")),
            bf16=bool(declare(node, "bf16")),
            conf=float(declare(node, "conf")),
            iou=float(declare(node, "iou")),
            max_det=int(declare(node, "max_det")),
            threads=self.threads or None,
        )

    def plan_threads(self, strip: bool) -> ForwardPlan:
        """The band's and the far strip's forwards for the ``threads`` parameter (:meth:`ForwardPlan.of`: with a
        strip and ``threads >= 2`` at once, each network on ``threads // 2``); later loads use its thread count."""
        plan = ForwardPlan.of(self.threads, strip)
        self.kw["threads"] = plan.network_threads or None
        if strip:
            self.node.get_logger().info(f"far strip: {plan.describe()} ({self.threads or 'library default'} thread(s))")
        return plan

    def set_threshold(self, detector: Detector, name: str, value) -> None:
        """Apply a new ``conf``, ``iou`` or ``max_det`` to ``detector`` and to later (re)loads."""
        value = int(value) if name == "max_det" else float(value)
        self.kw[name] = value
        setattr(detector, name, value)

    def load(self, band_wh: tuple[int, int] | None = None, model: str | None = None) -> Detector:
        """Load the model (``model``: another file than the ``model`` parameter's, e.g. ``far_model``) and warm it up. ``band_wh`` (W, H) is the size of the images the node will
        see, when known: a checkpoint is then built for the band's own size (no letterbox, also for
        fixed-size backends) and warmed at it, so the first real frame is as fast as the rest."""
        model = model or self.model
        if band_wh:
            det = Detector.load_for_band(model, band_wh, **self.kw)
            for _ in range(3):
                det.infer(np.zeros((band_wh[1], band_wh[0], 3), np.uint8))
        else:
            det = Detector.load(model, **self.kw)
            det.warmup()
        self.node.get_logger().info(
            f"model {det.source} ({det.backend} on {det.runs_on}, {det.precision}, {self.kw['threads'] or 'library default'} thread(s), "
            f"input {det.imgsz[0]}x{det.imgsz[1]}) loaded and warm")
        return det

