"""Model files: where the shipped default model lies, the description of an exported model (class names,
input size) from its YAML sidecar (``<file name>.yaml``) or the metadata embedded in the file; the
detector's box model measured on labelled frames (``<file name>.box_model.yaml``, issue 27) is read and written
by :mod:`cone_perception.attitude.box_files` (re-exported here)."""

from __future__ import annotations

import ast
import logging
from pathlib import Path

import yaml

from ..attitude.box_files import (  # noqa: F401 (the box model's files: re-exported, their home is attitude/)
    BOX_MODEL_CHOICES, attitude_config_for, box_model_for, box_model_or_default, box_model_path, far_reading_for,
    read_box_model, write_box_model,
)
from ..errors import ConfigError
from ..resources import DEFAULT_MODEL_NAME, default_model_path  # noqa: F401 (re-exported)

log = logging.getLogger(__name__)

def sidecar_path(model_path: str | Path) -> Path:
    """The YAML sidecar ``export`` writes for one exported file: ``<file name>.yaml`` (``m.onnx`` ->
    ``m.onnx.yaml``), so a TorchScript and an ONNX export to one stem keep one sidecar each."""
    model_path = Path(model_path)
    return model_path.with_name(model_path.name + ".yaml")


def find_sidecar(model_path: Path) -> Path | None:
    """The sidecar of an exported model: ``<file name>.yaml``, else ``<stem>.yaml`` (other YOLO tools, older
    exports); None when neither exists."""
    for side in (sidecar_path(model_path), model_path.with_suffix(".yaml")):
        if side.is_file():
            return side
    return None


def read_sidecar(model_path: Path) -> tuple[list[str], tuple[int, int] | None]:
    """Class names and optional input size from the sidecar of an exported model (:func:`find_sidecar`)."""
    side = find_sidecar(model_path)
    if side is None:
        raise ConfigError(str(sidecar_path(model_path)), None,
                          f"class names of {model_path.name} not found: neither embedded in the file nor in a sidecar "
                          f"{sidecar_path(model_path).name} or {model_path.with_suffix('.yaml').name} "
                          "(write `names: [blue_cone, ...]`, or export again: export embeds them)")
    try:
        doc = yaml.safe_load(side.read_text()) or {}
    except yaml.YAMLError as e:
        raise ConfigError(str(side), None, f"not valid YAML: {e}") from e
    names = doc.get("names") if isinstance(doc, dict) else None
    if isinstance(names, dict):
        try:
            names = [names[k] for k in sorted(names, key=int)]
        except (ValueError, TypeError) as e:
            raise ConfigError(str(side), "names", f"dict keys must be class indices 0..n-1: {e}") from e
    if not isinstance(names, list) or not names:
        raise ConfigError(str(side), "names", "must be a non-empty list of class names (or {index: name})")
    imgsz = doc.get("imgsz")
    if imgsz is not None:
        if not (isinstance(imgsz, (list, tuple)) and len(imgsz) == 2 and all(int(v) > 0 and int(v) % 32 == 0 for v in imgsz)):
            raise ConfigError(str(side), "imgsz", f"must be [W, H], positive multiples of 32, got {imgsz}")
        imgsz = (int(imgsz[0]), int(imgsz[1]))
    return [str(n) for n in names], imgsz


def external_names(model_path: Path, embedded: dict) -> tuple[list[str], tuple[int, int] | None, str]:
    """Class names and input size of an exported model: the YAML sidecar if there is one, else the
    metadata ``export`` and other YOLO tools embed (``names`` as "{0: 'blue_cone', ...}", ``imgsz`` as [h, w])."""
    side = find_sidecar(model_path)
    if side is not None or "names" not in embedded:
        names, imgsz = read_sidecar(model_path)
        return names, imgsz, str(side)
    side = sidecar_path(model_path)
    src = f"{model_path}: embedded metadata"
    try:
        names = embedded["names"]
        names = ast.literal_eval(names) if isinstance(names, str) else names
        if isinstance(names, dict):
            names = [names[k] for k in sorted(names, key=int)]
        imgsz = embedded.get("imgsz")
        imgsz = ast.literal_eval(imgsz) if isinstance(imgsz, str) else imgsz
    except (ValueError, SyntaxError, KeyError, TypeError) as e:
        raise ConfigError(src, "names", f"cannot read the embedded class names ({e}); write a sidecar {side.name}") from e
    if not isinstance(names, (list, tuple)) or not names:
        raise ConfigError(src, "names", f"embedded class names are not a list or dict; write a sidecar {side.name}")
    size = (int(imgsz[1]), int(imgsz[0])) if isinstance(imgsz, (list, tuple)) and len(imgsz) == 2 else None  # [h, w]
    return [str(n) for n in names], size, src


def write_sidecar(model_path: Path, class_names: list[str], imgsz: tuple[int, int], extra: dict | None = None) -> Path:
    """Write ``<file name>.yaml`` (:func:`sidecar_path`) with the class names, ``imgsz: [W, H]`` and ``extra``."""
    side = sidecar_path(model_path)
    doc = {"names": list(class_names), "imgsz": [int(imgsz[0]), int(imgsz[1])], **(extra or {})}
    side.write_text(yaml.safe_dump(doc, sort_keys=False))
    return side

