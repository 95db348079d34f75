"""Foot point -> cone centre: the offset along the viewing ray, measured on rendered scenes."""

from __future__ import annotations

import numpy as np
import pytest

from cone_perception.classes import CLASS_NAMES, LARGE_ORANGE, ORANGE
from cone_perception.errors import ConfigError
from cone_perception.geometry.calib import (
    DEFAULT_FOOT_POINTS, RECOMMENDED_FOOT_OFFSET_M, calibration_from_dict, load_calibration,
)
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


def _plate_box(cfg, xy_centre: np.ndarray, plate_yaw_rad: float, side_m: float) -> tuple[np.ndarray, float]:
    """Box (pixel-edge u1, v1, u2, v2) of a square plate (``side_m``) at ``xy_centre`` turned by
    ``plate_yaw_rad`` against the viewing ray, its near edge the foot; and that edge's distance h to the centre."""
    cam = cfg.camera()
    cam_xy = cfg.calibration().camera_ground_xy()
    d = (xy_centre - cam_xy) / np.linalg.norm(xy_centre - cam_xy)
    n = np.array([-d[1], d[0]])
    h = side_m / 2 * (abs(np.cos(plate_yaw_rad)) + abs(np.sin(plate_yaw_rad)))
    near = xy_centre - h * d
    pts = np.array([[*near, 0.0], [*(near + h * n), 0.0], [*(near - h * n), 0.0]])
    uv, _ = cam.project(pts)
    return np.array([uv[:, 0].min() + 0.5, uv[0, 1] - 20.0, uv[:, 0].max() + 0.5, uv[0, 1] + 0.5]), h


@pytest.mark.parametrize("yaw_deg", [0.0, 20.0, 45.0])
def test_foot_offset_from_the_box_width_follows_the_plate_yaw(yaw_deg) -> None:
    """A plate turned by yaw_deg against the ray: its near edge is s/2 (|cos| + |sin|) before the centre;
    the width of its box gives that offset, where the class's fixed 0.15 m is off by up to 3.6 cm."""
    cfg = SynthConfig(jitter=False)
    side = 0.228
    centres = np.array([[4.0, 0.0], [8.0, 1.5], [12.0, -2.0]])
    rows = [_plate_box(cfg, c, np.radians(yaw_deg), side) for c in centres]
    boxes = boxes_from_arrays(np.array([b for b, _ in rows]), np.ones(len(rows)), np.full(len(rows), ORANGE))
    cal = cfg.calibration()
    fixed = ConeMapper(cal).map_boxes(boxes)
    cal.foot_offset_from_width = True
    wide = ConeMapper(cal).map_boxes(boxes)
    err_w = np.hypot(wide["x"] - centres[:, 0], wide["y"] - centres[:, 1])
    err_f = np.hypot(fixed["x"] - centres[:, 0], fixed["y"] - centres[:, 1])
    assert err_w.max() < 0.004, err_w
    h = rows[0][1]
    np.testing.assert_allclose(err_f, abs(h - RECOMMENDED_FOOT_OFFSET_M["orange"]), atol=0.004)
    # the output covariance and the other fields are those of the fixed offset
    np.testing.assert_array_equal(wide["cov_xx"], fixed["cov_xx"])
    np.testing.assert_array_equal(wide["class_id"], fixed["class_id"])


def test_foot_offset_from_width_is_clipped_and_keeps_the_fixed_offset_where_the_size_is_unknown() -> None:
    from cone_perception.classes import UNKNOWN

    cfg = SynthConfig(jitter=False)
    cal = cfg.calibration()
    cal.foot_offset_from_width = True
    m = ConeMapper(cal)
    box, _ = _plate_box(cfg, np.array([8.0, 0.0]), 0.0, 0.228)
    wide = box.copy()
    wide[0], wide[2] = box[0] - 40, box[2] + 40  # a box far too wide (a cone lying on its side, two cones)
    narrow = box.copy()
    narrow[2] = narrow[0] + 1
    recs = boxes_from_arrays(np.array([wide, narrow, wide]), np.ones(3), np.array([ORANGE, ORANGE, UNKNOWN]))
    off = m.width_offsets(recs, m.foot_points(recs))
    np.testing.assert_allclose(off, [0.228 / np.sqrt(2), 0.114, RECOMMENDED_FOOT_OFFSET_M["unknown"]])
    # in the YAML: a boolean, written only when set
    d = cal.to_dict()
    assert d["foot_offset_from_width"] is True and calibration_from_dict(d, "mem.yaml").foot_offset_from_width
    assert "foot_offset_from_width" not in cfg.calibration().to_dict()
    with pytest.raises(ConfigError) as e:
        calibration_from_dict(dict(d, foot_offset_from_width="yes"), "mem.yaml")
    assert e.value.field == "foot_offset_from_width"


def test_foot_offset_from_width_is_nearer_the_truth_on_rendered_cones() -> None:
    """Rendered cones stand on plates at any yaw: the width rule beats the fixed offset (exact boxes)."""
    cfg, truths = _exact_boxes()
    boxes = boxes_from_arrays(np.array([t.box for t in truths]), np.ones(len(truths)), np.array([t.class_id for t in truths]))
    xy = np.array([[t.x_m, t.y_m] for t in truths])
    med = {}
    for from_width in (False, True):
        cal = cfg.calibration()
        cal.foot_offset_from_width = from_width
        c = ConeMapper(cal).map_boxes(boxes)
        med[from_width] = np.median(np.hypot(c["x"] - xy[:, 0], c["y"] - xy[:, 1]))
    assert med[True] < 0.95 * med[False], med
