"""The band's rows (``band_rows``): the calibration's crop, placed from the calibration (geometry/strip.py
``plan_band``), or set by hand; bad values refused naming the option; the commands run the band they say."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from cone_perception.cli import main as cli_main
from cone_perception.crop import CropSpec
from cone_perception.detector.farband import band_rows_for, far_rows_for
from cone_perception.errors import ConfigError
from cone_perception.geometry.calib import load_calibration
from cone_perception.geometry.strip import TALLEST_CONE_M, foot_distance, plan_band

CALIB = load_calibration("example_mainhoop")  # 1920x1080, fy 960, 1.2 m, pitch 10 deg, crop 384-960 halved


def _rows_in_view(calib, d: float, z: float) -> np.ndarray:
    """Image rows of points ``d`` m ahead of the camera at height ``z``, across the view."""
    cam, m = calib.pinhole_camera(), calib.mount_pose
    s = np.linspace(-2.0 * d, 2.0 * d, 801)
    uv, depth = cam.project(np.column_stack([np.full_like(s, m.x_m + d), m.y_m + s, np.full_like(s, z)]))
    ok = (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width - 1)
    return uv[ok, 1]


def test_foot_distance_is_the_ground_row_of_the_camera_model():
    """The feet at row v are d = h / tan(pitch + atan((v - cy) / fy)) ahead (camera 1.2 m up, pitched 10 deg)."""
    cam = CALIB.pinhole_camera()
    for v in (600.0, 960.0, 1079.0):
        d = 1.2 / np.tan(np.radians(10.0) + np.arctan((v - 540.0) / 960.0))
        assert foot_distance(cam, v) == pytest.approx(d, rel=1e-3)
    assert foot_distance(cam, 2000.0) == pytest.approx(foot_distance(cam, 1079.0))  # below the image: its bottom row
    assert np.isnan(foot_distance(cam, 300.0))  # above the horizon (row 371): no ground


@pytest.mark.parametrize("far_rows, top_m", [("auto", 15.0), ("none", 40.0)])
def test_auto_band_holds_the_cones_it_must_with_margins_in_32_row_steps(far_rows, top_m):
    """``auto``: from the top of a large cone as far ahead as the band must see (the strip's near end 15 m with
    the strip on, max_range_m 40 m without) to the crop's bottom (feet 1.8 m ahead), the attitude margins
    (0.5 deg) around them; its height a multiple of 32 rows at the band's scale, the columns and downscale the
    crop's. On example_mainhoop it is not smaller than the hand-set 576 rows: the crop has no margins."""
    band = band_rows_for("auto", CALIB, far_rows)
    c = band.crop
    assert (c.u0, c.u1, c.downscale) == (0, 1920, 2) and c.height_full_px % 64 == 0
    assert c.height_full_px >= CALIB.crop.height_full_px
    assert band.plan.spec.far_m == top_m and band.plan.spec.near_m == pytest.approx(foot_distance(band.plan.camera, 960))
    tops, feet = _rows_in_view(CALIB, top_m, TALLEST_CONE_M), _rows_in_view(CALIB, band.plan.spec.near_m, 0.0)
    margin = 960 * np.tan(np.radians(0.5))  # a 0.5 deg pitch margin at the centre, in rows
    assert tops.min() >= c.v0 + margin and feet.max() <= c.v1 - margin
    assert "placed from the calibration" in band.what


def test_auto_band_ending_past_the_image_is_clamped_to_it_and_smaller_than_a_padded_crop():
    """The rendered drives' calibration (crop 368-1080: 356 rows halved, run padded to 384): the auto band's
    margins reach past the image's bottom, so it ends at the image's bottom (no rows below), 704 rows: 352
    halved, one 32-row step less than the padded crop."""
    calib = replace(CALIB, crop=CropSpec(368, 1080, 0, 1920, 2))
    band = band_rows_for("auto", calib, "auto")
    assert band.crop.v1 == 1080 and band.crop.height_full_px == 704 and band.crop.out_height == 352
    assert "ending at the image's edge" in band.what
    assert "edge" not in band_rows_for("auto", CALIB, "auto").what  # 368-1008: inside
    assert _rows_in_view(calib, 15.0, TALLEST_CONE_M).min() >= band.crop.v0


def test_a_band_taller_than_the_image_is_refused_naming_the_field():
    """A 256-row image of the same camera (cy 128): the band from 40 m cones' tops (above the image) to its
    bottom needs more rows than the image has: refused naming band_rows (and the calibration); so is a crop
    ending above the horizon (no cone feet at its bottom)."""
    cam = CALIB.pinhole_camera()
    K = cam.K.copy()
    K[1, 2] = 128.0
    short = type(cam)(K, 1920, 256, CALIB.mount_pose, cam.dist_coeffs)
    with pytest.raises(ConfigError, match="band_rows.*more than the image") as e:
        plan_band(short, 256, 40.0, 2, source="cam.yaml")
    assert e.value.source == "cam.yaml"
    with pytest.raises(ConfigError, match="no cone feet"):
        plan_band(CALIB.pinhole_camera(), 300, 15.0, 2)  # a crop ending above the horizon


def test_crop_and_hand_set_rows_and_no_camera_matrix():
    """``crop`` (and None) is the calibration's crop, unchanged; ``V0,V1`` those rows with the crop's columns and
    downscale; ``auto`` without a camera_matrix keeps the crop and says why."""
    assert band_rows_for(None, CALIB).crop is CALIB.crop and band_rows_for("crop", CALIB).apply(CALIB) is CALIB
    b = band_rows_for("416,928", CALIB)
    assert b.crop == CropSpec(416, 928, 0, 1920, 2) and b.apply(CALIB).crop == b.crop and b.plan is None
    bare = replace(CALIB, camera_matrix=None, mount_pose=None)
    fallback = band_rows_for("auto", bare)
    assert fallback.crop == CALIB.crop and "no camera_matrix" in fallback.what


@pytest.mark.parametrize("rows, why", [("x", "expected crop, auto or two image rows"), ("1,2,3", "expected crop"),
                                       ("600,500", "need 0 <= V0 < V1"), ("0,2000", "need 0 <= V0 < V1"),
                                       ("385,960", "not divisible by downscale 2")])
def test_bad_band_rows_are_refused_naming_the_option(rows, why):
    with pytest.raises(ConfigError, match=why) as e:
        band_rows_for(rows, CALIB, source="--band-rows")
    assert e.value.source == "--band-rows"


def test_the_strip_and_the_commands_use_the_band(capsys):
    """The far strip is checked against the band it runs with; ``bench pipeline --band-rows`` runs that band (its
    crop and model input in the result), a bad value fails naming --band-rows."""
    calib = band_rows_for("416,928", CALIB).apply(CALIB)
    assert far_rows_for("auto", calib).crop.v0 == 370
    with pytest.raises(ConfigError, match="do not overlap the band"):
        far_rows_for("200,300", calib)
    assert cli_main(["bench", "pipeline", "--frames", "2", "--warmup", "1", "--scenes", "1", "--far-rows", "none",
                     "--band-rows", "416,928", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["crop"]["v0"] == 416 and r["crop"]["v1"] == 928 and r["model_input"] == [960, 256]
    assert cli_main(["bench", "pipeline", "--frames", "2", "--band-rows", "nope"]) != 0
    assert "--band-rows" in capsys.readouterr().err
