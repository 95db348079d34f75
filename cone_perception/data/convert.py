"""Dataset converters: FSOCO (Supervisely JSON) -> YOLO txt, and 16:9 restore of squeezed sets.

FSOCO (thesis, sec. 3.2): each image carries a black border with the
contributing team's logo; it is cropped off and the boxes shifted. The 80/20
train / val split is made per team, so every team's conditions sit in both.
"""

from __future__ import annotations

import json
import logging
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml
from tqdm import tqdm

from ..classes import CLASS_NAMES, class_id_from_name
from ..errors import ConfigError
from .datasets import in_clips
from .yolo_yaml import yolo_names

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp")


def content_rect(img: np.ndarray, dark: int = 12, min_fraction: float = 0.5) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) half-open of the image without its black border.

    A row / column belongs to the border when fewer than ``min_fraction`` of
    its pixels are brighter than ``dark`` (a logo in the border stays below
    that share). Returns the full image when no border is found.
    """
    bright = img.max(axis=2) > dark if img.ndim == 3 else img > dark
    rows = np.flatnonzero(bright.mean(1) >= min_fraction)
    cols = np.flatnonzero(bright.mean(0) >= min_fraction)
    h, w = bright.shape
    if rows.size == 0 or cols.size == 0:
        return 0, 0, w, h
    return int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1


@dataclass
class ConvertReport:
    images: int = 0
    boxes: int = 0
    per_split: dict = field(default_factory=dict)
    skipped: dict = field(default_factory=dict)  # reason -> count
    problems: list = field(default_factory=list)

    def skip(self, reason: str, msg: str) -> None:
        self.skipped[reason] = self.skipped.get(reason, 0) + 1
        if len(self.problems) < 20:
            self.problems.append(msg)


def _team_dirs(src: Path) -> list[Path]:
    teams = sorted(p for p in src.iterdir() if p.is_dir() and (p / "ann").is_dir() and (p / "img").is_dir())
    if not teams:
        raise ConfigError(str(src), None, "no team folders with ann/ and img/ (Supervisely layout) found")
    return teams


def fsoco_to_yolo(src: str | Path, out: str | Path, val_fraction: float = 0.2, seed: int = 0,
                  border_px: int | None = None, progress: bool = True) -> ConvertReport:
    """Convert an FSOCO Supervisely export ``src`` (team folders with ann/ and img/) to YOLO txt in ``out``.

    Writes ``out/images/{train,val}/<team>_<image>``, ``out/labels/...`` and
    ``out/data.yaml`` (project class names; a data YAML for ``cone-perception
    train``). ``border_px``: crop this many px from every side instead of
    detecting the black border.
    """
    src, out = Path(src), Path(out)
    if not src.is_dir():
        raise ConfigError(str(src), None, "FSOCO folder not found")
    rep = ConvertReport()
    rng = np.random.default_rng(seed)
    jobs = []
    for team in _team_dirs(src):
        anns = sorted((team / "ann").glob("*.json"))
        order = rng.permutation(len(anns))
        n_val = int(round(val_fraction * len(anns)))
        for rank, k in enumerate(order):
            jobs.append((team, anns[k], "val" if rank < n_val else "train"))
    for split in ("train", "val"):
        (out / "images" / split).mkdir(parents=True, exist_ok=True)
        (out / "labels" / split).mkdir(parents=True, exist_ok=True)
    for team, ann_path, split in tqdm(jobs, desc="fsoco-to-yolo", disable=not progress):
        img_path = team / "img" / ann_path.name[: -len(".json")]
        if not img_path.is_file():
            rep.skip("missing_image", f"{ann_path}: image {img_path.name} not found")
            continue
        try:
            ann = json.loads(ann_path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            rep.skip("bad_json", f"{ann_path}: not valid JSON: {e}")
            continue
        img = cv2.imread(str(img_path), cv2.IMREAD_COLOR)
        if img is None:
            rep.skip("unreadable_image", f"{img_path}: cannot be read")
            continue
        h, w = img.shape[:2]
        if border_px is not None:
            x0, y0, x1, y1 = border_px, border_px, w - border_px, h - border_px
        else:
            x0, y0, x1, y1 = content_rect(img)
        cw, ch = x1 - x0, y1 - y0
        lines = []
        for j, obj in enumerate(ann.get("objects", [])):
            where = f"{ann_path}: objects[{j}]"
            if obj.get("geometryType") != "rectangle":
                rep.skip("not_rectangle", f"{where}: geometry {obj.get('geometryType')!r} skipped")
                continue
            try:
                cls = class_id_from_name(obj["classTitle"])
                (ax, ay), (bx, by) = obj["points"]["exterior"]
            except KeyError as e:
                rep.skip("unknown_class", f"{where}: {e.args[0]}")
                continue
            except (TypeError, ValueError):
                rep.skip("bad_points", f"{where}: points.exterior must be two [x, y] corners")
                continue
            bx1, bx2 = sorted((float(ax) - x0, float(bx) - x0))
            by1, by2 = sorted((float(ay) - y0, float(by) - y0))
            bx1, bx2 = max(bx1, 0.0), min(bx2, float(cw))
            by1, by2 = max(by1, 0.0), min(by2, float(ch))
            if bx2 - bx1 < 1 or by2 - by1 < 1:
                rep.skip("box_in_border", f"{where}: box lies in the cropped border")
                continue
            lines.append(f"{cls} {(bx1 + bx2) / 2 / cw:.6f} {(by1 + by2) / 2 / ch:.6f} {(bx2 - bx1) / cw:.6f} {(by2 - by1) / ch:.6f}\n")
        name = f"{team.name}_{img_path.stem}"
        cv2.imwrite(str(out / "images" / split / f"{name}{img_path.suffix}"), img[y0:y1, x0:x1])
        (out / "labels" / split / f"{name}.txt").write_text("".join(lines))
        rep.images += 1
        rep.boxes += len(lines)
        rep.per_split[split] = rep.per_split.get(split, 0) + 1
    names = list(CLASS_NAMES)
    doc = {
        "names": names,
        "train": [{"path": ".", "images": "images/train", "labels": "labels/train", "names": names}],
        "val": [{"path": ".", "images": "images/val", "labels": "labels/val", "names": names}],
    }
    (out / "data.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    for m in rep.problems:
        log.warning("%s", m)
    return rep


def _dataset_names(root: Path) -> list[str] | None:
    """Class names of a YOLO dataset folder from its data.yaml (list or dict) or classes.txt; None if none."""
    f = root / "data.yaml"
    if f.is_file():
        try:
            names = (yaml.safe_load(f.read_text()) or {}).get("names")
        except (yaml.YAMLError, AttributeError):
            names = None
        if isinstance(names, dict):
            names = [names[k] for k in sorted(names, key=int)]
        if isinstance(names, list) and names:
            return [str(n) for n in names]
    if (root / "classes.txt").is_file():
        return [l.strip() for l in (root / "classes.txt").read_text().splitlines() if l.strip()] or None
    return None


def restore_aspect(src: str | Path, out: str | Path, aspect: tuple[float, float] = (16, 9), images: str = "images",
                   labels: str = "labels", progress: bool = True, width: int | None = None,
                   clips: list[str] | None = None, names: list[str] | None = None) -> ConvertReport:
    """Copy a YOLO dataset, resizing every image to ``aspect`` (w:h); labels are unchanged (they are
    normalised). The width is kept, or set to ``width``. ``clips`` keeps only frames of these clips
    (file name before '-', as in training data YAMLs). Other files at the top (data.yaml, README)
    are copied too; then ``out/data.yaml`` is written (Ultralytics form, ``train: images``, the dataset's class
    names: ``names``, else those of ``src/data.yaml`` or ``src/classes.txt``; none found is an error before
    any image is written), so ``cone-perception train --data out/data.yaml`` reads it."""
    if width is not None and width < 16:
        raise ConfigError("restore-aspect", "width", f"must be at least 16 px, got {width}")
    src, out = Path(src), Path(out)
    si, sl = src / images, src / labels
    if not si.is_dir():
        raise ConfigError(str(si), None, "image folder not found")
    if out.resolve() == src.resolve():
        raise ConfigError(str(out), None, "output folder must differ from the source")
    names = names or _dataset_names(src)
    if not names:
        raise ConfigError(str(src), "names", "class names unknown (no data.yaml or classes.txt with names): give "
                                              "them in id order, e.g. --names blue_cone,large_orange_cone,orange_cone,yellow_cone")
    yolo_names({"names": list(names)}, "--names")
    (out / images).mkdir(parents=True, exist_ok=True)
    (out / labels).mkdir(parents=True, exist_ok=True)
    rep = ConvertReport()
    files = sorted(p for p in si.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if clips:
        files = [p for p in files if in_clips(p.stem, set(clips))]
        if not files:
            raise ConfigError(str(si), "clips", f"no images of clips {', '.join(clips)}")
    for p in tqdm(files, desc="restore-aspect", disable=not progress):
        img = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if img is None:
            rep.skip("unreadable_image", f"{p}: cannot be read")
            continue
        h, w = img.shape[:2]
        new_w = width or w
        new_h = int(round(new_w * aspect[1] / aspect[0]))
        if (new_w, new_h) != (w, h):
            smaller = new_w * new_h < w * h
            img = cv2.resize(img, (new_w, new_h), interpolation=cv2.INTER_AREA if smaller else cv2.INTER_LINEAR)
        cv2.imwrite(str(out / images / p.name), img)
        lf = sl / f"{p.stem}.txt"
        if lf.is_file():
            shutil.copyfile(lf, out / labels / lf.name)
            rep.boxes += sum(1 for line in lf.read_text().splitlines() if line.strip())
        else:
            rep.skip("no_label", f"{p}: no label file (copied as background image)")
        rep.images += 1
    for f in src.iterdir():
        if f.is_file():
            shutil.copyfile(f, out / f.name)
    if (out / "data.yaml").is_file():  # the source's own, describing the source's layout
        (out / "data.yaml").replace(out / "data.source.yaml")
    doc = {"train": images, "names": [str(n) for n in names]}
    (out / "data.yaml").write_text(
        f"# written by cone-perception data restore-aspect from {src} (aspect {aspect[0]:g}:{aspect[1]:g})\n"
        "# Ultralytics form; labels in labels/; no val: split here (use this folder as val: of another YAML if it "
        "is held out)\n" + yaml.safe_dump(doc, sort_keys=False))
    for m in rep.problems:
        log.warning("%s", m)
    return rep
