"""Ground truth for ``eval``: YOLO label folders or synthetic ``gt.jsonl``, paired with predictions.

Two formats:

* YOLO label folder ``DIR``: ``images/`` + ``labels/`` (flat, or one sub-folder per split such as
  ``images/val`` + ``labels/val``) and class names in ``data.yaml`` / ``classes.txt`` (or given),
  mapped to project ids by name. Labels are normalised, so boxes take the size of the image
  given in the prediction line. No cone positions.
* ``gt.jsonl`` written by ``cone-perception synth``: one line per image with ``image``, ``width``,
  ``height`` and ``cones`` (``class_id``, ``x_m``, ``y_m`` in ``rear_axle`` m, ``box`` full-image
  px, ``visible_fraction``). It lists every cone with a visible pixel; cones the YOLO labels leave
  out (box < :data:`LABEL_MIN_BOX_PX` or visible fraction < :data:`LABEL_MIN_VISIBLE`, the
  synthetic labelling rule) become *ignore* boxes.

Predictions are matched to ground-truth images by name: the exact name, the end of the path,
the file name, or the stem. Every mismatch is an error naming the file and line.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..classes import NUM_CLASSES
from ..crop import MIN_VISIBLE
from ..data.datasets import IMAGE_SUFFIXES, load_entry
from ..data.predictions import ImagePrediction, iter_json_lines
from ..errors import ConfigError
from ..records import boxes_to_arrays
from .metrics import box_iou

#: The synthetic labelling rule (``synth`` writes YOLO labels only for cones passing it).
LABEL_MIN_BOX_PX = 4.0
LABEL_MIN_VISIBLE = 0.3
MAX_LISTED = 5


@dataclass
class GroundTruthImage:
    """One image's ground truth. Boxes are normalised (0..1) when ``width`` is None."""

    image: str  # name as in the source: path relative to the folder, or as in gt.jsonl
    width: int | None
    height: int | None
    boxes: np.ndarray  # (M, 4) float64 x1 y1 x2 y2, image px (or 0..1 when width is None)
    class_ids: np.ndarray  # (M,) int64 project ids
    ignore: np.ndarray  # (M,) bool
    xy_m: np.ndarray | None = None  # (M, 2) float64 rear_axle m, None without positions
    where: str = ""  # file (and line) it came from
    path: str | None = None  # the image file, where known (pictures in the report)
    bag_frame: tuple[str, int] | None = None  # (rosbag folder, header stamp ns): a bag's frame (pictures)


@dataclass
class GroundTruth:
    source: str
    kind: str  # "yolo" or "jsonl"
    images: list[GroundTruthImage]
    calib_path: Path | None = None  # a calibration found beside the ground truth
    info: dict = field(default_factory=dict)  # counts worth reporting (label problems, ...)

    @property
    def has_positions(self) -> bool:
        return self.kind == "jsonl"


@dataclass
class EvalImage:
    """Ground truth and prediction of one image, both in the prediction's image px."""

    image: str
    width: int
    height: int
    gt_boxes: np.ndarray  # (M, 4) float64 px
    gt_classes: np.ndarray  # (M,) int64
    gt_ignore: np.ndarray  # (M,) bool
    gt_xy_m: np.ndarray | None  # (M, 2) rear_axle m
    pred_boxes: np.ndarray  # (K, 4) float64 px
    pred_scores: np.ndarray  # (K,) float64
    pred_classes: np.ndarray  # (K,) int64
    input_scale: float | None = None  # model input px per image px (from the prediction file)
    path: str | None = None  # the image file, where known
    bag_frame: tuple[str, int] | None = None  # (rosbag folder, header stamp ns) of a bag's frame, where known
    pred_far: np.ndarray | None = None  # (K,) bool: the predictions the far strip drew (the prediction file's ``far``)


def restrict_to_band(images: list[EvalImage], rows: tuple[int, int], min_visible: float = MIN_VISIBLE) -> tuple[list[EvalImage], int]:
    """Score only what a band of image rows ``[v0, v1)`` shows (the car's crop).

    Ground-truth boxes are clipped to the band's rows, as training clips a cone cut by its window;
    a box with less than ``min_visible`` of its height inside becomes an ignore region (no miss, and a
    detection on it is not false). ``rows`` are px of the prediction's image. Returns the new images
    and how many boxes became ignore regions.
    """
    v0, v1 = float(rows[0]), float(rows[1])
    if not 0 <= v0 < v1:
        raise ValueError(f"band rows must satisfy 0 <= v0 < v1, got {rows}")
    out, n_out = [], 0
    for im in images:
        b = np.array(im.gt_boxes, np.float64).reshape(-1, 4)
        h0 = np.maximum(b[:, 3] - b[:, 1], 1e-9)
        c = b.copy()
        c[:, 1] = c[:, 1].clip(v0, v1)
        c[:, 3] = c[:, 3].clip(v0, v1)
        outside = (c[:, 3] - c[:, 1]) < min_visible * h0
        n_out += int((outside & ~im.gt_ignore).sum())
        out.append(replace(im, gt_boxes=np.where(outside[:, None], b, c), gt_ignore=im.gt_ignore | outside))
    return out, n_out


def restrict_to_min_height(images: list[EvalImage], min_height: float, iou: float = 0.5) -> tuple[list[EvalImage], int, int]:
    """Score only cones at least ``min_height`` px tall at the model input (image px x ``input_scale``;
    image px where the prediction file has no scale), the way COCO scores an area range.

    Shorter ground-truth boxes become ignore regions; a shorter detection is dropped unless it overlaps
    (IoU >= ``iou``) a kept box of its class, so a cone of 12.5 px found as 11.5 px still counts.
    Returns the new images, the boxes made ignore regions and the detections dropped.
    """
    if not min_height > 0:
        raise ValueError(f"min_height must be > 0 px, got {min_height}")
    out, n_gt, n_pred = [], 0, 0
    for im in images:
        s = im.input_scale or 1.0
        small_gt = (im.gt_boxes[:, 3] - im.gt_boxes[:, 1]) * s < min_height
        ign = im.gt_ignore | small_gt
        n_gt += int((small_gt & ~im.gt_ignore).sum())
        small_pred = (im.pred_boxes[:, 3] - im.pred_boxes[:, 1]) * s < min_height
        keep = ~small_pred
        if small_pred.any() and (~ign).any():
            ious = box_iou(im.pred_boxes[small_pred], im.gt_boxes[~ign])
            same = im.pred_classes[small_pred][:, None] == im.gt_classes[~ign][None, :]
            keep[np.flatnonzero(small_pred)] = np.any((ious >= iou) & same, axis=1)
        n_pred += int((~keep).sum())
        out.append(replace(im, gt_ignore=ign, pred_boxes=im.pred_boxes[keep], pred_scores=im.pred_scores[keep],
                           pred_classes=im.pred_classes[keep],
                           pred_far=im.pred_far[keep] if im.pred_far is not None else None))
    return out, n_gt, n_pred


def restrict_to_range(images: list[EvalImage], max_range_m: float) -> tuple[list[EvalImage], int]:
    """Score only cones within ``max_range_m`` of the rear axle (their true positions, ``gt_xy_m``): farther ones
    become ignore regions (no miss, and a detection on one is not false), as the drives score cones within the
    design range of the far strip (issue 26: 40 m). Returns the new images and how many boxes became ignore
    regions; ValueError when an image's ground truth has no cone positions (YOLO labels)."""
    if not (math.isfinite(max_range_m) and max_range_m > 0):
        raise ValueError(f"needs a range > 0 m, got {max_range_m}")
    out, n_far = [], 0
    for im in images:
        if im.gt_xy_m is None:
            raise ValueError(f"the ground truth of {im.image} has no cone positions (a gt.jsonl of `synth` has them)")
        far = np.hypot(im.gt_xy_m[:, 0], im.gt_xy_m[:, 1]) > max_range_m
        n_far += int((far & ~im.gt_ignore).sum())
        out.append(replace(im, gt_ignore=im.gt_ignore | far))
    return out, n_far


def restrict(images: list[EvalImage], band: tuple[int, int] | None = None, min_height: float | None = None,
             max_range: float | None = None, iou: float = 0.5, gt_source: str = "eval") -> tuple[list[EvalImage], dict]:
    """``eval --band``, ``--min-height`` and ``--max-range`` in turn (each None: not applied): the images and what
    each set aside; ConfigError naming the option for a value it refuses."""
    counts: dict = {}
    if band is not None:
        images, n_out = restrict_to_band(images, band)
        counts.update(band_rows=list(band), ignored_outside_band=n_out)
    if min_height is not None:
        try:
            images, n_gt, n_pred = restrict_to_min_height(images, min_height, iou)
        except ValueError as e:
            raise ConfigError("eval", "--min-height", str(e)) from None
        counts.update(min_height_px=min_height, ignored_below_min_height=n_gt, detections_dropped_below_min_height=n_pred)
    if max_range is not None:
        try:
            images, n_far = restrict_to_range(images, max_range)
        except ValueError as e:
            raise ConfigError(gt_source, "--max-range", str(e)) from None
        counts.update(max_range_m=max_range, ignored_beyond_max_range=n_far)
    return images, counts


def load_ground_truth(path: str | os.PathLike, names: list[str] | None = None) -> GroundTruth:
    """A YOLO label folder or a ``gt.jsonl``; ``names`` overrides the folder's class names."""
    path = Path(path)
    if not path.exists():
        raise ConfigError(str(path), None, "ground truth not found: give a YOLO folder (images/, labels/, data.yaml) or a gt.jsonl")
    if path.is_dir():
        return _load_yolo(path, names)
    return _load_jsonl(path)


def _beside(path: Path, *candidates: str) -> Path | None:
    for c in candidates:
        p = path / c if path.is_dir() else path.parent / c
        if p.is_file():
            return p
    return None


def _load_yolo(root: Path, names: list[str] | None) -> GroundTruth:
    images_dir = root / "images"
    if not images_dir.is_dir() or not (root / "labels").is_dir():
        raise ConfigError(str(root), None, "a YOLO ground-truth folder needs images/ and labels/ sub-folders")
    has_names = names or any((root / f).is_file() for f in ("data.yaml", "dataset.yaml", "classes.txt"))
    if not has_names:
        raise ConfigError(str(root), "names", "no data.yaml / classes.txt with class names: add one or pass --gt-names")

    direct = any(p.suffix.lower() in IMAGE_SUFFIXES for p in images_dir.iterdir())
    subdirs = [""] if direct else sorted(p.name for p in images_dir.iterdir() if p.is_dir())
    entries = []
    for sub in subdirs:
        e = {"path": ".", "images": f"images/{sub}".rstrip("/"), "labels": f"labels/{sub}".rstrip("/")}
        if names:
            e["names"] = list(names)
        if sub and not (root / e["labels"]).is_dir():
            continue
        entries.append(load_entry(e, root, str(root), f"images/{sub}".rstrip("/")))
    if not entries:
        raise ConfigError(str(root / "images"), None, "no images (directly or in split sub-folders with labels/ beside)")
    out, info = [], {"label_problems": 0, "images_without_labels": 0, "labels_without_image": 0}
    for ent in entries:
        info["label_problems"] += ent.stats["bad_label_lines"]
        info["images_without_labels"] += ent.stats["images_without_labels"]
        info["labels_without_image"] += ent.stats["labels_without_image"]
        for img, lab in zip(ent.image_paths, ent.labels):
            c, cx, cy, w, h = (lab[:, k].astype(np.float64) for k in range(5))
            boxes = np.c_[cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2].clip(0.0, 1.0).reshape(-1, 4)
            rel = img.relative_to(root).as_posix()
            out.append(GroundTruthImage(rel, None, None, boxes, c.astype(np.int64), np.zeros(len(c), bool),
                                        None, str(ent.labels_dir / f"{img.stem}.txt"), str(img)))
    return GroundTruth(str(root), "yolo", out, _beside(root, "calib.yaml"), info)


def _load_jsonl(path: Path) -> GroundTruth:
    src = str(path)
    out = []
    bag_dir = path.parent / path.name[: -len("_gt.jsonl")] if path.name.endswith("_gt.jsonl") else None
    if bag_dir is not None and not (bag_dir / "metadata.yaml").is_file():
        bag_dir = None
    for i, d in iter_json_lines(path, {"image", "width", "height", "cones"}):
        where = f"line {i}"
        if not isinstance(d["cones"], list):
            raise ConfigError(src, f"{where}: cones", "must be a list of cones (a gt.jsonl of cone-perception synth)")
        W, H = d["width"], d["height"]
        rows = []
        for k, c in enumerate(d["cones"]):
            try:
                cid = c["class_id"]
                row = [float(v) for v in c["box"]] + [float(c["x_m"]), float(c["y_m"]), float(c.get("visible_fraction", 1.0))]
            except (KeyError, TypeError, ValueError):
                raise ConfigError(src, f"{where}: cones[{k}]", "needs class_id, box [u1, v1, u2, v2], x_m, y_m (numbers)") from None
            if not isinstance(cid, int) or not 0 <= cid < NUM_CLASSES:
                raise ConfigError(src, f"{where}: cones[{k}].class_id", f"must be an integer 0..{NUM_CLASSES - 1}, got {cid!r}")
            if len(row) != 7 or not np.all(np.isfinite(row)) or row[2] < row[0] or row[3] < row[1]:
                raise ConfigError(src, f"{where}: cones[{k}]", "box must be 4 finite numbers u1 v1 u2 v2 with u2 >= u1, v2 >= v1")
            rows.append([*row, cid])
        a = np.asarray(rows, np.float64).reshape(-1, 8)
        wh = a[:, 2:4] - a[:, 0:2]
        ignore = (wh[:, 0] < LABEL_MIN_BOX_PX) | (wh[:, 1] < LABEL_MIN_BOX_PX) | (a[:, 6] < LABEL_MIN_VISIBLE)
        if "stamp_ns" in d and bag_dir is not None:  # a frame of a bag (synth bag writes <bag>_gt.jsonl)
            img_path, bag_frame = None, (str(bag_dir), int(d["stamp_ns"]))
        else:
            img_path, bag_frame = str(path.parent / str(d["image"])), None
        out.append(GroundTruthImage(str(d["image"]), W, H, a[:, :4], a[:, 7].astype(np.int64), ignore, a[:, 4:6], f"{src}: {where}",
                                    img_path, bag_frame))
    if not out:
        raise ConfigError(src, None, "no ground-truth lines")
    stem = path.name[: -len("gt.jsonl")] if path.name.endswith("gt.jsonl") else ""
    calib = _beside(path, f"{stem}calib.yaml", "calib.yaml")
    return GroundTruth(src, "jsonl", out, calib, {"ignored_boxes": int(sum(g.ignore.sum() for g in out))})


def _name_index(gt: GroundTruth) -> dict[str, list[int]]:
    """Every name a prediction may use for a ground-truth image -> image indices."""
    index: dict[str, list[int]] = {}
    for k, g in enumerate(gt.images):
        p = Path(g.image)
        parts = p.parts
        keys = {g.image, p.name, p.stem} | {Path(*parts[i:]).as_posix() for i in range(len(parts))}
        for key in keys:
            index.setdefault(key, []).append(k)
    return index


def _lookup(index: dict[str, list[int]], name: str) -> list[int]:
    p = Path(name)
    for key in (name, p.as_posix(), *(Path(*p.parts[i:]).as_posix() for i in range(1, len(p.parts))), p.stem):
        hits = index.get(key)
        if hits:
            return sorted(set(hits))
    return []


def pair_with_predictions(gt: GroundTruth, preds: list[ImagePrediction], pred_source: str, only_predicted: bool = False) -> tuple[list[EvalImage], dict]:
    """Pair each prediction line with its ground-truth image; boxes end in the prediction's image px.

    Raises :class:`ConfigError` for a prediction of an image not in the ground truth, an ambiguous
    name, an image predicted twice, and (unless ``only_predicted``) ground-truth images without a
    prediction line. Returns the pairs and counts (``gt_images_not_predicted``, ``size_mismatch``).
    """
    if not preds:
        raise ConfigError(pred_source, None, "no prediction lines")
    index = _name_index(gt)
    seen: dict[int, int] = {}
    out, resized = [], 0
    for p in preds:
        hits = _lookup(index, p.image)
        where = f"line {p.line}"
        if not hits:
            raise ConfigError(pred_source, where, f"image {p.image!r} is not in the ground truth {gt.source}")
        if len(hits) > 1:
            cands = ", ".join(gt.images[k].image for k in hits[:MAX_LISTED])
            raise ConfigError(pred_source, where, f"image {p.image!r} matches several ground-truth images ({cands}): use the path")
        k = hits[0]
        if k in seen:
            raise ConfigError(pred_source, where, f"image {p.image!r} was already predicted on line {seen[k]}")
        seen[k] = p.line
        g = gt.images[k]
        if g.width is None:
            sx, sy = float(p.width), float(p.height)
        else:
            sx, sy = p.width / g.width, p.height / g.height
            resized += int((g.width, g.height) != (p.width, p.height))
        b, s, c = boxes_to_arrays(p.boxes)
        out.append(EvalImage(p.image, p.width, p.height, g.boxes * np.array([sx, sy, sx, sy]), g.class_ids, g.ignore,
                             g.xy_m, b.astype(np.float64), s.astype(np.float64), c, p.input_scale, g.path, g.bag_frame,
                             p.far))
    missing = [g.image for k, g in enumerate(gt.images) if k not in seen]
    if missing and not only_predicted:
        raise ConfigError(pred_source, None, f"has no line for {len(missing)} of {len(gt.images)} ground-truth images of {gt.source} "
                          f"(e.g. {', '.join(missing[:MAX_LISTED])}); pass --only-predicted to evaluate just the predicted ones")
    return out, {"gt_images": len(gt.images), "gt_images_not_predicted": len(missing), "size_mismatch_scaled": resized}
