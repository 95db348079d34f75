"""Geometry-aware copy-paste: real cones cut out of training frames, pasted on the road of others.

Cones stand on the ground, so in one camera a cone's box height is linear in the
row of its foot: ``h = a * y2 + b`` (pinhole camera over a flat road; normalised
image units, so the law survives any resize). :func:`fit_row_law` fits it per
frame from the frame's own small cones (per dataset entry where a frame has too
few); :class:`ConeBank` holds cone patches cut from the training frames and
:meth:`ConeBank.paste` puts new cones into a frame at the height the law gives
for the row they stand on:

* where: feet inside the convex hull of the frame's labelled cone feet (the
  track between its cone lines, not the car's own body below them), covering
  at most ``max_overlap`` of a labelled or already pasted box, never outside
  the image;
* how: a soft cone-shaped matte (a feathered trapezoid), so the patch's
  rectangle and background do not show; pasted far to near, and a labelled
  cone nearer than a pasted one stays in front of it (occlusion order);
* what: the class is drawn with ``class_weights`` (large orange and orange
  oversampled: rare in the real frames), a large orange cone is
  ``LARGE_H / SMALL_H`` times the law's (small-cone) height; labels are added.

All randomness comes from the ``rng`` passed in (a sample stays reproducible).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from tqdm import tqdm

from ..classes import BLUE, LARGE_ORANGE, NUM_CLASSES, ORANGE, YELLOW

#: cone heights in metres (FSG rules), the same as the renderer's
SMALL_H, LARGE_H = 0.325, 0.505


@dataclass(frozen=True)
class CopyPasteConfig:
    p: float = 0.0  # probability that a training frame gets pasted cones (0 = off)
    max_cones: int = 4  # up to this many pasted cones per frame (at least 1)
    class_weights: tuple[float, ...] = (1.0, 1.0, 2.0, 3.0, 0.0)  # per project class: blue, yellow, orange, large orange, unknown
    min_height_px: float = 6.0  # no cone smaller than this (fitted px)
    max_upscale: float = 1.5  # a patch is never enlarged more than this
    max_overlap: float = 0.3  # a pasted box may cover at most this fraction of a smaller labelled / pasted one
    hull_margin: float = 0.02  # feet may lie this far (image widths) outside the hull of the labelled feet
    feather: float = 0.08  # matte blur, fraction of the pasted height
    bank_per_class: int = 400  # patches kept per class
    min_source_px: int = 14  # patches only from cones at least this tall in their frame
    patch_height_px: int = 96  # patches are stored at most this tall


@dataclass(frozen=True)
class RowLaw:
    """Box height vs foot row, normalised units: ``h = a * y2 + b`` (a > 0)."""

    a: float
    b: float

    def height(self, y2: np.ndarray | float) -> np.ndarray | float:
        return self.a * np.asarray(y2) + self.b

    def row_for_height(self, h: float) -> float:
        return (h - self.b) / self.a


def fit_row_law(boxes_n: np.ndarray, cls: np.ndarray, min_cones: int = 4, min_spread: float = 0.05) -> RowLaw | None:
    """Least-squares ``h = a * y2 + b`` over the small cones of one frame (or entry).

    ``boxes_n``: (M, 4) x1 y1 x2 y2 in 0..1 image units; large orange cones count with their
    height scaled to a small cone's. None when fewer than ``min_cones`` cones, their foot
    rows span less than ``min_spread``, or the slope is not positive (no ground-plane law).
    Cones cut by the image's bottom edge are left out (their foot is not seen)."""
    boxes_n = np.asarray(boxes_n, np.float64).reshape(-1, 4)
    cls = np.asarray(cls).reshape(-1)
    keep = (boxes_n[:, 3] < 0.995) & np.isin(cls, (BLUE, YELLOW, ORANGE, LARGE_ORANGE))
    y2 = boxes_n[keep, 3]
    h = (boxes_n[keep, 3] - boxes_n[keep, 1]) * np.where(cls[keep] == LARGE_ORANGE, SMALL_H / LARGE_H, 1.0)
    if y2.size < min_cones or np.ptp(y2) < min_spread:
        return None
    a, b = np.polyfit(y2, h, 1)
    if not a > 0:
        return None
    return RowLaw(float(a), float(b))


def cone_matte(w: int, h: int, feather_px: float) -> np.ndarray:
    """(h, w) float32 alpha 0..1: a cone's silhouette (trapezoid, 20 % wide at the top), edges feathered."""
    m = np.zeros((h + 4, w + 4), np.float32)
    top = 0.2 * w
    pts = np.array([[2 + (w - top) / 2, 2], [2 + (w + top) / 2, 2], [2 + w - 0.5, 2 + h - 0.5], [2, 2 + h - 0.5]], np.float32)
    cv2.fillPoly(m, [np.round(pts * 4).astype(np.int32)], 1.0, lineType=cv2.LINE_AA, shift=2)
    if feather_px > 0.3:
        m = cv2.GaussianBlur(m, (0, 0), feather_px)
    return m[2:-2, 2:-2]


def _overlaps(box: np.ndarray, boxes: np.ndarray, frac: float = 0.05) -> bool:
    if boxes.size == 0:
        return False
    ix = np.minimum(box[2], boxes[:, 2]) - np.maximum(box[0], boxes[:, 0])
    iy = np.minimum(box[3], boxes[:, 3]) - np.maximum(box[1], boxes[:, 1])
    inter = np.clip(ix, 0, None) * np.clip(iy, 0, None)
    a0 = (box[2] - box[0]) * (box[3] - box[1])
    a1 = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    return bool(np.any(inter > frac * np.minimum(a0, a1)))


class ConeBank:
    """Cone patches cut from training frames, by class: BGR uint8 (h, w, 3), most ``patch_height_px`` tall."""

    def __init__(self, cfg: CopyPasteConfig):
        self.cfg = cfg
        self.patches: list[list[np.ndarray]] = [[] for _ in range(NUM_CLASSES)]

    def add_frame(self, img: np.ndarray, boxes: np.ndarray, cls: np.ndarray) -> int:
        """Cut the clean cones of one frame (tall enough, not at an image edge, overlapping no other box)."""
        h_img, w_img = img.shape[:2]
        n = 0
        for i, (box, c) in enumerate(zip(np.asarray(boxes, np.float32).reshape(-1, 4), cls)):
            x1, y1, x2, y2 = (int(round(v)) for v in box)
            if y2 - y1 < self.cfg.min_source_px or x2 - x1 < 4 or x1 <= 0 or y1 <= 0 or x2 >= w_img or y2 >= h_img:
                continue
            if _overlaps(box, np.delete(np.asarray(boxes, np.float32).reshape(-1, 4), i, 0), 0.0):
                continue
            patch = img[y1:y2, x1:x2]
            if patch.shape[0] > self.cfg.patch_height_px:
                s = self.cfg.patch_height_px / patch.shape[0]
                patch = cv2.resize(patch, (max(2, round(patch.shape[1] * s)), self.cfg.patch_height_px), interpolation=cv2.INTER_AREA)
            self.patches[int(c)].append(np.ascontiguousarray(patch))
            n += 1
        return n

    def trim(self, rng: np.random.Generator) -> None:
        """Keep at most ``bank_per_class`` patches per class (a random subset)."""
        for c, ps in enumerate(self.patches):
            if len(ps) > self.cfg.bank_per_class:
                keep = rng.choice(len(ps), self.cfg.bank_per_class, replace=False)
                self.patches[c] = [ps[int(k)] for k in sorted(keep)]

    def counts(self) -> list[int]:
        return [len(p) for p in self.patches]

    def paste(
        self, rng: np.random.Generator, img: np.ndarray, boxes: np.ndarray, cls: np.ndarray,
        law: RowLaw | None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Paste 1..``max_cones`` cones into ``img`` (BGR uint8, not changed) standing on the road.

        ``boxes`` (M, 4) float32 px, ``cls`` (M,) int64: the frame's labels; ``law``: its row law
        (None: nothing is pasted). Returns the new image and the labels with the pasted cones
        appended (the frame's own labels first, unchanged)."""
        cfg = self.cfg
        weights = np.array([cfg.class_weights[c] if self.patches[c] else 0.0 for c in range(NUM_CLASSES)])
        if law is None or weights.sum() <= 0:
            return img, boxes, cls
        H, W = img.shape[:2]
        boxes = np.asarray(boxes, np.float32).reshape(-1, 4)
        cls = np.asarray(cls, np.int64).reshape(-1)
        # where cones may stand: inside the convex hull of the labelled cones' feet (the track between
        # its cone lines; not the car's own body below them), where the law gives >= min_height_px
        if len(boxes) < 3:
            return img, boxes, cls
        feet = np.stack([(boxes[:, 0] + boxes[:, 2]) / 2, boxes[:, 3]], 1).astype(np.float32)
        hull = cv2.convexHull(feet)
        margin = cfg.hull_margin * W
        y_lo = max(float(feet[:, 1].min()) - margin, law.row_for_height(cfg.min_height_px / H) * H)
        y_hi = min(float(H), float(feet[:, 1].max()) + margin)
        x_lo, x_hi = max(0.0, float(feet[:, 0].min()) - margin), min(float(W), float(feet[:, 0].max()) + margin)
        if y_lo >= y_hi or x_lo >= x_hi:
            return img, boxes, cls
        planned = []  # (foot y px, box, class, patch)
        taken = boxes.copy()
        for _ in range(int(rng.integers(1, cfg.max_cones + 1))):
            c = int(rng.choice(NUM_CLASSES, p=weights / weights.sum()))
            for _try in range(12):
                fx, fy = float(rng.uniform(x_lo, x_hi)), float(rng.uniform(y_lo, y_hi))
                if cv2.pointPolygonTest(hull, (fx, fy), True) < -margin:
                    continue
                y2n = fy / H
                hn = float(law.height(y2n)) * (LARGE_H / SMALL_H if c == LARGE_ORANGE else 1.0)
                h = hn * H
                if h < cfg.min_height_px or y2n * H - h < 0:
                    continue
                ok = [p for p in self.patches[c] if p.shape[0] * cfg.max_upscale >= h]
                if not ok:
                    continue
                patch = ok[int(rng.integers(len(ok)))]
                w = h * patch.shape[1] / patch.shape[0]
                x1 = fx - w / 2
                box = np.array([x1, y2n * H - h, x1 + w, y2n * H], np.float32)
                box = np.round(box)
                if box[0] < 0 or box[1] < 0 or box[2] > W or box[3] > H or box[2] - box[0] < 2:
                    continue
                if _overlaps(box, taken, cfg.max_overlap):
                    continue
                taken = np.concatenate([taken, box[None]])
                planned.append((box[3], box, c, patch))
                break
        if not planned:
            return img, boxes, cls
        out = img.copy()
        planned.sort(key=lambda t: t[0])  # far (small foot row) first, near last
        for y_foot, box, c, patch in planned:
            x1, y1, x2, y2 = (int(v) for v in box)
            pw, ph = x2 - x1, y2 - y1
            src = cv2.resize(patch, (pw, ph), interpolation=cv2.INTER_AREA if ph < patch.shape[0] else cv2.INTER_LINEAR)
            alpha = cone_matte(pw, ph, cfg.feather * ph)
            # labelled cones nearer than this one stay in front of it
            for ob, oc in zip(boxes, cls):
                if ob[3] > y_foot and ob[0] < x2 and ob[2] > x1 and ob[1] < y2 and ob[3] > y1:
                    m = cone_matte(max(1, int(ob[2] - ob[0])), max(1, int(ob[3] - ob[1])), 0.0)
                    ox, oy = int(ob[0]), int(ob[1])
                    ax1, ay1 = max(x1, ox), max(y1, oy)
                    ax2, ay2 = min(x2, ox + m.shape[1]), min(y2, oy + m.shape[0])
                    if ax2 > ax1 and ay2 > ay1:
                        alpha[ay1 - y1:ay2 - y1, ax1 - x1:ax2 - x1] *= 1 - m[ay1 - oy:ay2 - oy, ax1 - ox:ax2 - ox]
            region = out[y1:y2, x1:x2].astype(np.float32)
            a = alpha[..., None]
            out[y1:y2, x1:x2] = np.clip(region * (1 - a) + src.astype(np.float32) * a, 0, 255).astype(np.uint8)
        new_b = np.stack([p[1] for p in planned]).astype(np.float32)
        new_c = np.array([p[2] for p in planned], np.int64)
        return out, np.concatenate([boxes, new_b]), np.concatenate([cls, new_c])


def build_bank(items, cfg: CopyPasteConfig, seed: int = 0, progress: bool = False) -> ConeBank:
    """A bank from every frame of ``items`` (a loader's ``_Items``: ``len()`` and ``load(k)`` -> BGR, boxes, classes)."""
    bank = ConeBank(cfg)
    for k in tqdm(range(len(items)), desc="copy-paste bank", disable=not progress, leave=False):
        img, b, c = items.load(k)
        bank.add_frame(img, b, c)
    bank.trim(np.random.default_rng([seed, 11]))
    return bank
