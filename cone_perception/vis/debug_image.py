"""The debug image (``image_cropped/debug``): the band the detector saw, with each box in its
class colour, its score and the distance of its cone. ROS-free; the nodes publish it
(``debug_image: true``), ``bench`` times it."""

from __future__ import annotations

import cv2
import numpy as np

from ..classes import CLASS_NAMES
from ..crop import CropSpec
from ..errors import FrameError
from ..mapping import ConeMapper
from .draw import draw_boxes


def box_ranges_m(mapper: ConeMapper, boxes: np.ndarray) -> np.ndarray:
    """(N,) float64: distance (m) from the ``rear_axle`` origin to the cone each of the ``BOX_DTYPE``
    records maps to, NaN where the box maps to no cone (above the horizon, beyond the range, flat, bad).

    The very mapping of ``/cones`` (:meth:`ConeMapper.box_ranges`), each box by itself and nothing counted (the
    frame's own mapping counts its drops); a message ``map_boxes`` refuses as a whole is mapped box by box.
    """
    n = len(boxes)
    if n == 0:
        return np.full(0, np.nan)
    try:
        return mapper.box_ranges(boxes)
    except FrameError:
        return np.array([box_ranges_m(mapper, boxes[i : i + 1])[0] if n > 1 else np.nan for i in range(n)])


def draw_debug_band(band_bgr: np.ndarray, boxes: np.ndarray, crop: CropSpec, ranges_m: np.ndarray | None = None) -> np.ndarray:
    """A copy of ``band_bgr`` (H, W, 3) uint8 with ``boxes`` (``BOX_DTYPE``, full-image px) drawn in
    band px: class colour, "class score distance" (e.g. ``blue 0.87 6.2 m``; ``-`` where the box
    maps to no cone), and the number of boxes in the top-left corner. No boxes: the band as it is,
    with "0 boxes"."""
    boxes = np.asarray(boxes)
    band_boxes = boxes.copy()
    if len(boxes):
        uv1 = crop.to_cropped(np.stack([boxes["u1"], boxes["v1"]], 1))
        uv2 = crop.to_cropped(np.stack([boxes["u2"], boxes["v2"]], 1))
        band_boxes["u1"], band_boxes["v1"] = uv1[:, 0], uv1[:, 1]
        band_boxes["u2"], band_boxes["v2"] = uv2[:, 0], uv2[:, 1]
    texts = []
    for i, b in enumerate(boxes):
        cid = int(b["class_id"])
        name = CLASS_NAMES[cid] if cid < len(CLASS_NAMES) else str(cid)
        r = np.nan if ranges_m is None else float(ranges_m[i])
        texts.append(f"{name} {float(b['score']):.2f} " + (f"{r:.1f} m" if np.isfinite(r) else "-"))
    out = draw_boxes(band_bgr, band_boxes, texts=texts)
    label = f"{len(boxes)} box{'' if len(boxes) == 1 else 'es'}"
    cv2.putText(out, label, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(out, label, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (255, 255, 255), 1, cv2.LINE_AA)
    return out


class RateLimit:
    """At most ``hz`` events per second: :meth:`due` is true when ``1 / hz`` has passed since the last
    event it let through (the first is always due)."""

    def __init__(self, hz: float) -> None:
        self.hz = float(hz)
        self._last: float | None = None

    def due(self, now_s: float) -> bool:
        if self._last is not None and now_s - self._last < 1.0 / self.hz - 1e-6:  # 1 us: float rounding
            return False
        self._last = now_s
        return True


class DebugImage:
    """What a node needs for its debug image: the mapper for the distances (None: no distances, ``-``)
    and the rate limit."""

    def __init__(self, mapper: ConeMapper | None, hz: float = 5.0) -> None:
        self.mapper = mapper
        self.limit = RateLimit(hz)

    def render(self, band_bgr: np.ndarray, boxes: np.ndarray, crop: CropSpec) -> np.ndarray:
        """The debug image of one frame: :func:`draw_debug_band` with :func:`box_ranges_m`."""
        ranges = None if self.mapper is None else box_ranges_m(self.mapper, boxes)
        return draw_debug_band(band_bgr, boxes, crop, ranges)
