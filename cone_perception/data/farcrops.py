"""Training crops for the far strip: windows around small cones, cut at the frames' native scale.

The far strip (``detector/farband.py``) runs a model on full-resolution rows near the horizon,
where cones 15-40 m ahead are 8-21 px tall. The trainer fits every image to the input width
(``train/augment.py``, ``fit_width``), so a 1920x1080 frame trained at a 960-px input is halved
and its far cones shrink below what the strip shows. ``far_crops`` cuts windows of ``W x H`` px
(no resize) around cones of ``min_height..max_height`` px from the images of one split of a data
YAML, with their labels, into a YOLO dataset the trainer reads at the strip's scale:

* each labelled cone in the height range is a candidate centre; up to ``per_image`` of them per
  image are drawn at random (a crop that already holds a drawn cone is not cut twice);
* the window is placed at random so the cone lies inside it; frames narrower or lower than the
  window give their whole width or height;
* labels: boxes clipped to the window; a box kept when at least ``MIN_VISIBLE`` of its area and
  2 px of its width and height remain (as the trainer's own window does);
* images are read as the trainer reads them (``restore_aspect`` of the YAML entry applied), so the
  real bgracing frames come out at their 640x360 source scale and the rendered ones at 1920x1080.

Images with no cone in the range are counted and give no crop.

Hard negatives (``around``): the windows are cut around a model's *false* detections instead, read from a
``detect`` prediction file of the same images: its boxes of ``min_height..max_height`` px at score >= ``around_conf``
that overlap no labelled cone (IoU < :data:`FALSE_IOU`, any class) and whose centre lies in no cone's box. A
rendered set (``synth dataset``: a ``gt.jsonl`` beside ``images/``) lists every cone with a visible pixel, also
those its labels leave out (too small, mostly hidden): a detection on one of those is no false one, and a window
around it would teach the model to miss real cones. The windows keep every label they show, so the model learns
the look it took for a cone (e.g. worn yellow paint, ``synth --paint-lines yellow``) as background beside the
cones it must still find.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml
from tqdm import tqdm

from ..classes import CLASS_NAMES
from ..crop import MIN_VISIBLE
from ..errors import ConfigError
from ..mapping import box_iou
from ..records import boxes_from_arrays
from .datasets import labels_to_xyxy, load_data_yaml, read_image
from .predictions import read_predictions

#: Box-height bins (px at the crop's scale) of the report.
HEIGHT_BINS = (0, 8, 12, 24, 48)
#: Hard negatives: a detection overlapping every labelled cone less than this (IoU) is a false one.
FALSE_IOU = 0.3


@dataclass
class FarCropReport:
    images: int = 0  # images read
    without_candidate: int = 0  # images with no cone in the height range (no crop)
    crops: int = 0
    boxes: int = 0
    by_height: dict = field(default_factory=dict)  # "0-8" -> boxes in the crops

    def line(self) -> str:
        bins = ", ".join(f"{k} px: {v}" for k, v in self.by_height.items())
        return (f"{self.crops} crops with {self.boxes} boxes ({bins}) from {self.images} images; "
                f"{self.without_candidate} images without a cone in the height range")


def _bin_name(i: int) -> str:
    lo = HEIGHT_BINS[i]
    return f"{lo}-{HEIGHT_BINS[i + 1]}" if i + 1 < len(HEIGHT_BINS) else f">={lo}"


def window_around(box: np.ndarray, img_wh: tuple[int, int], win_wh: tuple[int, int],
                  rng: np.random.Generator) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) of a window of ``win_wh`` (shrunk to the image) holding ``box`` (x1 y1 x2 y2), at random."""
    w, h = img_wh
    cw, ch = min(win_wh[0], w), min(win_wh[1], h)

    def start(lo_edge: float, hi_edge: float, size: int, total: int) -> int:
        lo = int(np.ceil(hi_edge)) - size  # the window's start that still holds the box's far edge
        hi = int(np.floor(lo_edge))  # ... and its near edge
        lo, hi = max(0, lo), min(total - size, hi)
        if lo > hi:  # box larger than the window: centre it
            return int(np.clip(round((lo_edge + hi_edge - size) / 2), 0, total - size))
        return int(rng.integers(lo, hi + 1))

    x0 = start(float(box[0]), float(box[2]), cw, w)
    y0 = start(float(box[1]), float(box[3]), ch, h)
    return x0, y0, x0 + cw, y0 + ch


def boxes_in_window(boxes: np.ndarray, cls: np.ndarray, win: tuple[int, int, int, int],
                    min_visible: float = MIN_VISIBLE, min_px: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (x1 y1 x2 y2, image px) -> those the window shows, clipped and in window px."""
    x0, y0, x1, y1 = win
    b = boxes.astype(np.float32).copy()
    area0 = np.maximum((b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1]), 1e-6)
    b[:, 0::2] = b[:, 0::2].clip(x0, x1) - x0
    b[:, 1::2] = b[:, 1::2].clip(y0, y1) - y0
    bw, bh = b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]
    keep = (bw >= min_px) & (bh >= min_px) & (bw * bh >= min_visible * area0)
    return b[keep], cls[keep]


def on_no_cone(pred_boxes: np.ndarray, boxes: np.ndarray, unlabelled: np.ndarray | None = None) -> np.ndarray:
    """(K,) bool: which predictions (:data:`~cone_perception.records.BOX_DTYPE`) overlap no labelled box of ``boxes``
    (x1 y1 x2 y2) at IoU >= :data:`FALSE_IOU` and have their centre in none of ``boxes`` and ``unlabelled`` (cones
    without a label, x1 y1 x2 y2)."""
    p = pred_boxes
    cones = boxes if unlabelled is None else np.r_[boxes.reshape(-1, 4), unlabelled.reshape(-1, 4)]
    if len(p) == 0 or len(cones) == 0:
        return np.ones(len(p), bool)
    xyxy = np.c_[p["u1"], p["v1"], p["u2"], p["v2"]].astype(np.float32).reshape(-1, 4)
    cu, cv = (xyxy[:, 0] + xyxy[:, 2]) / 2, (xyxy[:, 1] + xyxy[:, 3]) / 2
    inside = ((cones[None, :, 0] <= cu[:, None]) & (cu[:, None] <= cones[None, :, 2])
              & (cones[None, :, 1] <= cv[:, None]) & (cv[:, None] <= cones[None, :, 3])).any(axis=1)
    false = ~inside
    if len(boxes):
        labels = boxes_from_arrays(boxes, np.ones(len(boxes)), np.zeros(len(boxes), np.int64))
        false &= box_iou(p, labels).max(axis=1) < FALSE_IOU
    return false


def false_detections(pred_boxes: np.ndarray, boxes: np.ndarray, conf: float,
                     unlabelled: np.ndarray | None = None) -> np.ndarray:
    """(K, 4) x1 y1 x2 y2 of the predictions at score >= ``conf`` on no cone (:func:`on_no_cone`)."""
    p = pred_boxes[pred_boxes["score"] >= conf]
    xyxy = np.c_[p["u1"], p["v1"], p["u2"], p["v2"]].astype(np.float32).reshape(-1, 4)
    return xyxy[on_no_cone(p, boxes, unlabelled)]


def _predictions_by_name(path: str | Path) -> dict[str, np.ndarray]:
    """A ``detect`` prediction file: image file name -> its boxes (the last line of a name wins)."""
    return {Path(d.image).name: d.boxes for d in read_predictions(path)}


def _rendered_cones(images_dir: Path) -> dict[str, np.ndarray]:
    """Every cone's box per image file name from the ``gt.jsonl`` of a rendered set (``synth dataset``: beside
    ``images/``, which holds ``images_dir``); empty where there is none."""
    for root in (images_dir.parent, images_dir.parent.parent):
        gt = root / "gt.jsonl"
        if gt.is_file():
            out = {}
            for line in gt.read_text(encoding="utf-8").splitlines():
                d = json.loads(line) if line.strip() else None
                if d and isinstance(d.get("cones"), list):
                    out[Path(d["image"]).name] = np.asarray([c["box"] for c in d["cones"]], np.float32).reshape(-1, 4)
            return out
    return {}


def far_crops(data_yaml: str | Path, out: str | Path, split: str = "train", size: tuple[int, int] = (960, 128),
              min_height: float = 4.0, max_height: float = 24.0, per_image: int = 2, seed: int = 0,
              progress: bool = True, around: str | Path | None = None, around_conf: float = 0.25) -> FarCropReport:
    """Cut the far-strip crops of ``split`` (train or val) of ``data_yaml`` into the YOLO dataset ``out``
    (``images/``, ``labels/``, ``data.yaml`` with the project's class names, ``train: images``); with ``around`` (a
    prediction file of these images), around its false detections instead of around cones (module doc)."""
    if split not in ("train", "val"):
        raise ConfigError("--split", None, f"must be train or val, got {split!r}")
    if size[0] < 32 or size[1] < 32:
        raise ConfigError("--size", None, f"crops need at least 32x32 px, got {size[0]}x{size[1]}")
    if not 0 <= min_height < max_height:
        raise ConfigError("--min-height", None, f"needs 0 <= min-height < max-height, got {min_height}, {max_height}")
    if per_image < 1:
        raise ConfigError("--per-image", None, f"must be at least 1, got {per_image}")
    if around is not None and not 0.0 <= around_conf <= 1.0:
        raise ConfigError("--around-conf", None, f"must be a score in 0..1, got {around_conf}")
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ConfigError(str(out), None, "output must be a new or empty folder")
    preds = _predictions_by_name(around) if around is not None else None
    train, val, _ = load_data_yaml(data_yaml)
    entries = train if split == "train" else val
    if not entries:
        raise ConfigError(str(data_yaml), split, f"no {split} split in this data YAML")
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "labels").mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    rep = FarCropReport(by_height={_bin_name(i): 0 for i in range(len(HEIGHT_BINS))})
    total = sum(len(e.image_paths) for e in entries)
    with tqdm(total=total, desc="far-crops", unit="image", disable=not progress) as bar:
        for ei, e in enumerate(entries):
            rendered = _rendered_cones(e.images_dir) if preds is not None else {}
            for path, lab in zip(e.image_paths, e.labels):
                bar.update(1)
                rep.images += 1
                img = read_image(path, e.restore_aspect)
                h, w = img.shape[:2]
                boxes, cls = labels_to_xyxy(lab, w, h)
                centres = boxes
                if preds is not None:
                    found = preds.get(path.name)
                    centres = (false_detections(found, boxes, around_conf, rendered.get(path.name))
                               if found is not None else boxes[:0])
                heights = centres[:, 3] - centres[:, 1]
                cand = np.flatnonzero((heights >= min_height) & (heights <= max_height))
                if cand.size == 0:
                    rep.without_candidate += 1
                    continue
                taken: list[tuple[int, int, int, int]] = []
                for j in rng.permutation(cand):
                    if len(taken) == per_image:
                        break
                    bx = centres[j]
                    if any(x0 <= bx[0] and bx[2] <= x1 and y0 <= bx[1] and bx[3] <= y1 for x0, y0, x1, y1 in taken):
                        continue
                    win = window_around(bx, (w, h), size, rng)
                    taken.append(win)
                    b, c = boxes_in_window(boxes, cls, win)
                    cw, ch = win[2] - win[0], win[3] - win[1]
                    name = f"{path.stem}_e{ei}f{len(taken) - 1}"
                    cv2.imwrite(str(out / "images" / f"{name}.jpg"), img[win[1]:win[3], win[0]:win[2]],
                                [cv2.IMWRITE_JPEG_QUALITY, 95])
                    lines = [f"{int(k)} {(q[0] + q[2]) / 2 / cw:.6f} {(q[1] + q[3]) / 2 / ch:.6f} "
                             f"{(q[2] - q[0]) / cw:.6f} {(q[3] - q[1]) / ch:.6f}\n" for q, k in zip(b, c)]
                    (out / "labels" / f"{name}.txt").write_text("".join(lines), encoding="utf-8")
                    rep.crops += 1
                    rep.boxes += len(b)
                    idx = np.searchsorted(HEIGHT_BINS, b[:, 3] - b[:, 1], side="right") - 1
                    for i in idx:
                        rep.by_height[_bin_name(int(i))] += 1
    what = "cones" if around is None else f"false detections (score >= {around_conf:g}) of {around}"
    (out / "data.yaml").write_text(
        f"# written by cone-perception data far-crops from {data_yaml} ({split} split), windows of "
        f"{size[0]}x{size[1]} px at native scale around {what} {min_height:g}-{max_height:g} px tall\n"
        + yaml.safe_dump({"train": "images", "names": list(CLASS_NAMES)}, sort_keys=False), encoding="utf-8")
    return rep


__all__ = ["FALSE_IOU", "FarCropReport", "HEIGHT_BINS", "boxes_in_window", "false_detections", "far_crops", "on_no_cone",
           "window_around"]
