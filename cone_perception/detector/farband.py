"""The far band: the image rows near the horizon run a second time at full resolution.

At the car's 960x288 input (the band halved), cones beyond about 15 m are under 12 px tall and
most of them are missed. The far band cuts a strip of full-resolution rows (``V0,V1``, the whole
image width, no downscale) where those cones stand, runs the detector on it as well, and merges
its boxes with the band's:

* a far-band box that touches the strip's top or bottom edge (within ``EDGE_PX``) is dropped:
  it is a nearer cone cut by the strip, which the band sees whole;
* the rest join the band's boxes, and one class-aware NMS keeps the best box of each cone.

Cost: one more forward on ``width x (V1 - V0)`` px (1920x192: 1.33x the pixels of 960x288).
What it is worth: ``models/cone_detector.md``, "Small, far cones".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..classes import CLASS_NAMES
from ..crop import CropSpec
from ..errors import ConfigError
from ..model.decode import nms_per_class
from ..params import DEFAULT_IOU
from .detector import Detector

#: A far-band box whose top or bottom is this close to the strip's edge (full-image px) is a cut cone.
EDGE_PX = 2.0


def far_band_crop(rows: str | tuple[int, int], image_width: int, image_height: int, band: CropSpec,
                  source: str = "far_rows") -> CropSpec:
    """``"V0,V1"`` (or a pair) -> the far band's crop: rows V0..V1, the whole width, downscale 1.

    ConfigError naming ``source`` unless the rows lie inside the image, overlap the band (a far
    band beside the band would see cones the mapping was not calibrated for) and span 32-1024 rows."""
    if isinstance(rows, str):
        try:
            v0, v1 = (int(float(t)) for t in rows.split(","))
        except ValueError:
            raise ConfigError(source, None, f"expected two image rows V0,V1, got {rows!r}") from None
    else:
        v0, v1 = (int(r) for r in rows)
    if not 0 <= v0 < v1 <= image_height:
        raise ConfigError(source, None, f"rows {v0},{v1} are not inside the {image_width}x{image_height} image")
    if v1 <= band.v0 or v0 >= band.v1:
        raise ConfigError(source, None, f"rows {v0},{v1} do not overlap the band's rows {band.v0},{band.v1}")
    if not 32 <= v1 - v0 <= 1024:
        raise ConfigError(source, None, f"{v1 - v0} rows: the far band needs 32..1024 rows")
    crop = CropSpec(v0, v1, 0, image_width, 1)
    crop.validate(image_width, image_height, source)
    return crop


def drop_cut_boxes(boxes: np.ndarray, crop: CropSpec, edge_px: float = EDGE_PX) -> np.ndarray:
    """``BOX_DTYPE`` boxes of a strip minus those touching its top or bottom edge (cones the strip cuts)."""
    keep = (boxes["v1"] > crop.v0 + edge_px) & (boxes["v2"] < crop.v1 - edge_px)
    return boxes[keep]


def merge_boxes(band_boxes: np.ndarray, far_boxes: np.ndarray, iou: float = DEFAULT_IOU) -> np.ndarray:
    """Boxes of the band and of the far band (``BOX_DTYPE``, full-image px) -> one set, best first:
    class-aware NMS over both, so a cone both saw keeps its best-scored box."""
    if len(far_boxes) == 0:
        return band_boxes
    both = np.concatenate([band_boxes, far_boxes])
    xywh = np.stack([both["u1"], both["v1"], both["u2"] - both["u1"], both["v2"] - both["v1"]], 1)
    keep = nms_per_class(xywh, both["score"], both["class_id"], 0.0, iou)
    return both[keep]


def check_far_classes(band_detector, far_detector, source: str = "far_model") -> None:
    """ConfigError naming ``source`` (the far model's option) unless the far band's model finds the same
    cone classes as the band's: their boxes merge into one set, and a class only one of them knows would
    come and go with the cone's distance. Detectors without a ``class_map`` (test doubles) are not checked."""
    band, far = getattr(band_detector, "class_map", None), getattr(far_detector, "class_map", None)
    if band is None or far is None:
        return
    band, far = {int(c) for c in band}, {int(c) for c in far}
    if band != far:
        def names(ids):
            return ", ".join(CLASS_NAMES[i] for i in sorted(ids)) or "none"
        raise ConfigError(source, getattr(far_detector, "source", None),
                          f"the far band's model has the classes [{names(far)}], the band's model [{names(band)}]: "
                          f"only in the far model: [{names(far - band)}], only in the band's: [{names(band - far)}]")


@dataclass
class FarBand:
    """The far band of one camera: its crop and the detector built for its size (``Detector.load_for_band``).

    ``model_source``: the option the far band's model came from (``far_model``, ``--far-model``), named by
    :meth:`check_classes`'s error."""

    crop: CropSpec
    detector: object  # a Detector (anything with detect(bgr, crop) -> BOX_DTYPE and a timing dict)
    model_source: str = "far_model"

    def check_classes(self, band_detector) -> None:
        """ConfigError naming :attr:`model_source` unless this band's model has the band model's classes
        (:func:`check_far_classes`); the Pipeline calls it before the first frame."""
        check_far_classes(band_detector, self.detector, self.model_source)

    @classmethod
    def load(cls, model, rows: str | tuple[int, int], image_width: int, image_height: int, band: CropSpec,
             source: str = "far_rows", model_source: str = "far_model", **detector_kw) -> "FarBand":
        """The far band of ``rows`` with ``model`` (the band's own, or a far model: ``model_source`` names
        its option in errors) built for its strip (``Detector.load_for_band``)."""
        crop = far_band_crop(rows, image_width, image_height, band, source)
        det = Detector.load_for_band(model, (crop.out_width, crop.out_height), **detector_kw)
        det.warmup()
        return cls(crop, det, model_source)

    def detect(self, strip_bgr: np.ndarray) -> np.ndarray:
        """Full-resolution strip ``(V1 - V0, W, 3)`` BGR -> its boxes, cut cones dropped (full-image px)."""
        return drop_cut_boxes(self.detector.detect(strip_bgr, self.crop), self.crop)

    def merged(self, band_boxes: np.ndarray, strip_bgr: np.ndarray) -> np.ndarray:
        iou = getattr(self.detector, "iou", DEFAULT_IOU)
        return merge_boxes(band_boxes, self.detect(strip_bgr), iou)


__all__ = ["EDGE_PX", "FarBand", "check_far_classes", "drop_cut_boxes", "far_band_crop", "merge_boxes"]
