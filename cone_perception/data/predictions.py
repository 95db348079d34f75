"""Prediction files (JSON lines) written by ``detect`` and read by ``eval``.

One line per image::

    {"image": "<file name or stamp>", "width": W, "height": H,
     "boxes": [[u1, v1, u2, v2, score, class_id], ...], "input_scale": s, "far": [i, ...]}

Boxes are in the image's own pixels; the optional ``input_scale`` is the model input px per image px
(1/downscale for a band, the letterbox ratio otherwise), so box sizes at the model input are known; class ids in
project order; the optional ``far`` lists the indices of the boxes the far strip's network drew (``detect`` with a
far strip writes it, so that ``map --boxes`` reads them through that network's box model, as the node does).
Reading validates every line and names the file and line of anything malformed.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Iterator

import numpy as np

from ..classes import NUM_CLASSES
from ..errors import ConfigError
from ..records import BOX_DTYPE, boxes_from_arrays


@dataclass
class ImagePrediction:
    image: str
    width: int
    height: int
    boxes: np.ndarray  # BOX_DTYPE, image px
    line: int = 0  # line number in the file it was read from (0: not read from a file)
    input_scale: float | None = None  # model input px per image px, if the file says
    far: np.ndarray | None = None  # (N,) bool: the boxes the far strip drew, if the file says


def far_indices(far: np.ndarray | None) -> list[int] | None:
    """The ``far`` key of a prediction line for a (N,) bool mask of the boxes the far strip drew (None: no strip)."""
    return None if far is None else [int(i) for i in np.flatnonzero(far)]


def prediction_line(image: str, width: int, height: int, boxes: np.ndarray, input_scale: float | None = None,
                    far: np.ndarray | None = None) -> str:
    """One JSON line (without newline) for ``BOX_DTYPE`` records; ``far``: which of them the far strip drew."""
    rows = [
        [round(float(b["u1"]), 2), round(float(b["v1"]), 2), round(float(b["u2"]), 2), round(float(b["v2"]), 2),
         round(float(b["score"]), 4), int(b["class_id"])]
        for b in boxes
    ]
    doc = {"image": str(image), "width": int(width), "height": int(height), "boxes": rows}
    if input_scale is not None:
        doc["input_scale"] = round(float(input_scale), 6)
    if far is not None:
        doc["far"] = far_indices(far)
    return json.dumps(doc)


def write_prediction(fh: IO[str], image: str, width: int, height: int, boxes: np.ndarray,
                     input_scale: float | None = None, far: np.ndarray | None = None) -> None:
    fh.write(prediction_line(image, width, height, boxes, input_scale, far) + "\n")


def iter_json_lines(path: str | os.PathLike, keys: set[str]) -> Iterator[tuple[int, dict]]:
    """``(line number, object)`` of each non-empty line of a JSON-lines file with an image size.

    Raises :class:`ConfigError` naming the file and line for a line that is not a JSON object with
    ``keys`` and positive integer ``width`` / ``height``.
    """
    path = Path(path)
    try:
        fh = path.open(encoding="utf-8", errors="replace")  # undecodable bytes fail as "not JSON" with their line
    except OSError as e:
        raise ConfigError(str(path), None, f"cannot read: {e.strerror}") from None
    with fh:
        for i, line in enumerate(fh, 1):
            if not line.strip():
                continue
            where = f"line {i}"
            try:
                d = json.loads(line)
            except json.JSONDecodeError as e:
                raise ConfigError(str(path), where, f"not JSON: {e.msg}") from None
            if not isinstance(d, dict) or not keys <= set(d):
                raise ConfigError(str(path), where, f"needs the keys {', '.join(sorted(keys))}")
            size = (d["width"], d["height"])
            if not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in size):
                raise ConfigError(str(path), where, f"width and height must be positive integers, got {size[0]!r}, {size[1]!r}")
            yield i, d


def read_predictions(path: str | os.PathLike) -> Iterator[ImagePrediction]:
    """Yield the lines of a prediction file; a malformed line raises :class:`ConfigError` with its number."""
    path = Path(path)
    for i, d in iter_json_lines(path, {"image", "width", "height", "boxes"}):
        where = f"line {i}"
        try:
            a = np.asarray(d["boxes"], dtype=np.float64) if d["boxes"] else np.zeros((0, 6))
        except (TypeError, ValueError):
            a = None
        if a is None or a.ndim != 2 or a.shape[1] != 6:
            raise ConfigError(str(path), where, "boxes must be a list of [u1, v1, u2, v2, score, class_id]")
        if not np.all(np.isfinite(a)):
            raise ConfigError(str(path), where, "boxes have non-finite values")
        if np.any((a[:, 5] < 0) | (a[:, 5] >= NUM_CLASSES) | (a[:, 5] != np.round(a[:, 5]))):
            raise ConfigError(str(path), where, f"class_id must be an integer 0..{NUM_CLASSES - 1}")
        if np.any((a[:, 2] < a[:, 0]) | (a[:, 3] < a[:, 1])):
            raise ConfigError(str(path), where, "a box has u2 < u1 or v2 < v1")
        scale = d.get("input_scale")
        if scale is not None and not (isinstance(scale, (int, float)) and not isinstance(scale, bool) and 0 < scale < 1e3):
            raise ConfigError(str(path), where, f"input_scale must be a positive number, got {scale!r}")
        far = _far_mask(d.get("far"), len(a), str(path), where)
        yield ImagePrediction(str(d["image"]), int(d["width"]), int(d["height"]),
                              boxes_from_arrays(a[:, :4], a[:, 4], a[:, 5].astype(np.int64)).astype(BOX_DTYPE), i,
                              float(scale) if scale is not None else None, far)


def _far_mask(far, n: int, path: str, where: str) -> np.ndarray | None:
    """The ``far`` key (indices of the boxes the far strip drew) as a (n,) bool mask; ConfigError for anything else."""
    if far is None:
        return None
    if not isinstance(far, list) or not all(isinstance(i, int) and not isinstance(i, bool) and 0 <= i < n for i in far):
        raise ConfigError(path, where, f"far must be a list of box indices 0..{n - 1}, got {far!r}")
    if len(set(far)) != len(far):
        raise ConfigError(path, where, f"far lists a box twice: {far!r}")
    mask = np.zeros(n, bool)
    mask[far] = True
    return mask
