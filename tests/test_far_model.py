"""The shipped far strip model (models/cone_detector_far.pt): the band model's classes, and in the strip it finds
the far cones at least as well as the band's model does there."""

from __future__ import annotations

import numpy as np

from cone_perception.detector.farband import FarBand, check_far_classes
from cone_perception.resources import models_dir

STRIP = "370,466"  # the example calibration's far strip (96 rows)


def _frames(seed: int, n: int):
    from cone_perception.synth.config import SynthConfig
    from cone_perception.synth.scene import random_pose

    cfg = SynthConfig(width=1920, height=1080, seed=seed, jitter=False)
    renderer, rng = cfg.renderer(), np.random.default_rng(seed)
    out = []
    for i in range(n):
        if i % 4 == 0:
            track, look = cfg.track(i, rng), renderer.new_look(rng)
        out.append(renderer.render(track, random_pose(track, rng, False), look, rng))
    return out


def _iou(xyxy: np.ndarray, box) -> np.ndarray:
    lt, rb = np.maximum(xyxy[:, :2], box[:2]), np.minimum(xyxy[:, 2:], box[2:])
    inter = np.prod(np.clip(rb - lt, 0, None), 1)
    return inter / (np.prod(xyxy[:, 2:] - xyxy[:, :2], 1) + (box[2] - box[0]) * (box[3] - box[1]) - inter)


def _strip_recall(far: FarBand, frames) -> tuple[int, int, int]:
    """(found, cones, false detections) at score >= 0.25: cones whole inside the strip and at least half
    visible, found by a box of their class at IoU >= 0.5; false = a box at IoU < 0.3 with every rendered cone."""
    c = far.crop
    found = total = false = 0
    for img, truth in frames:
        boxes = far.detect(img[c.v0:c.v1])
        xyxy = np.stack([boxes["u1"], boxes["v1"], boxes["u2"], boxes["v2"]], 1)
        best = np.zeros(len(boxes))
        for t in truth:
            best = np.maximum(best, _iou(xyxy, t.box))
        false += int((best < 0.3).sum())
        for t in truth:
            if t.visible_fraction < 0.5 or t.box[1] < c.v0 + 2 or t.box[3] > c.v1 - 2:
                continue
            total += 1
            found += bool(np.any((_iou(xyxy, t.box) >= 0.5) & (boxes["class_id"] == t.class_id)))
    return found, total, false


def test_shipped_far_model_beats_the_band_model_in_the_strip():
    from cone_perception.crop import CropSpec
    from cone_perception.detector import Detector, default_model_path

    band = CropSpec(384, 960, 0, 1920, 2)
    far_path = models_dir() / "cone_detector_far.pt"
    far = FarBand.load(far_path, STRIP, 1920, 1080, band, model_source="--far-model", conf=0.25)
    base = FarBand.load(default_model_path(), STRIP, 1920, 1080, band, conf=0.25)
    check_far_classes(Detector.load_for_band(default_model_path(), (960, 288)), far.detector)  # no error: same classes
    frames = _frames(9, 8)
    f_far, n, d_far = _strip_recall(far, frames)
    f_base, n_base, d_base = _strip_recall(base, frames)
    assert n == n_base and n >= 60, n  # enough far cones in the strip
    assert f_far >= f_base + 0.08 * n, (f_far, f_base, n)
    assert d_far <= d_base + 0.02 * n, (d_far, d_base)  # not by firing at the background


def test_far_model_choices_and_the_far_model_default(tmp_path):
    """``far_model`` / ``--far-model``: auto (the default, and None: not given) = models/cone_detector_far.pt;
    band or empty = the band's own model (whatever the caller passes for it); else that file. The node's
    parameter table says auto (issue 26f: the image attitude reads its boxes through its own box model)."""
    from pathlib import Path

    from cone_perception.params import PARAMS
    from cone_perception.resources import default_far_model_path, far_model_for, far_model_given

    assert default_far_model_path() == models_dir() / "cone_detector_far.pt" and default_far_model_path().exists()
    band = tmp_path / "band.pt"
    for choice in (None, "auto", " AUTO "):
        assert far_model_for(choice, band) == default_far_model_path() and not far_model_given(choice)
    for choice in ("", "band", "Band"):
        assert far_model_for(choice, band) == band and not far_model_given(choice)
    assert far_model_for("", None) is None and far_model_for("band", None) is None  # the node: the band's loaded model
    assert far_model_for("x/m.pt", band) == Path("x/m.pt") and far_model_given("x/m.pt")
    assert PARAMS["far_model"].default == "auto"
