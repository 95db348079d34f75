"""Far tiles: on the frames between the far strip's (``far_every``), full-resolution windows of the strip only around
the far cones the last frames had, run as one mosaic (issue 26, "the strip only where it is needed").

A far cone moves a few pixels from one frame to the next at 15-40 m, so the last frames' boxes whole in the strip's
rows (``memory``: two frames, so a cone a tile missed once is looked for again) say where to look. Each such box
gets a window of the strip's rows (this frame's, moved with the attitude) and its own columns plus ``margin_px``
each side; windows closer than ``gap_px`` merge. The windows are laid side by side, ``gap_px`` apart on the
letterbox grey, in a mosaic as wide as the smallest of the far model's networks that holds them (built for the
strip's height and every ``TILE_STEP_PX`` columns up to ``far_tiles``, and ``far_tiles`` itself), and one forward
runs on it: the tiles cost what the far cones' columns need. Its boxes go back to their window's place in the full
image; a box crossing into a gap, or within half the margin of a window's inner side (a cone cut by the window,
where the image goes on, may come out as a whole, smaller box short of the side), is dropped, as are the strip's
cut cones at its top and bottom (``farband.drop_cut_boxes``). Windows that do not fit the mosaic:
:meth:`FarTiles.windows` says None and the pipeline runs the whole strip. New far cones are found by the whole
strip, every ``far_every``-th frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..crop import CropSpec
from ..errors import ConfigError
from .detector import Detector
from .farband import drop_cut_boxes

#: Columns each side of a far cone's last box (full-image px): its motion between two frames and the yaw's.
TILE_MARGIN_PX = 64
#: The tiles look around the far cones of this many last frames: one a tile missed once is looked for again.
TILE_MEMORY_FRAMES = 2
#: Grey columns between two windows in the mosaic; windows nearer than this merge.
TILE_GAP_PX = 16
#: The mosaics' widths: every this many columns up to ``far_tiles`` (a network built for each, loaded warm).
TILE_STEP_PX = 256
#: The narrowest mosaic ``far_tiles`` takes (columns).
MIN_WIDTH = 192
#: The mosaic's fill: the letterbox grey the networks were trained with.
FILL = 114


def mosaic_widths(width: int) -> list[int]:
    """The mosaics' widths of ``far_tiles`` ``width``: every :data:`TILE_STEP_PX` columns below it, and itself."""
    return [w for w in range(TILE_STEP_PX, width, TILE_STEP_PX)] + [width]


@dataclass
class FarTiles:
    """The far tiles of one camera: ``detectors``, the far model built for each mosaic width (columns -> a
    detector for that width and the strip's rows, ``Detector.load_for_band``); :attr:`width`: the widest."""

    detectors: dict  # width -> anything with detect(bgr, crop) -> BOX_DTYPE and a timing dict
    margin_px: int = TILE_MARGIN_PX
    gap_px: int = TILE_GAP_PX
    memory: int = TILE_MEMORY_FRAMES  # the tiles look around the boxes of this many last frames

    def __post_init__(self) -> None:
        self.detectors = dict(sorted(self.detectors.items()))
        self.width = max(self.detectors)
        self.detector = self.detectors[self.width]  # the last detect's network (its timing: the frame's far_forward)
        if min(self.detectors) < 2 * self.margin_px + 2:
            raise ValueError(f"far tiles: a mosaic of {min(self.detectors)} px is under one window "
                             f"({2 * self.margin_px + 2} px)")

    @classmethod
    def for_setting(cls, model, width: int, far, far_every: int, source: str = "far_tiles",
                    **detector_kw) -> "FarTiles | None":
        """The far tiles of ``far_tiles`` ``width`` (0: off) for the far band ``far`` (None: off) run every
        frame but each ``far_every``-th, with ``model`` (the far band's) built for its mosaic, warm; ConfigError
        naming ``source`` for a width that is not 0 or a multiple of 32 from 192 up to the strip's width."""
        if not cls.wanted(width, far, far_every, source):
            return None
        dets = {}
        for w in mosaic_widths(width):
            dets[w] = Detector.load_for_band(model, (w, far.crop.height_full_px), **detector_kw)
            dets[w].warmup()
        return cls(dets)

    @staticmethod
    def wanted(width: int, far, far_every: int, source: str = "far_tiles") -> bool:
        """Whether ``far_tiles`` ``width`` runs tiles for the far band ``far`` at ``far_every`` (0, no far band or
        ``far_every`` 1: no); ConfigError naming ``source`` unless 0 or a multiple of 32 from 192 to the strip's width."""
        if width != 0 and (width % 32 or not MIN_WIDTH <= width <= (far.crop.width_full_px if far else 8192)):
            raise ConfigError(source, None, f"must be 0 (off) or a multiple of 32 from {MIN_WIDTH} to the strip's "
                                            f"width{f' {far.crop.width_full_px}' if far else ''}, got {width}")
        return width != 0 and far is not None and far_every > 1

    def windows(self, boxes: np.ndarray, image_width: int) -> list[tuple[int, int]] | None:
        """The columns ``[u0, u1)`` (even, inside the image, left to right) around ``boxes`` (``BOX_DTYPE``,
        full-image px), merged where nearer than ``gap_px``; ``[]`` for no boxes, None when they do not fit
        the mosaic."""
        if len(boxes) == 0:
            return []
        lo = np.clip(np.floor(boxes["u1"] - self.margin_px), 0, image_width).astype(int) // 2 * 2
        hi = np.clip(np.ceil(boxes["u2"] + self.margin_px), 0, image_width).astype(int)
        hi = np.minimum(hi + hi % 2, image_width)
        out: list[list[int]] = []
        for a, b in sorted(zip(lo.tolist(), hi.tolist())):
            if out and a <= out[-1][1] + self.gap_px:
                out[-1][1] = max(out[-1][1], b)
            else:
                out.append([a, b])
        used = sum(b - a for a, b in out) + self.gap_px * (len(out) - 1)
        return [(a, b) for a, b in out] if used <= self.width else None

    def mosaic(self, strip_bgr: np.ndarray, windows: list[tuple[int, int]]) -> tuple[np.ndarray, list[int]]:
        """(the mosaic ``(H, W, 3)``, each window's first column in it) of the full-width strip's windows: W the
        narrowest of the mosaics' widths that holds them."""
        h = strip_bgr.shape[0]
        used = sum(b - a for a, b in windows) + self.gap_px * (len(windows) - 1)
        canvas = np.full((h, next(w for w in self.detectors if w >= used), 3), FILL, np.uint8)
        xs, x = [], 0
        for a, b in windows:
            canvas[:, x:x + b - a] = strip_bgr[:, a:b]
            xs.append(x)
            x += b - a + self.gap_px
        return canvas, xs

    def detect(self, strip_bgr: np.ndarray, crop: CropSpec, windows: list[tuple[int, int]],
               image_width: int) -> np.ndarray:
        """This frame's full-width strip ``strip_bgr`` (cut at ``crop``) -> the boxes of its ``windows`` in
        full-image px (cut cones dropped)."""
        canvas, xs = self.mosaic(strip_bgr, windows)
        self.detector = self.detectors[canvas.shape[1]]
        boxes = self.detector.detect(canvas, CropSpec(crop.v0, crop.v1, 0, canvas.shape[1], 1))
        if len(boxes) == 0:
            return boxes
        keep = np.zeros(len(boxes), bool)
        shift = np.zeros(len(boxes), np.float32)
        for (a, b), x in zip(windows, xs):
            side = self.margin_px // 2  # a cone cut by the side may come out as a whole, smaller box short of it
            left = x + (side if a > 0 else -np.inf)  # a window's side at the image's border cuts nothing
            right = x + (b - a) - (side if b < image_width else -np.inf)
            inside = (boxes["u1"] > left) & (boxes["u2"] < right)
            keep |= inside
            shift[inside] = a - x
        boxes = boxes[keep].copy()
        boxes["u1"] += shift[keep]
        boxes["u2"] += shift[keep]
        return drop_cut_boxes(boxes, crop)


__all__ = ["FILL", "FarTiles", "MIN_WIDTH", "TILE_MEMORY_FRAMES", "TILE_GAP_PX", "TILE_MARGIN_PX", "TILE_STEP_PX", "mosaic_widths"]
