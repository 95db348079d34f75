"""The debug image's drawing (core, no ROS): boxes in band px, class colours, distances, rate limit."""

from __future__ import annotations

import numpy as np
import pytest

from cone_perception.classes import BLUE, CLASS_BGR, YELLOW
from cone_perception.geometry.calib import load_calibration
from cone_perception.mapping import ConeMapper
from cone_perception.records import boxes_from_arrays
from cone_perception.vis.debug_image import DebugImage, RateLimit, box_ranges_m, draw_debug_band

CALIB = load_calibration("example_mainhoop")  # band rows 384-960, downscale 2 -> 960x288


def _boxes():
    # full-image px: a blue cone near the bottom of the band, a yellow one further up, one beyond the range
    return boxes_from_arrays(
        np.array([[800.0, 840, 880, 940], [1100, 600, 1140, 660], [1000, 390, 1010, 400]]), [0.9, 0.6, 0.5],
        [BLUE, YELLOW, YELLOW],
    )


def test_ranges_are_the_mapped_cones_distances():
    mapper, boxes = ConeMapper(CALIB), _boxes()
    r = box_ranges_m(mapper, boxes)
    cones = mapper.map_boxes(boxes[:2])
    np.testing.assert_allclose(r[:2], np.hypot(cones["x"], cones["y"]), rtol=1e-6)
    assert 2 < r[0] < r[1] < 30
    assert np.isnan(r[2])  # beyond max_range_m (30 m): no cone, no distance


def test_ranges_count_nothing_and_give_every_box_its_own_distance():
    """The pipeline node draws its debug image with the pipeline's own mapper: the distances must not count the
    frame's drops a second time (/diagnostics boxes_dropped), and two boxes of one viewing ray, which /cones makes
    one cone, each show their own distance."""
    mapper = ConeMapper(CALIB, 0.8, 40.0)
    boxes = _boxes()
    twice = np.concatenate([boxes[1:2], boxes[1:2]])  # two boxes of the yellow cone, 2 px apart in foot row
    twice["v2"][1] += 2
    twice["score"][0] = 0.9  # both above the flat gate's score
    twice["score"][1] = 0.55
    assert len(mapper.map_boxes(twice)) == 1 and mapper.dropped["one_ray"] == 1
    before = dict(mapper.dropped)
    r = box_ranges_m(mapper, np.concatenate([boxes, twice]))
    assert mapper.dropped == before
    assert np.isnan(r[2]) and np.isfinite(r[[0, 1, 3, 4]]).all() and r[4] < r[3]


def test_boxes_drawn_in_band_px_with_class_colours():
    crop = CALIB.crop
    band = np.full((crop.out_height, crop.out_width, 3), 90, np.uint8)
    boxes = _boxes()
    out = draw_debug_band(band, boxes, crop, box_ranges_m(ConeMapper(CALIB), boxes))
    assert out.shape == band.shape and out.dtype == np.uint8
    assert (band == 90).all()  # the input is not drawn on
    # blue box: full (800, 840)-(880, 940) -> band ((800-0)/2, (840-384)/2) = (400, 228)-(440, 278)
    left_edge = out[240:270, 400]
    assert (np.abs(left_edge.astype(int) - CLASS_BGR[BLUE]).sum(1) < 60).mean() > 0.8
    yellow_left = out[(600 - 384) // 2 + 5 : (660 - 384) // 2 - 5, 550]
    assert (np.abs(yellow_left.astype(int) - CLASS_BGR[YELLOW]).sum(1) < 60).mean() > 0.8
    assert (out[150:200, 700:900] == 90).all()  # away from boxes and labels: the band as it was


def test_no_boxes_gives_the_band_with_a_count():
    crop = CALIB.crop
    band = np.zeros((crop.out_height, crop.out_width, 3), np.uint8)
    out = DebugImage(ConeMapper(CALIB)).render(band, boxes_from_arrays(np.zeros((0, 4)), [], []), crop)
    assert out.shape == band.shape
    assert out[:30, :120].any() and not out[40:].any()  # only the "0 boxes" text


def test_rate_limit():
    lim = RateLimit(5.0)
    assert lim.due(10.0)
    assert not lim.due(10.1) and not lim.due(10.19)
    assert lim.due(10.2)
    lim.hz = 1.0
    assert not lim.due(11.1) and lim.due(11.2)
    times = np.arange(0, 10, 0.01)
    lim = RateLimit(5.0)
    assert sum(lim.due(t) for t in times) == 50  # 100 frames/s in, 5 images/s out


def test_ranges_one_bad_box_does_not_hide_the_others():
    mapper, boxes = ConeMapper(CALIB), _boxes()
    good = box_ranges_m(mapper, boxes)
    bad = boxes.copy()
    bad["u2"][1] = bad["u1"][1] - 5  # u2 < u1: map_boxes refuses the whole message
    r = box_ranges_m(mapper, bad)
    assert r[0] == pytest.approx(good[0]) and np.isnan(r[1]) and np.isnan(r[2])
    many = np.concatenate([boxes] * 100)  # 300 boxes, each its own distance
    np.testing.assert_allclose(box_ranges_m(mapper, many), np.tile(good, 100), rtol=1e-6)


def test_covariance_ellipses_axes_and_yaw():
    from cone_perception.geometry import covariance_ellipses
    from cone_perception.records import CONE_DTYPE

    c = np.zeros(3, CONE_DTYPE)
    # sigma 0.3 m along x, 0.1 m along y; then the same turned by 30 degrees; then a round one
    rot = np.radians(30.0)
    R = np.array([[np.cos(rot), -np.sin(rot)], [np.sin(rot), np.cos(rot)]])
    for i, cov in enumerate([np.diag([0.09, 0.01]), R @ np.diag([0.09, 0.01]) @ R.T, np.diag([0.04, 0.04])]):
        c["cov_xx"][i], c["cov_xy"][i], c["cov_yy"][i] = cov[0, 0], cov[0, 1], cov[1, 1]
    major, minor, yaw = covariance_ellipses(c, 2.0)
    np.testing.assert_allclose(major[:2], [1.2, 1.2], rtol=1e-5)  # 2 * 2 sigma * 0.3 m
    np.testing.assert_allclose(minor[:2], [0.4, 0.4], rtol=1e-4)
    assert np.sin(yaw[0]) == pytest.approx(0.0, abs=1e-6)
    assert np.degrees(yaw[1]) % 180.0 == pytest.approx(30.0, abs=1e-3)
    assert major[2] == pytest.approx(minor[2]) == pytest.approx(0.8)
