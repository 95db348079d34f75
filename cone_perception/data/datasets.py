"""Datasets in YOLO txt layout, described by a data YAML, mixed with weights.

Two forms of data YAML are read: an Ultralytics one (``path``, ``train: images/train``,
``val``, ``test``, ``names``; see :mod:`.yolo_yaml`; ``synth dataset`` writes one) and
this package's own, which mixes several datasets. Our own form (paths relative to the YAML file)::

    train:
      - path: /work/shared/datasets/bgracing-real
        images: images            # default "images"; labels default: same with images -> labels
        names: [blue_cone, large_orange_cone, orange_cone, yellow_cone]   # dataset ids -> names
        restore_aspect: [16, 9]   # stored squeezed (e.g. 640x640 from 16:9): resize back first
        clips: [autox3, autox6, skidpad, autox5]   # keep only these clips (file name before '-')
        exclude_clips: []         # or drop these
        weight: 1.0               # samples per epoch = weight x images
      - path: ../synthetic/train  # names may also come from <path>/data.yaml or classes.txt
    val:
      - path: /work/shared/datasets/bgracing-real
        names: [blue_cone, large_orange_cone, orange_cone, yellow_cone]
        restore_aspect: [16, 9]
        clips: [autox4, autox2, accel]

Class names map to project ids with :func:`classes.class_id_from_name`. Bad
label lines are reported with file and line, skipped and counted; label files
without an image are counted; nothing is dropped silently.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml

from ..classes import CLASS_NAMES, class_map_from_names
from ..errors import ConfigError
from .yolo_yaml import is_yolo_style, yolo_entries

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp")
MAX_REPORTED = 10
#: Clips of the real (bgracing) frames held out for validation: never trained or calibrated on.
VALIDATION_CLIPS = ("autox4", "autox2", "accel")


@dataclass
class DatasetEntry:
    """One dataset folder of a data YAML, with its images and labels read."""

    name: str
    images_dir: Path
    labels_dir: Path
    class_map: list[int]
    restore_aspect: tuple[int, int] | None = None
    weight: float = 1.0
    image_paths: list[Path] = field(default_factory=list)
    labels: list[np.ndarray] = field(default_factory=list)  # per image (M, 5): project class, cx, cy, w, h (0..1)
    stats: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return {"name": self.name, "images": len(self.image_paths), "boxes": int(sum(len(l) for l in self.labels)),
                "weight": self.weight, "restore_aspect": list(self.restore_aspect) if self.restore_aspect else None,
                **self.stats}


def clip_of(stem: str) -> str:
    """Clip name of a frame file: the part before the first '-' (``autox3_mp4-12_jpg_ab`` -> ``autox3_mp4``)."""
    return stem.split("-", 1)[0]


def in_clips(stem: str, clips: set[str]) -> bool:
    """Whether a frame belongs to one of ``clips``; ``autox3`` matches clip ``autox3`` and ``autox3_mp4``."""
    c = clip_of(stem)
    return c in clips or c.split("_", 1)[0] in clips


def parse_label_file(path: Path, class_map: list[int], problems: list[str]) -> np.ndarray:
    """Read one YOLO label file -> (M, 5) float32 (project class, cx, cy, w, h); bad lines -> ``problems``."""
    rows = []
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        problems.append(f"{path}: unreadable: {e}")
        return np.zeros((0, 5), np.float32)
    for lineno, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        where = f"{path}:{lineno}"
        if len(parts) != 5:
            problems.append(f"{where}: expected 'class cx cy w h', got {len(parts)} fields: {line.strip()[:60]!r}")
            continue
        try:
            c = int(parts[0])
            cx, cy, w, h = (float(v) for v in parts[1:])
        except ValueError:
            problems.append(f"{where}: not numbers: {line.strip()[:60]!r}")
            continue
        if not 0 <= c < len(class_map):
            problems.append(f"{where}: class {c} outside 0..{len(class_map) - 1}")
            continue
        if not (w > 0 and h > 0 and all(np.isfinite([cx, cy, w, h])) and -0.01 <= cx <= 1.01 and -0.01 <= cy <= 1.01):
            problems.append(f"{where}: box out of range (cx cy in 0..1, w h > 0): {line.strip()[:60]!r}")
            continue
        rows.append((class_map[c], cx, cy, min(w, 1.0), min(h, 1.0)))
    return np.asarray(rows, np.float32).reshape(-1, 5)


def _names_for(entry: dict, root: Path, source: str, idx: str) -> list[str]:
    if "names" in entry:
        names = entry["names"]
    else:
        names = None
        for cand in ("data.yaml", "dataset.yaml"):
            f = root / cand
            if f.is_file():
                names = (yaml.safe_load(f.read_text()) or {}).get("names")
                break
        if names is None and (root / "classes.txt").is_file():
            names = [l.strip() for l in (root / "classes.txt").read_text().splitlines() if l.strip()]
    if isinstance(names, dict):
        names = [names[k] for k in sorted(names, key=int)]
    if not isinstance(names, list) or not names:
        raise ConfigError(source, f"{idx}.names", "class names missing: give names: [...] or put data.yaml / classes.txt in the folder")
    return [str(n) for n in names]


def load_entry(entry: dict, base_dir: Path, source: str, idx: str, allow_empty: bool = False) -> DatasetEntry | None:
    """Read one dataset entry of a data YAML (index its images, parse its labels). A folder without images
    is a :class:`ConfigError`; with ``allow_empty`` (val) a warning and None, unless clips were asked for."""
    if not isinstance(entry, dict) or "path" not in entry:
        raise ConfigError(source, idx, "each dataset needs at least 'path:'")
    unknown = set(entry) - {"path", "images", "labels", "names", "restore_aspect", "clips", "exclude_clips", "weight"}
    if unknown:
        raise ConfigError(source, f"{idx}.{sorted(unknown)[0]}", "unknown key")
    root = (base_dir / str(entry["path"])).expanduser()
    images_dir = root / str(entry.get("images", "images"))
    labels_dir = root / str(entry.get("labels", str(entry.get("images", "images")).replace("images", "labels")))
    if not images_dir.is_dir():
        raise ConfigError(source, f"{idx}.path", f"image folder {images_dir} not found")
    if not labels_dir.is_dir():
        raise ConfigError(source, f"{idx}.labels", f"label folder {labels_dir} not found")
    names = _names_for(entry, root, source, idx)
    class_map = class_map_from_names(names, f"{source}: {idx}")
    ra = entry.get("restore_aspect")
    if ra is not None and not (isinstance(ra, (list, tuple)) and len(ra) == 2 and all(float(v) > 0 for v in ra)):
        raise ConfigError(source, f"{idx}.restore_aspect", f"must be [w, h] like [16, 9], got {ra}")
    weight = float(entry.get("weight", 1.0))
    if weight <= 0:
        raise ConfigError(source, f"{idx}.weight", f"must be > 0, got {weight}")
    clips = set(entry.get("clips") or [])
    exclude = set(entry.get("exclude_clips") or [])

    images = sorted(p for p in images_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if clips:
        images = [p for p in images if in_clips(p.stem, clips)]
    if exclude:
        images = [p for p in images if not in_clips(p.stem, exclude)]
    stems = {p.stem for p in images}
    problems: list[str] = []
    labels, unlabelled = [], 0
    for p in images:
        lf = labels_dir / f"{p.stem}.txt"
        if lf.is_file():
            labels.append(parse_label_file(lf, class_map, problems))
        else:
            unlabelled += 1
            labels.append(np.zeros((0, 5), np.float32))
    all_label_stems = {p.stem for p in labels_dir.glob("*.txt")}
    orphan = sorted(s for s in all_label_stems - {p.stem for p in images_dir.iterdir()}
                    if (not clips or in_clips(s, clips)) and not in_clips(s, exclude))
    for s in orphan:
        problems.append(f"{labels_dir / (s + '.txt')}: no image {s}.* in {images_dir}")
    for msg in problems[:MAX_REPORTED]:
        log.warning("%s", msg)
    if len(problems) > MAX_REPORTED:
        log.warning("%s: %d more label problems not shown", root, len(problems) - MAX_REPORTED)
    if not images and allow_empty and not clips and not exclude:
        log.warning("%s: %s: no images in %s: that split is left out", source, idx, images_dir)
        return None
    if not images:
        raise ConfigError(source, f"{idx}.path", f"no images in {images_dir}" + (f" for clips {sorted(clips)}" if clips else ""))
    del stems
    return DatasetEntry(
        name=str(entry["path"]), images_dir=images_dir, labels_dir=labels_dir, class_map=class_map,
        restore_aspect=(float(ra[0]), float(ra[1])) if ra else None, weight=weight, image_paths=images, labels=labels,
        stats={"bad_label_lines": sum(1 for m in problems if ": no image " not in m),
               "labels_without_image": len(orphan), "images_without_labels": unlabelled,
               "clips": sorted(clips) if clips else None, "exclude_clips": sorted(exclude) if exclude else None},
    )


def load_data_yaml(path: str | Path) -> tuple[list[DatasetEntry], list[DatasetEntry], dict]:
    """Read a data YAML -> (train entries, val entries, the YAML's other keys)."""
    path = Path(path)
    src = str(path)
    if not path.is_file():
        raise ConfigError(src, None, "data YAML not found")
    try:
        doc = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as e:
        raise ConfigError(src, None, f"not valid YAML: {e}") from e
    if not isinstance(doc, dict) or not doc.get("train"):
        raise ConfigError(src, "train", "needs a list of datasets under 'train:' (or an Ultralytics 'train: images/train')")
    if is_yolo_style(doc):
        splits = yolo_entries(doc, path)
        loaded = {k: [load_entry({a: b for a, b in e.items() if a != "_key"}, path.parent, src, e["_key"], k == "val")
                      for e in v] for k, v in splits.items()}
        loaded = {k: [e for e in v if e is not None] for k, v in loaded.items()}
        rest = {k: v for k, v in doc.items() if k not in ("train", "val")}
        if loaded.get("test"):
            rest["test_entries"] = loaded["test"]
        return loaded["train"], loaded.get("val", []), rest
    out = []
    for key in ("train", "val"):
        items = doc.get(key) or []
        if isinstance(items, dict):
            items = [items]
        entries = [load_entry(e, path.parent, src, f"{key}[{i}]", key == "val") for i, e in enumerate(items)]
        out.append([e for e in entries if e is not None])
    rest = {k: v for k, v in doc.items() if k not in ("train", "val")}
    return out[0], out[1], rest


def read_image(path: Path, restore_aspect: tuple[float, float] | None) -> np.ndarray:
    """BGR uint8 image, resized back to ``restore_aspect`` (w:h, keeping the width) when given."""
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise OSError(f"cannot read image {path}")
    if restore_aspect:
        h, w = img.shape[:2]
        new_h = int(round(w * restore_aspect[1] / restore_aspect[0]))
        if new_h != h:
            img = cv2.resize(img, (w, new_h), interpolation=cv2.INTER_AREA if new_h < h else cv2.INTER_LINEAR)
    return img


def labels_to_xyxy(labels: np.ndarray, w: int, h: int) -> tuple[np.ndarray, np.ndarray]:
    """(M, 5) normalised labels -> ((M, 4) float32 x1 y1 x2 y2 px, (M,) int64 classes)."""
    c = labels[:, 0].astype(np.int64)
    cx, cy, bw, bh = labels[:, 1] * w, labels[:, 2] * h, labels[:, 3] * w, labels[:, 4] * h
    boxes = np.stack([cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2], 1).astype(np.float32)
    boxes[:, 0::2] = boxes[:, 0::2].clip(0, w)
    boxes[:, 1::2] = boxes[:, 1::2].clip(0, h)
    return boxes.reshape(-1, 4), c


def split_counts(entries: list[DatasetEntry]) -> dict:
    """Images, background images (no box) and boxes per project class of a split's entries."""
    per_class = np.zeros(len(CLASS_NAMES), np.int64)
    background = 0
    for e in entries:
        for lab in e.labels:
            if len(lab) == 0:
                background += 1
            per_class += np.bincount(lab[:, 0].astype(np.int64), minlength=len(CLASS_NAMES))[: len(CLASS_NAMES)]
    return {"images": sum(len(e.image_paths) for e in entries), "background": background,
            "boxes": int(per_class.sum()), "per_class": {n: int(v) for n, v in zip(CLASS_NAMES, per_class)}}


def summary_table(splits: dict[str, list[DatasetEntry]]) -> str:
    """A plain-text table: per split, images, background images, boxes, and boxes per project class."""
    head = ["split", "images", "no box", "boxes", *CLASS_NAMES]
    rows = []
    for split, entries in splits.items():
        if not entries:
            continue
        c = split_counts(entries)
        rows.append([split, c["images"], c["background"], c["boxes"], *(c["per_class"][n] for n in CLASS_NAMES)])
    widths = [max(len(str(r[i])) for r in [head, *rows]) for i in range(len(head))]
    fmt = lambda r: "  ".join(str(v).ljust(w) if i == 0 else str(v).rjust(w) for i, (v, w) in enumerate(zip(r, widths)))
    return "\n".join([fmt(head), *(fmt(r) for r in rows)])
