"""Augmentations that keep cone colours meaningful.

Every function takes a numpy ``rng`` (so a sample is reproducible from its
seed), a BGR uint8 image (h, w, 3), boxes (M, 4) float32 x1 y1 x2 y2 px and
classes (M,) int64, and returns the same three. Colour IS the class: hue moves
by a few degrees only; a horizontal flip keeps each cone's class (a blue cone
stays blue; only the track side changes).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..crop import MIN_VISIBLE

PAD_VALUE = 114


@dataclass(frozen=True)
class AugmentConfig:
    mosaic: float = 0.5  # probability of a 2x2 mosaic
    scale: tuple[float, float] = (0.5, 1.5)  # zoom range (1 = width fits the input)
    hue: float = 0.01  # max hue shift, fraction of the circle (0.01 = 3.6 deg)
    saturation: float = 0.5  # max relative saturation change
    value: float = 0.4  # max relative brightness change
    flip: float = 0.5
    blur: float = 0.05
    noise: float = 0.1
    cutout: float = 0.2
    min_visible: float = MIN_VISIBLE  # keep a clipped box if this fraction of it remains in the frame
    min_size_px: float = 2.0
    copy_paste: float = 0.0  # probability of pasting cones cut from other frames (train/copy_paste.py; 0 = off)

    @classmethod
    def off(cls) -> "AugmentConfig":
        """No augmentation at all (plain width-fit + crop/pad)."""
        return cls(mosaic=0.0, scale=(1.0, 1.0), hue=0.0, saturation=0.0, value=0.0, flip=0.0, blur=0.0, noise=0.0, cutout=0.0,
                   copy_paste=0.0)


def fit_width(img: np.ndarray, boxes: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Resize so the image is ``width`` px wide (aspect kept)."""
    h, w = img.shape[:2]
    if w == width:
        return img, boxes
    r = width / w
    img = cv2.resize(img, (width, max(1, round(h * r))), interpolation=cv2.INTER_AREA if r < 1 else cv2.INTER_LINEAR)
    return img, boxes * np.float32(r)


def _filter_boxes(boxes_t: np.ndarray, cls: np.ndarray, w: int, h: int, min_visible: float, min_size: float):
    """Clip transformed boxes to the (w, h) frame; keep those with enough visible area and size."""
    area0 = (boxes_t[:, 2] - boxes_t[:, 0]) * (boxes_t[:, 3] - boxes_t[:, 1])
    b = boxes_t.copy()
    b[:, 0::2] = b[:, 0::2].clip(0, w)
    b[:, 1::2] = b[:, 1::2].clip(0, h)
    bw, bh = b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]
    keep = (bw >= min_size) & (bh >= min_size) & (bw * bh >= min_visible * np.maximum(area0, 1e-6))
    return b[keep].astype(np.float32), cls[keep]


def random_window(
    rng: np.random.Generator, img: np.ndarray, boxes: np.ndarray, cls: np.ndarray, out_wh: tuple[int, int],
    scale: tuple[float, float], cfg: AugmentConfig, centre: tuple[float, float] | None = None,
):
    """Zoom by a random factor and cut a random ``out_wh`` window (padded grey where the image ends).

    With ``centre`` (px in ``img``) the window is centred near it (mosaic);
    otherwise it is placed uniformly over the zoomed image.
    """
    W, H = out_wh
    s = float(rng.uniform(*scale)) if scale[0] != scale[1] else float(scale[0])
    h, w = img.shape[:2]
    sw, sh = w * s, h * s

    def offset(size: float, out: int, c: float | None) -> float:
        if c is not None:
            return c * s - out / 2 + rng.uniform(-0.25, 0.25) * out
        return rng.uniform(0, size - out) if size >= out else -rng.uniform(0, out - size)

    ox = offset(sw, W, None if centre is None else centre[0])
    oy = offset(sh, H, None if centre is None else centre[1])
    M = np.array([[s, 0, -ox], [0, s, -oy]], np.float32)
    interp = cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR
    out = cv2.warpAffine(img, M, (W, H), flags=interp, borderMode=cv2.BORDER_CONSTANT, borderValue=(PAD_VALUE,) * 3)
    b = boxes * np.float32(s) - np.array([ox, oy, ox, oy], np.float32)
    b, c = _filter_boxes(b, cls, W, H, cfg.min_visible, cfg.min_size_px)
    return out, b, c


def mosaic4(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]], out_wh: tuple[int, int], rng: np.random.Generator):
    """Four (image, boxes, classes) around a random centre on a (2W, 2H) grey canvas -> canvas, boxes, classes, centre."""
    W, H = out_wh
    canvas = np.full((2 * H, 2 * W, 3), PAD_VALUE, np.uint8)
    xc, yc = int(rng.uniform(0.5 * W, 1.5 * W)), int(rng.uniform(0.5 * H, 1.5 * H))
    all_b, all_c = [], []
    for i, (img, b, c) in enumerate(parts):
        h, w = img.shape[:2]
        if i == 0:  # top-left: image's bottom-right at the centre
            x1a, y1a, x2a, y2a = max(xc - w, 0), max(yc - h, 0), xc, yc
            x1b, y1b = w - (x2a - x1a), h - (y2a - y1a)
        elif i == 1:  # top-right
            x1a, y1a, x2a, y2a = xc, max(yc - h, 0), min(xc + w, 2 * W), yc
            x1b, y1b = 0, h - (y2a - y1a)
        elif i == 2:  # bottom-left
            x1a, y1a, x2a, y2a = max(xc - w, 0), yc, xc, min(yc + h, 2 * H)
            x1b, y1b = w - (x2a - x1a), 0
        else:  # bottom-right
            x1a, y1a, x2a, y2a = xc, yc, min(xc + w, 2 * W), min(yc + h, 2 * H)
            x1b, y1b = 0, 0
        canvas[y1a:y2a, x1a:x2a] = img[y1b : y1b + (y2a - y1a), x1b : x1b + (x2a - x1a)]
        dx, dy = x1a - x1b, y1a - y1b
        bb = b + np.array([dx, dy, dx, dy], np.float32)
        # keep only the part of each box inside this image's pasted region
        area0 = (bb[:, 2] - bb[:, 0]) * (bb[:, 3] - bb[:, 1])
        bb[:, 0::2] = bb[:, 0::2].clip(x1a, x2a)
        bb[:, 1::2] = bb[:, 1::2].clip(y1a, y2a)
        vis = (bb[:, 2] - bb[:, 0]) * (bb[:, 3] - bb[:, 1])
        keep = vis >= MIN_VISIBLE * np.maximum(area0, 1e-6)
        all_b.append(bb[keep])
        all_c.append(c[keep])
    return canvas, np.concatenate(all_b).reshape(-1, 4), np.concatenate(all_c), (xc, yc)


def hsv_jitter(rng: np.random.Generator, img: np.ndarray, hue: float, sat: float, val: float) -> np.ndarray:
    """Small hue shift, larger saturation / brightness changes (OpenCV hue is 0..179)."""
    if hue == sat == val == 0:
        return img
    gh, gs, gv = rng.uniform(-1, 1, 3) * np.array([hue, sat, val])
    x = np.arange(256, dtype=np.float32)
    lut_h = ((x + gh * 180) % 180).astype(np.uint8)
    lut_s = np.clip(x * (1 + gs), 0, 255).astype(np.uint8)
    lut_v = np.clip(x * (1 + gv), 0, 255).astype(np.uint8)
    h, s, v = cv2.split(cv2.cvtColor(img, cv2.COLOR_BGR2HSV))
    hsv = cv2.merge((cv2.LUT(h, lut_h), cv2.LUT(s, lut_s), cv2.LUT(v, lut_v)))
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)


def hflip(img: np.ndarray, boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    w = img.shape[1]
    b = boxes.copy()
    b[:, 0], b[:, 2] = w - boxes[:, 2], w - boxes[:, 0]
    return np.ascontiguousarray(img[:, ::-1]), b


def cutout(rng: np.random.Generator, img: np.ndarray, boxes: np.ndarray, cls: np.ndarray, max_covered: float = 0.6):
    """1-3 grey rectangles; boxes covered more than ``max_covered`` are removed from the labels."""
    h, w = img.shape[:2]
    img = img.copy()
    for _ in range(int(rng.integers(1, 4))):
        cw, ch = int(rng.uniform(0.02, 0.15) * w), int(rng.uniform(0.05, 0.3) * h)
        x0, y0 = int(rng.uniform(0, w - cw)), int(rng.uniform(0, h - ch))
        img[y0 : y0 + ch, x0 : x0 + cw] = int(rng.integers(64, 192))
        if len(boxes):
            ix = (np.minimum(boxes[:, 2], x0 + cw) - np.maximum(boxes[:, 0], x0)).clip(0)
            iy = (np.minimum(boxes[:, 3], y0 + ch) - np.maximum(boxes[:, 1], y0)).clip(0)
            area = np.maximum((boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1]), 1e-6)
            keep = ix * iy / area <= max_covered
            boxes, cls = boxes[keep], cls[keep]
    return img, boxes, cls


def photometric(rng: np.random.Generator, img: np.ndarray, cfg: AugmentConfig) -> np.ndarray:
    """HSV jitter, then sometimes blur, sometimes Gaussian noise."""
    img = hsv_jitter(rng, img, cfg.hue, cfg.saturation, cfg.value)
    if cfg.blur and rng.random() < cfg.blur:
        k = int(rng.choice([3, 5]))
        img = cv2.GaussianBlur(img, (k, k), 0)
    if cfg.noise and rng.random() < cfg.noise:
        sigma = rng.uniform(2, 8)
        img = np.clip(img.astype(np.float32) + rng.normal(0, sigma, img.shape).astype(np.float32), 0, 255).astype(np.uint8)
    return img
