"""Model files: where the shipped default model lies, the description of an exported model (class names,
input size) from its YAML sidecar (``<file name>.yaml``) or the metadata embedded in the file, and the
detector's box model measured on labelled frames (``<file name>.box_model.yaml``, issue 27)."""

from __future__ import annotations

import ast
import logging
from pathlib import Path

import yaml

from ..attitude.boxes import DEFAULT_BOX_MODEL, BoxModel
from ..errors import ConfigError
from ..resources import models_dir

log = logging.getLogger(__name__)

#: File name of the shipped default model under ``models/``.
DEFAULT_MODEL_NAME = "cone_detector.pt"


def default_model_path() -> Path:
    """``models/cone_detector.pt`` of the installed package (may not exist yet)."""
    return models_dir() / DEFAULT_MODEL_NAME


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


def box_model_path(model_path: str | Path) -> Path:
    """The box-model sidecar of a model file: ``<file name>.box_model.yaml`` (``m.pt`` -> ``m.pt.box_model.yaml``)."""
    model_path = Path(model_path)
    return model_path.with_name(model_path.name + ".box_model.yaml")


def write_box_model(path: str | Path, box_model: BoxModel, command: str = "") -> Path:
    """Write ``box_model`` (:class:`~cone_perception.attitude.boxes.BoxModel`) to the YAML file ``path``
    (``box_model:`` mapping; ``command``: how it was measured)."""
    path = Path(path)
    doc = {"box_model": box_model.to_dict()}
    if command:
        doc["measured_with"] = command
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def read_box_model(model_path: str | Path) -> BoxModel | None:
    """The box model beside a model file (:func:`box_model_path`; for an export ``m.onnx`` also that of
    ``m.pt``), or None where there is none. :class:`ConfigError` naming the file and field for a bad one."""
    model_path = Path(model_path)
    for side in (box_model_path(model_path), box_model_path(model_path.with_suffix(".pt"))):
        if not side.is_file():
            continue
        try:
            doc = yaml.safe_load(side.read_text()) or {}
        except yaml.YAMLError as e:
            raise ConfigError(str(side), None, f"not valid YAML: {e}") from e
        try:
            return BoxModel.from_dict(doc.get("box_model") if isinstance(doc, dict) else None)
        except ValueError as e:
            raise ConfigError(str(side), "box_model", str(e)) from None
    return None


def box_model_or_default(model_path: str | Path | None) -> BoxModel:
    """The model's box model, or :data:`~cone_perception.attitude.boxes.DEFAULT_BOX_MODEL` with a warning
    (no shift, a wide per-cone spread: measure one with ``eval --box-model-out``)."""
    bm = read_box_model(model_path) if model_path is not None else None
    if bm is None:
        log.warning("%s has no box model (%s): the image attitude takes its boxes as the labelled cones with a wide "
                    "per-cone spread; measure one with `cone-perception eval --box-model-out`", model_path,
                    box_model_path(model_path).name if model_path is not None else "no model file")
        return DEFAULT_BOX_MODEL
    return bm
