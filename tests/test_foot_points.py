"""Foot point -> cone centre: the offset along the viewing ray, measured on rendered scenes."""

from __future__ import annotations

import numpy as np
import pytest

from cone_perception.calib import DEFAULT_FOOT_POINTS, RECOMMENDED_FOOT_OFFSET_M, calibration_from_dict, load_calibration
from cone_perception.classes import CLASS_NAMES, LARGE_ORANGE, ORANGE
from cone_perception.errors import ConfigError
from cone_perception.mapping import ConeMapper
from cone_perception.records import boxes_from_arrays
from cone_perception.synth.config import SynthConfig
from cone_perception.synth.scene import random_pose


def test_offset_moves_along_the_ray_from_the_camera() -> None:
    c = load_calibration("example_mainhoop")
    cam_xy = c.camera_ground_xy()
    np.testing.assert_allclose(cam_xy, [0.5, 0.0], atol=1e-6)  # from H and K: the mount of the example
    m = ConeMapper(c)
    xy = np.array([[5.0, 2.0], [12.0, -3.0]])
    moved = m.foot_offsets(xy, np.array([ORANGE, LARGE_ORANGE]))
    d = moved - xy
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), [0.15, 0.19], atol=1e-9)
    ray = (xy - cam_xy) / np.linalg.norm(xy - cam_xy, axis=1, keepdims=True)
    np.testing.assert_allclose(d / np.linalg.norm(d, axis=1, keepdims=True), ray, atol=1e-9)


def test_camera_xy_override_and_bad_offsets() -> None:
    d = load_calibration("example_mainhoop").to_dict()
    d["camera_xy_m"] = [1.0, 0.2]
    np.testing.assert_allclose(calibration_from_dict(d, "mem.yaml").camera_ground_xy(), [1.0, 0.2])
    for bad, field in [({"blue": -0.1}, "foot_offset_m.blue"), ({"purple": 0.1}, "foot_offset_m.purple"),
                       ({"blue": "far"}, "foot_offset_m.blue")]:
        d2 = dict(d, foot_offset_m=bad)
        with pytest.raises(ConfigError) as e:
            calibration_from_dict(d2, "mem.yaml")
        assert e.value.field == field


def _exact_boxes(frames: int = 24):
    cfg = SynthConfig(seed=11, jitter=False, nose_prob=0.0)
    renderer, rng = cfg.renderer(), np.random.default_rng(11)
    truths = []
    for k in range(frames):
        if k % 8 == 0:
            track, look = cfg.track(k, rng), renderer.new_look(rng)
        _, t = renderer.render(track, random_pose(track, rng, False), look, rng)
        truths += [x for x in t if x.visible_fraction >= 0.999 and x.distance_m <= 15.0]
    return cfg, truths


def test_bottom_centre_plus_offset_beats_the_thesis_corners_on_rendered_cones() -> None:
    """Exact boxes of rendered cones, exact homography, no jitter: what the foot-point rule alone costs."""
    cfg, truths = _exact_boxes()
    boxes = boxes_from_arrays(np.array([t.box for t in truths]), np.ones(len(truths)), np.array([t.class_id for t in truths]))
    xy_true = np.array([[t.x_m, t.y_m] for t in truths])
    errors = {}
    for name, rules, offsets in [
        ("thesis corners", DEFAULT_FOOT_POINTS, dict.fromkeys(CLASS_NAMES, 0.0)),
        ("centre + offset", dict.fromkeys(CLASS_NAMES, "bottom_center"), RECOMMENDED_FOOT_OFFSET_M),
    ]:
        cal = cfg.calibration()
        cal.foot_points = tuple(rules[n] for n in CLASS_NAMES)
        cal.foot_offset_m = tuple(offsets[n] for n in CLASS_NAMES)
        cones = ConeMapper(cal).map_boxes(boxes)
        assert len(cones) == len(truths)
        errors[name] = np.hypot(cones["x"] - xy_true[:, 0], cones["y"] - xy_true[:, 1])
    assert len(truths) > 100
    assert np.median(errors["centre + offset"]) < 0.05
    assert np.percentile(errors["centre + offset"], 90) < 0.10
    assert np.median(errors["thesis corners"]) > 3 * np.median(errors["centre + offset"])
