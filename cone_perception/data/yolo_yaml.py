"""Ultralytics-style data YAMLs (the format FS teams already have), read into our dataset entries.

The layout read here::

    path: ../datasets/fsoco     # dataset root; relative to this YAML's folder; default: the YAML's folder
    train: images/train         # image folder(s) relative to path: one string or a list
    val: images/val             # optional
    test: images/test           # optional; checked, counted, not trained on
    names: [blue_cone, yellow_cone, orange_cone, large_orange_cone]   # or {0: blue_cone, 1: ...}
    nc: 4                       # optional; must match names when given

Labels lie where Ultralytics looks: the image folder's path with its last
``images`` component replaced by ``labels`` (``images/train`` -> ``labels/train``,
``train/images`` -> ``train/labels``). Class names map to the project's
classes by name (:func:`classes.class_id_from_name`); a name that does not map
is an error naming ``names[i]``. Image-list ``.txt`` files are not read (an
error says so).
"""

from __future__ import annotations

from pathlib import Path

from ..classes import class_id_from_name
from ..errors import ConfigError

#: Keys that make a data YAML Ultralytics-style (``train:`` a folder string or list of strings).
SPLITS = ("train", "val", "test")


def is_yolo_style(doc: dict) -> bool:
    """Whether a parsed data YAML is Ultralytics-style (``train`` a string or a list of strings)."""
    t = doc.get("train")
    return isinstance(t, str) or (isinstance(t, list) and bool(t) and all(isinstance(v, str) for v in t))


def yolo_names(doc: dict, source: str) -> list[str]:
    """The dataset's class names in id order from ``names`` (list or ``{id: name}``); checks ``nc`` and that
    every name maps to a project class."""
    names = doc.get("names")
    if isinstance(names, dict):
        try:
            ids = sorted(int(k) for k in names)
        except (TypeError, ValueError) as e:
            raise ConfigError(source, "names", f"keys of a names mapping must be class ids 0..n-1, got {list(names)}") from e
        if ids != list(range(len(ids))):
            raise ConfigError(source, "names", f"class ids must be 0..{len(ids) - 1} without gaps, got {ids}")
        names = [names[k] if k in names else names[str(k)] for k in ids]
    if not isinstance(names, list) or not names:
        raise ConfigError(source, "names", "class names missing: give names: [a, b, ...] or names: {0: a, 1: b}")
    nc = doc.get("nc")
    if nc is not None and int(nc) != len(names):
        raise ConfigError(source, "nc", f"nc is {nc} but names lists {len(names)} classes")
    for i, n in enumerate(names):
        try:
            class_id_from_name(str(n))
        except KeyError as e:
            raise ConfigError(source, f"names[{i}]", str(e.args[0])) from e
    return [str(n) for n in names]


def labels_dir_for(images_dir: Path) -> Path | None:
    """Ultralytics' label folder of an image folder: the last ``images`` path component -> ``labels``."""
    parts = list(images_dir.parts)
    for i in range(len(parts) - 1, -1, -1):
        if parts[i] == "images":
            parts[i] = "labels"
            return Path(*parts)
    return None


def yolo_entries(doc: dict, yaml_path: Path) -> dict[str, list[dict]]:
    """Ultralytics data YAML -> per split, entries in our data-YAML form (``path``, ``images``, ``labels``,
    ``names``; absolute paths) plus ``_key``, the YAML key to name in errors. Paths are checked here:
    a missing folder is a :class:`ConfigError` naming the YAML file, the key and the folder."""
    source = str(yaml_path)
    names = yolo_names(doc, source)
    root_text = doc.get("path")
    root = yaml_path.parent if root_text in (None, "") else (yaml_path.parent / str(root_text)).expanduser()
    if not root.is_dir():
        raise ConfigError(source, "path", f"dataset root {root} not found")
    out: dict[str, list[dict]] = {}
    for split in SPLITS:
        value = doc.get(split)
        if value in (None, "", []):
            continue
        items = [value] if isinstance(value, str) else value
        if not isinstance(items, list) or not all(isinstance(v, str) for v in items):
            raise ConfigError(source, split, f"must be an image folder or a list of them, got {value!r}")
        entries = []
        for i, rel in enumerate(items):
            key = split if isinstance(value, str) else f"{split}[{i}]"
            images_dir = root / rel
            if rel.lower().endswith(".txt"):
                raise ConfigError(source, key, f"image-list files ({rel}) are not read: give the image folder instead")
            if not images_dir.is_dir():
                raise ConfigError(source, key, f"image folder {images_dir} not found")
            labels_dir = labels_dir_for(images_dir)
            if labels_dir is None:
                raise ConfigError(source, key, f"{images_dir} has no 'images' folder in its path, so its labels "
                                               "cannot be found (Ultralytics layout: .../images/... -> .../labels/...)")
            if not labels_dir.is_dir():
                raise ConfigError(source, key, f"label folder {labels_dir} (for images {images_dir}) not found")
            entries.append({"path": str(images_dir), "images": ".", "labels": str(labels_dir), "names": names,
                            "_key": key})
        out[split] = entries
    if "train" not in out:
        raise ConfigError(source, "train", "needs an image folder under 'train:'")
    return out
