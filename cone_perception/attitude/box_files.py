"""The detector's box model on disk (``<model file name>.box_model.yaml`` beside the model, issue 27): read,
write, the conservative default for a model without one, and which box model a run uses (:func:`box_model_for`:
``--box-model`` of ``replay`` / ``map``, the nodes' ``box_model``), for the far strip's model too
(:func:`far_reading_for`, issue 26f). Imports no torch (the mapping node reads it).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import yaml

from ..errors import ConfigError
from .boxes import DEFAULT_BOX_MODEL, RENDERED_TABLES, STRIP_INPUT_SCALE, BoxModel, BoxReading

log = logging.getLogger(__name__)


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


#: How the image attitude reads a detector's boxes (``replay``/``map`` ``--box-model``, the nodes' ``box_model``):
#: ``model`` = the model's measured box model, ``rendered`` = the rendered drives' box-top table, ``auto`` =
#: rendered for a synthetic camera (its detector's boxes sit on rendered cones as the table says), else model.
BOX_MODEL_CHOICES = ("auto", "model", "rendered")


def box_model_for(choice: str, model_path: str | Path, synthetic: bool) -> tuple[BoxModel | None, str]:
    """``(box model or None for the rendered table, what it is in words)`` for a :data:`BOX_MODEL_CHOICES`
    ``choice``, the detector's model file (:func:`~cone_perception.resources.default_model_path` for the
    shipped one) and whether the camera is a rendered one (``synthetic``: the
    calibration's ``camera`` is ``synth``). ValueError for an unknown choice."""
    if choice not in BOX_MODEL_CHOICES:
        raise ValueError(f"unknown box model choice {choice!r}; known: {', '.join(BOX_MODEL_CHOICES)}")
    if choice == "rendered" or (choice == "auto" and synthetic):
        return None, "rendered table" + (" (synthetic camera)" if choice == "auto" else "")
    bm = box_model_or_default(model_path)
    if bm is DEFAULT_BOX_MODEL:
        return bm, f"default (no {box_model_path(model_path).name}: no shift, spread {bm.sigma_rel:g})"
    return bm, f"measured ({box_model_path(model_path).name}, spread {bm.sigma_rel:g})"


#: Which measured box model reads the far strip's boxes on a real camera (the nodes' ``far_box_model``, ``--far-box-model``):
#: ``band`` (the default) = the band model's, at each box's size in the band model's input px; ``own`` = the far model's
#: own (``MODEL.box_model.yaml``), its sizes without measurements through the band's. The far model's own was measured
#: on 640x360 video, where a far cone is 8-24 px; on a sharper camera its boxes at 15-25 m are 24-48 px, where it has
#: no measurement, and on held-out sharp frames it doubled the image attitude's range error (issue 41): opt-in.
FAR_BOX_MODEL_CHOICES = ("band", "own")


def far_reading_for(choice: str, far_model_path: str | Path | None, band_model_path: str | Path,
                    synthetic: bool, far_box_model: str = "band") -> tuple[BoxReading | None, str]:
    """How the image attitude reads the far strip's boxes (:attr:`~cone_perception.attitude.ImageAttitudeConfig.far_reading`)
    for a :data:`BOX_MODEL_CHOICES` ``choice``: ``(reading, in words)``; the reading is None (its boxes read as the
    band's) where there is no strip (``far_model_path`` None) or the strip runs the band's own model. Else, as
    :func:`box_model_for` decides for the band: the far model's rendered table (:data:`~cone_perception.attitude.boxes.RENDERED_TABLES`;
    a model without one: the band's table, as before) or its measured box model (a model without one: the
    conservative default, warned), looked up at the strip's input scale (:data:`~cone_perception.attitude.boxes.STRIP_INPUT_SCALE`,
    full resolution) whatever scale it was measured at. A measured box model is the far model's own only with
    ``far_box_model`` ``own`` (:data:`FAR_BOX_MODEL_CHOICES`); by default the band's reads the strip's boxes.
    ValueError for an unknown choice."""
    if choice not in BOX_MODEL_CHOICES:
        raise ValueError(f"unknown box model choice {choice!r}; known: {', '.join(BOX_MODEL_CHOICES)}")
    if far_box_model not in FAR_BOX_MODEL_CHOICES:
        raise ValueError(f"unknown far box model {far_box_model!r}; known: {', '.join(FAR_BOX_MODEL_CHOICES)}")
    if far_model_path is None:
        return None, "no far strip"
    far = Path(far_model_path)
    if far.resolve() == Path(band_model_path).resolve():
        return None, "as the band's (the strip runs the band's model)"
    if choice == "rendered" or (choice == "auto" and synthetic):
        table = RENDERED_TABLES.get(far.with_suffix(".pt").name)
        if table is None:
            return None, f"the band's rendered table ({far.name} has none of its own)"
        what = f"rendered table of {far.with_suffix('.pt').name}"
        return BoxReading(None, table, what), what
    if far_box_model == "band":
        return None, "the band model's box model (far_box_model: band; its own: far_box_model own)"
    bm, what = box_model_for("model", far, False)
    if bm.input_scale != STRIP_INPUT_SCALE:  # its buckets are model input px: read at the strip's scale
        if bm.source == "measured":
            what += f", measured at input scale {bm.input_scale:g}, read at the strip's {STRIP_INPUT_SCALE:g}"
        bm = replace(bm, input_scale=STRIP_INPUT_SCALE)
    return BoxReading(bm, (), what), what


def attitude_config_for(choice: str, model_path: str | Path, far_model_path: str | Path | None, synthetic: bool,
                        far_box_model: str = "band"):
    """``(ImageAttitudeConfig, in words)``: the image fit reading the band model's (``model_path``) boxes by
    :func:`box_model_for` and the far strip's model's (``far_model_path``; None: no strip, or the band's model
    in it) by :func:`far_reading_for` (``far_box_model``: :data:`FAR_BOX_MODEL_CHOICES`), for one
    :data:`BOX_MODEL_CHOICES` ``choice`` (the nodes' ``box_model``, ``replay --box-model``). ValueError for an unknown choice."""
    from .image import ImageAttitudeConfig

    bm, what = box_model_for(choice, model_path, synthetic)
    far, far_what = far_reading_for(choice, far_model_path, model_path, synthetic, far_box_model)
    if far_model_path is not None:  # also where its boxes fall back to the band's reading: said, never silent
        what += f"; far strip: {far_what}"
    return ImageAttitudeConfig(box_model=bm, far_reading=far), what
