"""The detector's preprocessing: an image fitted into the network input (scale to fit, pad right / bottom) and
turned into the (1, 3, H, W) float32 RGB 0..1 blob every backend (and int8 calibration) takes."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

PAD_VALUE = 114


def round_up32(n: int) -> int:
    return int(-(-int(n) // 32) * 32)


def band_input_size(band_wh: tuple[int, int]) -> tuple[int, int]:
    """The network input (W, H) a checkpoint is built for to run a band of ``band_wh`` as it is:
    each side rounded up to a multiple of 32 (the band is padded, never scaled)."""
    return round_up32(band_wh[0]), round_up32(band_wh[1])


@dataclass(frozen=True)
class Letterbox:
    """How an image was fitted into the network input: scale, then pad right / bottom."""

    scale: float
    in_w: int
    in_h: int

    def boxes_to_image(self, boxes_in_px: np.ndarray, image_w: int, image_h: int) -> np.ndarray:
        """(N, 4) boxes in network-input px -> image px, clipped to the image (float32)."""
        b = np.asarray(boxes_in_px, dtype=np.float32).reshape(-1, 4) / np.float32(self.scale)
        b[:, 0::2] = b[:, 0::2].clip(0, image_w)
        b[:, 1::2] = b[:, 1::2].clip(0, image_h)
        return b


def letterbox(img: np.ndarray, in_w: int, in_h: int) -> tuple[np.ndarray, Letterbox]:
    """Fit ``img`` (h, w, 3) into (in_h, in_w, 3): scale to fit, pad right / bottom with grey."""
    h, w = img.shape[:2]
    r = min(in_w / w, in_h / h)
    if abs(r - 1.0) > 1e-9:
        nw, nh = min(in_w, round(w * r)), min(in_h, round(h * r))
        img = cv2.resize(img, (nw, nh), interpolation=cv2.INTER_LINEAR if r > 1 else cv2.INTER_AREA)
    else:
        r = 1.0
    h2, w2 = img.shape[:2]
    if (h2, w2) != (in_h, in_w):
        img = cv2.copyMakeBorder(img, 0, in_h - h2, 0, in_w - w2, cv2.BORDER_CONSTANT, value=(PAD_VALUE,) * 3)
    return img, Letterbox(r, in_w, in_h)


def preprocess(bgr: np.ndarray, in_w: int, in_h: int) -> tuple[np.ndarray, Letterbox]:
    """BGR uint8 image -> the network input: letterboxed to (in_w, in_h), (1, 3, H, W) float32 RGB 0..1.

    The one preprocessing of every backend (and of int8 calibration, :mod:`.quantize`)."""
    img, lb = letterbox(bgr, in_w, in_h)
    return cv2.dnn.blobFromImage(img, 1.0 / 255.0, swapRB=True), lb
