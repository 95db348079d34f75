"""The three stages in one call: raw frame -> cropped band -> boxes -> cones.

Used by the fused ``pipeline`` node, the offline ``replay``, ``detect`` on bags and
``bench``, so every path runs the very same code. ROS-free.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .adapter import DriverAdapter
from .calib import Calibration
from .mapping import ConeMapper

STAGES = ("adapter", "preprocess", "forward", "postprocess", "mapping")


@dataclass
class FrameResult:
    """Output of one frame: boxes (``BOX_DTYPE``, full-image px), cones (``CONE_DTYPE``, m), stage ms,
    and the band (for the debug image)."""

    boxes: np.ndarray
    cones: np.ndarray
    timing_ms: dict[str, float] = field(default_factory=dict)
    band: np.ndarray | None = None  # (H, W, 3) uint8 BGR: the cropped band the detector saw


class Pipeline:
    """Driver adapter + detector + mapper of one calibrated camera.

    ``detector`` is a :class:`cone_perception.detector.Detector` (anything with
    ``detect(bgr_cropped, crop) -> BOX_DTYPE`` and a ``timing`` dict of ms).
    """

    def __init__(self, calib: Calibration, detector):
        self.calib = calib
        self.adapter = DriverAdapter(calib.crop, calib.image_width, calib.image_height)
        self.detector = detector
        self.mapper = ConeMapper(calib)

    def _run(self, band: np.ndarray, t_adapter_s: float) -> FrameResult:
        boxes = self.detector.detect(band, self.calib.crop)
        t0 = time.perf_counter()
        cones = self.mapper.map_boxes(boxes)
        t_map = time.perf_counter() - t0
        timing = {"adapter": t_adapter_s * 1e3}
        timing.update({k.removesuffix("_ms"): v for k, v in self.detector.timing.items()})
        timing["mapping"] = t_map * 1e3
        return FrameResult(boxes, cones, timing, band)

    def process_raw(self, encoding: str, width: int, height: int, step: int, data) -> FrameResult:
        """sensor_msgs/Image fields -> :class:`FrameResult`. Raises ``FrameError`` for a bad frame."""
        t0 = time.perf_counter()
        band = self.adapter.from_raw(encoding, width, height, step, data)
        return self._run(band, time.perf_counter() - t0)

    def process_compressed(self, data) -> FrameResult:
        """sensor_msgs/CompressedImage data (JPEG/PNG) -> :class:`FrameResult`."""
        t0 = time.perf_counter()
        band = self.adapter.from_compressed(data)
        return self._run(band, time.perf_counter() - t0)
