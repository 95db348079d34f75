"""The band of the road: crop rectangle and integer downscale, and the mapping
between cropped-image pixels and full-image pixels.

Conventions: all rectangles are half-open ``[u0, u1) x [v0, v1)`` in pixels of
the FULL camera image. The cropped image has size
``((u1 - u0) / downscale, (v1 - v0) / downscale)``.
A cropped pixel coordinate ``(uc, vc)`` (continuous, pixel corners at integers)
maps to the full image as ``u = u0 + uc * downscale``, ``v = v0 + vc * downscale``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .errors import ConfigError, FrameError

ALLOWED_DOWNSCALE = (1, 2, 4)

#: A cone cut by the edge of a band or a training window still counts when at least this
#: fraction of its box area remains inside (training keeps such boxes clipped; ``eval --band``
#: scores them clipped and ignores the rest).
MIN_VISIBLE = 0.3


@dataclass(frozen=True)
class CropSpec:
    """Crop band in full-image pixels plus an integer downscale factor."""

    v0: int
    v1: int
    u0: int
    u1: int
    downscale: int = 1

    @property
    def width_full_px(self) -> int:
        return self.u1 - self.u0

    @property
    def height_full_px(self) -> int:
        return self.v1 - self.v0

    @property
    def out_width(self) -> int:
        """Width of the cropped (and downscaled) image in pixels."""
        return self.width_full_px // self.downscale

    @property
    def out_height(self) -> int:
        """Height of the cropped (and downscaled) image in pixels."""
        return self.height_full_px // self.downscale

    def validate(self, image_width: int, image_height: int, source: str = "crop") -> None:
        """Raise :class:`ConfigError` unless the crop fits the image and the factor."""
        if self.downscale not in ALLOWED_DOWNSCALE:
            raise ConfigError(source, "downscale", f"must be one of {ALLOWED_DOWNSCALE}, got {self.downscale}")
        if not (0 <= self.v0 < self.v1 <= image_height):
            raise ConfigError(
                source, "crop.v0/v1", f"rows [{self.v0}, {self.v1}) must lie inside 0..{image_height} with v0 < v1"
            )
        if not (0 <= self.u0 < self.u1 <= image_width):
            raise ConfigError(
                source, "crop.u0/u1", f"columns [{self.u0}, {self.u1}) must lie inside 0..{image_width} with u0 < u1"
            )
        if self.u0 % 2 or self.u1 % 2:
            raise ConfigError(source, "crop.u0/u1", f"must be even (YUYV packs 2 pixels), got {self.u0}, {self.u1}")
        if self.width_full_px % self.downscale or self.height_full_px % self.downscale:
            raise ConfigError(
                source,
                "crop",
                f"band {self.width_full_px}x{self.height_full_px} is not divisible by downscale {self.downscale}",
            )

    @classmethod
    def full_image(cls, width: int, height: int, downscale: int = 1) -> "CropSpec":
        return cls(0, height, 0, width, downscale)

    # -- coordinates --------------------------------------------------------------
    def to_full(self, uv_cropped_px: np.ndarray) -> np.ndarray:
        """(N, 2) cropped-image px -> (N, 2) full-image px (float)."""
        uv = np.asarray(uv_cropped_px, dtype=np.float64)
        return uv * self.downscale + np.array([self.u0, self.v0], dtype=np.float64)

    def to_cropped(self, uv_full_px: np.ndarray) -> np.ndarray:
        """(N, 2) full-image px -> (N, 2) cropped-image px (float)."""
        uv = np.asarray(uv_full_px, dtype=np.float64)
        return (uv - np.array([self.u0, self.v0], dtype=np.float64)) / self.downscale

    def boxes_to_full(self, boxes_cropped_px: np.ndarray) -> np.ndarray:
        """(N, 4) boxes ``u1 v1 u2 v2`` in cropped px -> full-image px (float32)."""
        b = np.asarray(boxes_cropped_px, dtype=np.float32).reshape(-1, 4)
        off = np.array([self.u0, self.v0, self.u0, self.v0], dtype=np.float32)
        return b * np.float32(self.downscale) + off

    # -- sensor_msgs/CameraInfo roi + binning ---------------------------------------
    def camera_info_fields(self, image_width: int, image_height: int) -> dict:
        """Fields of the ``image_cropped/camera_info`` message (plain values).

        ``width``/``height`` are the FULL image size; ``roi`` the crop rectangle
        in full-image px; ``binning_x/y`` the downscale factor.
        """
        return {
            "width": int(image_width),
            "height": int(image_height),
            "binning_x": int(self.downscale),
            "binning_y": int(self.downscale),
            "roi": {
                "x_offset": int(self.u0),
                "y_offset": int(self.v0),
                "width": int(self.width_full_px),
                "height": int(self.height_full_px),
                "do_rectify": False,
            },
        }

    @classmethod
    def from_camera_info(
        cls, *, width: int, height: int, roi_x: int, roi_y: int, roi_w: int, roi_h: int, binning_x: int, binning_y: int
    ) -> "CropSpec":
        """Inverse of :meth:`camera_info_fields`.

        Follows the CameraInfo convention: an all-zero roi means the full image;
        binning 0 means 1. Raises ``ValueError`` for unequal binning.
        """
        bx = int(binning_x) or 1
        by = int(binning_y) or 1
        if bx != by:
            raise ValueError(f"camera_info binning_x={bx} != binning_y={by}: only square downscale is supported")
        if roi_w == 0 or roi_h == 0:
            return cls(0, int(height), 0, int(width), bx)
        return cls(int(roi_y), int(roi_y + roi_h), int(roi_x), int(roi_x + roi_w), bx)


#: Largest full image side a calibration or a ``camera_info`` may declare (px); a larger one is an
#: error, not an allocation (``image_width: 1e9`` once ended in an out-of-memory traceback).
MAX_IMAGE_SIDE_PX = 16384
#: Largest band (after downscale) a ``camera_info`` may ask the detection node to run, in px; a
#: fixed-size network is built for the band, and a larger one would cost seconds and gigabytes.
MAX_BAND_PIXELS = 4096 * 2048


def camera_info_crop(
    *, width: int, height: int, roi_x: int, roi_y: int, roi_w: int, roi_h: int, binning_x: int, binning_y: int
) -> CropSpec:
    """The crop a ``sensor_msgs/CameraInfo`` describes (:meth:`CropSpec.from_camera_info`), validated
    as an image is: a :class:`~cone_perception.errors.FrameError` (reason ``bad_camera_info``, the
    message naming the field) for a zero or too large image (:data:`MAX_IMAGE_SIDE_PX`), a binning
    other than :data:`ALLOWED_DOWNSCALE`, unequal binning, a roi not inside the image (or not even
    columns, as YUYV needs), a band not divisible by the binning, or a band over :data:`MAX_BAND_PIXELS`."""
    def bad(field: str, what: str) -> FrameError:
        return FrameError("bad_camera_info", f"camera_info {field}: {what}")

    if not (0 < width <= MAX_IMAGE_SIDE_PX and 0 < height <= MAX_IMAGE_SIDE_PX):
        raise bad("width/height", f"{width}x{height} must be 1..{MAX_IMAGE_SIDE_PX} px a side")
    try:
        crop = CropSpec.from_camera_info(width=width, height=height, roi_x=roi_x, roi_y=roi_y, roi_w=roi_w,
                                         roi_h=roi_h, binning_x=binning_x, binning_y=binning_y)
    except ValueError as e:
        raise bad("binning_x/y", str(e)) from None
    try:
        crop.validate(width, height, "camera_info")
    except ConfigError as e:
        field = {"downscale": "binning_x/y", "crop.v0/v1": "roi.y_offset/height",
                 "crop.u0/u1": "roi.x_offset/width"}.get(e.field, "roi")
        raise bad(field, e.message) from None
    if crop.out_width * crop.out_height > MAX_BAND_PIXELS:
        raise bad("roi", f"band {crop.out_width}x{crop.out_height} is over {MAX_BAND_PIXELS} px")
    return crop


#: A box's patch for the far strip's verifier (detector/verifier.py): ``SIDE`` px square at the network's input,
#: ``CTX`` x the box's height in the image, at least ``MIN_SIDE`` px (a box of 6 px is judged with 12 px around it).
SIDE = 32
CTX = 2.0
MIN_SIDE = 12.0


def crop_patch(img: np.ndarray, box, jitter: np.random.Generator | None = None) -> np.ndarray:
    """The ``SIDE`` x ``SIDE`` BGR patch around ``box`` (u1, v1, u2, v2 in ``img`` px): a square ``CTX`` x the
    box's height wide (at least ``MIN_SIDE``) centred on the box, the image's edge rows repeated beyond it.
    ``jitter`` (training): the centre moved and the side scaled a little at random. Bilinear (``warpAffine`` has no
    area filter), the same in training and on the car."""
    u1, v1, u2, v2 = (float(x) for x in box)
    h = max(v2 - v1, 1.0)
    cx, cy = (u1 + u2) / 2.0, (v1 + v2) / 2.0
    s = max(CTX * h, MIN_SIDE)
    if jitter is not None:
        cx += float(jitter.normal(0.0, 0.08)) * h
        cy += float(jitter.normal(0.0, 0.08)) * h
        s *= float(np.exp(jitter.normal(0.0, 0.1)))
    k = SIDE / s
    m = np.array([[k, 0.0, SIDE / 2.0 - cx * k], [0.0, k, SIDE / 2.0 - cy * k]], np.float32)
    return cv2.warpAffine(img, m, (SIDE, SIDE), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
