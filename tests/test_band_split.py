"""The row-scaled band (``band_split``): the band's near rows at a quarter of full resolution, the split placed
from the calibration (geometry/strip.py ``plan_split``), set by hand, or off; bad values and calibrations refused
naming the field; the split detector cuts, scales and merges as it says; the commands run it."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from cone_perception.cli import main as cli_main
from cone_perception.crop import CropSpec
from cone_perception.detector.farband import EDGE_PX, SplitDetector, band_split_for
from cone_perception.errors import ConfigError
from cone_perception.geometry.calib import load_calibration
from cone_perception.geometry.strip import (SMALLEST_CONE_M, SPLIT_MIN_PX, TALLEST_CONE_M, cone_height_px,
                                            foot_distance, needed_rows, plan_split)
from cone_perception.records import BOX_DTYPE, boxes_from_arrays

from rosutil import ros  # noqa: F401 (a fixture)

CALIB = load_calibration("example_mainhoop")  # 1920x1080, fy 960, 1.2 m, pitch 10 deg, crop 384-960 halved


def _boxes(rows):
    a = np.array(rows, dtype=np.float32).reshape(-1, 6)
    return boxes_from_arrays(a[:, :4], a[:, 4], a[:, 5].astype(np.uint8))


def _invariants(cam, plan, margin_deg=0.5):
    """Every cone is whole in one part, and those whole only in the near band are >= SPLIT_MIN_PX tall there."""
    (u0, u1), (n0, n1) = plan.upper, plan.near
    for d in np.geomspace(1.0, 60.0, 200):
        foot = max(needed_rows(cam, d, d + 1.0, p, r)[1] for p in (-margin_deg, 0, margin_deg)
                   for r in (-margin_deg, 0, margin_deg))
        if foot >= u1 - EDGE_PX:  # cut by (or below) the upper band's bottom: the near band must see it, large enough
            assert cone_height_px(cam, d, SMALLEST_CONE_M) >= SPLIT_MIN_PX * plan.near_downscale
    d_up = foot_distance(cam, u1)  # the farthest cone whose foot reaches the upper band's bottom: whole in the near band
    assert needed_rows(cam, d_up, d_up)[0] >= n0 + EDGE_PX * 0  # its top inside the near band
    assert (n1 - n0) % (32 * plan.near_downscale) == 0 or n0 == u0


def test_auto_split_of_the_example_camera():
    """example_mainhoop (crop 384-960 halved, 960x288): the upper band 384-576 at 1/2 (960x96), the near band 448-960
    at 1/4 (480x128): small cones nearer than 6.3 m are >= 48 px tall at full resolution, >= 12 at the quarter;
    0.56x the band's pixels."""
    cam = CALIB.pinhole_camera()
    p = plan_split(cam, (384, 960), 2, CALIB.far_strip)
    assert p.upper == (384, 576) and p.near == (448, 960) and p.near_downscale == 4
    assert cone_height_px(cam, p.split_m, SMALLEST_CONE_M) == pytest.approx(48.0, abs=0.1)
    assert 6.0 < p.split_m < 6.6
    _invariants(cam, p)
    s = band_split_for("auto", CALIB)
    assert (s.upper, s.near) == (CropSpec(384, 576, 0, 1920, 2), CropSpec(448, 960, 0, 1920, 4))
    assert (s.upper.out_width, s.upper.out_height, s.near.out_width, s.near.out_height) == (960, 96, 480, 128)
    assert "placed from the calibration" in s.what


def test_the_calibration_decides_the_split():
    """Another camera (a longer lens, fy 1400) sees cones larger: more of the band runs at the quarter (the split
    moves up: the near band starts at the band's top, the upper band ends higher); the rendered drives' crop
    (368-1080) keeps its top and bottom. No rows are set by hand."""
    cam = CALIB.pinhole_camera()
    K = cam.K.copy()
    K[0, 0] = K[1, 1] = 1400.0
    long_lens = type(cam)(K, 1920, 1080, CALIB.mount_pose, cam.dist_coeffs)
    p_long = plan_split(long_lens, (384, 960), 2)
    p = plan_split(cam, (384, 960), 2)
    assert p_long.split_m > p.split_m and p_long.near[0] < p.near[0] and p_long.upper[1] < p.upper[1]
    assert p_long.near == (384, 960)  # a near band reaching above the band's top starts there
    _invariants(long_lens, p_long)
    drive = plan_split(cam, (368, 1080), 2)
    assert drive.upper[0] == 368 and drive.near[1] == 1080 and (drive.upper[1] - 368) % 64 == 0
    _invariants(cam, drive)


def test_hand_set_and_off():
    assert band_split_for(None, CALIB).upper is None and band_split_for("none", CALIB).near is None
    assert band_split_for("off", CALIB).upper is None
    s = band_split_for("448,576", CALIB, "--band-split")
    assert s.upper == CropSpec(384, 576, 0, 1920, 2) and s.near == CropSpec(448, 960, 0, 1920, 4)
    assert "fixed: --band-split" in s.what


@pytest.mark.parametrize("value, why", [("x", "expected none, auto or two image rows"), ("1,2,3", "expected none"),
                                        ("600,500", "need 384 < N0 < U1 < 960"), ("300,576", "need 384 < N0"),
                                        ("450,576", "must divide by 4"), ("448,577", "must divide by")])
def test_bad_values_are_refused_naming_the_option(value, why):
    with pytest.raises(ConfigError, match=why) as e:
        band_split_for(value, CALIB, "--band-split")
    assert e.value.source == "--band-split"


def test_calibrations_that_cannot_split_are_refused_naming_the_field():
    """No camera_matrix (auto: nothing to place it with); a band at downscale 1; a band whose bottom ends where small
    cones are still under 48 px (a crop ending near the horizon); a camera that sees no cone that large."""
    with pytest.raises(ConfigError, match="camera_matrix"):
        band_split_for("auto", replace(CALIB, camera_matrix=None, mount_pose=None), "band_split")
    with pytest.raises(ConfigError, match="downscale"):
        band_split_for("auto", replace(CALIB, crop=CropSpec(384, 960, 0, 1920, 1)), "band_split")
    with pytest.raises(ConfigError, match="band_split.*too little to run at the coarser scale") as e:
        band_split_for("auto", replace(CALIB, crop=CropSpec(384, 576, 0, 1920, 2)), "band_split")
    assert e.value.source == CALIB.source
    cam = CALIB.pinhole_camera()
    K = cam.K.copy()
    K[0, 0] = K[1, 1] = 20.0  # a fish-eye's worth of pixels: no cone ahead is 48 px tall
    with pytest.raises(ConfigError, match="no cone ahead is 48 px tall"):
        plan_split(type(cam)(K, 1920, 1080, CALIB.mount_pose, cam.dist_coeffs), (384, 960), 2)


class _Recorder:
    """A detector double: records the image shape and crop it was given, returns preset boxes."""

    def __init__(self, boxes):
        self.boxes, self.seen, self.timing, self.iou = boxes, [], {"forward_ms": 1.0}, 0.45

    def detect(self, img, crop):
        self.seen.append((img.shape, crop))
        return self.boxes


def test_split_detector_cuts_scales_and_merges():
    """The upper part gets the band's top rows as they are, the near part its lower rows at half the band's scale;
    a box on an inner edge is a cut cone and dropped; a near box whose foot stands above the upper band's bottom is
    a cone the upper band sees whole (dropped); a cone both still keep is kept once (the upper band's box); each
    part's boxes are its own (full-image px); timing is the sum."""
    s = band_split_for("auto", CALIB)  # upper 384-576, near 448-960: the upper band's feet end at 574 (EDGE_PX 2)
    upper = _Recorder(_boxes([[100, 500, 120, 530, 0.9, 0],      # whole in the upper band: kept
                              [300, 540, 340, 575, 0.8, 1],      # on the upper band's bottom edge (576): cut, dropped
                              [900, 470, 930, 520, 0.7, 2],      # a cone the near band sees too: the upper's kept
                              [500, 530, 530, 573.5, 0.6, 0]]))  # foot just above 574: the upper's
    near = _Recorder(_boxes([[600, 449, 640, 580, 0.9, 0],       # on the near band's top edge (448): cut, dropped
                             [901, 471, 931, 521, 0.8, 2],       # the upper's third cone: its foot above 574, dropped
                             [501, 531, 531, 574.5, 0.65, 1],    # the upper's fourth cone (foot a px lower, another
                                                                 # class at the coarser scale): one cone, the upper's
                             [1000, 700, 1100, 900, 0.95, 1]]))  # a near cone: kept
    det = SplitDetector(upper, near, s)
    band = np.random.default_rng(0).integers(0, 255, (288, 960, 3), dtype=np.uint8)
    out = det.detect(band, CALIB.crop)
    assert upper.seen[0][0] == (96, 960, 3) and upper.seen[0][1] == s.upper
    assert near.seen[0][0] == (128, 480, 3) and near.seen[0][1] == s.near
    got = sorted((float(b["u1"]), round(float(b["score"]), 3)) for b in out)
    assert got == [(100.0, 0.9), (500.0, 0.6), (900.0, 0.7), (1000.0, 0.95)]
    assert det.timing["forward_ms"] == 2.0 and det.iou == 0.45
    assert out.dtype.names == BOX_DTYPE.names


def test_the_near_part_sees_the_quarter_scale_image():
    """The near part's input is the band's lower rows averaged 2x2 (INTER_AREA): a 4x4 block of full-resolution
    pixels per pixel, as the band's 2x2 is of its own."""
    s = band_split_for("auto", CALIB)
    near = _Recorder(np.zeros(0, BOX_DTYPE))
    band = np.zeros((288, 960, 3), np.uint8)
    band[(448 - 384) // 2:, :2] = 200  # the first two band columns (four full-resolution ones) of the near rows
    captured = []
    near.detect = lambda img, crop: captured.append(img.copy()) or np.zeros(0, BOX_DTYPE)
    SplitDetector(_Recorder(np.zeros(0, BOX_DTYPE)), near, s).detect(band, CALIB.crop)
    img = captured[0]
    assert img.shape == (128, 480, 3) and (img[:, 0] == 200).all() and (img[:, 1:] == 0).all()


def test_bench_runs_the_split_and_says_so(capsys):
    assert cli_main(["bench", "pipeline", "--frames", "2", "--warmup", "1", "--scenes", "1", "--far-rows", "none",
                     "--band-split", "auto", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["model_input"] == [960, 96] and "rows 448-960 at 1/4 (480x128)" in r["band_split"]
    assert cli_main(["bench", "pipeline", "--frames", "2", "--band-split", "1,2"]) != 0
    assert "--band-split" in capsys.readouterr().err


def test_thresholds_set_at_run_time_reach_both_parts():
    """The node's conf / iou / max_det, set at run time on the band's detector, apply to both parts."""
    up, near = _Recorder(np.zeros(0, BOX_DTYPE)), _Recorder(np.zeros(0, BOX_DTYPE))
    det = SplitDetector(up, near, band_split_for("auto", CALIB))
    det.conf, det.iou = 0.4, 0.3
    assert (up.conf, near.conf, up.iou, near.iou, det.conf) == (0.4, 0.4, 0.3, 0.3, 0.4)


def test_pipeline_node_band_split_parameter(ros):  # noqa: F811 (ros is a fixture)
    """The node's ``band_split``: auto runs the split detector with the calibration's rows; its boxes are the core
    pipeline's with the same split; a run-time conf reaches both parts; a bad value stops the node naming it."""
    from rclpy.parameter import Parameter

    from cone_perception.bench.frames import rendered_frames
    from cone_perception.detector import default_model_path
    from cone_perception.nodes.pipeline import PipelineNode
    from cone_perception.pipeline import Pipeline

    node = ros.add(PipelineNode(context=ros.context, parameter_overrides=[Parameter("band_split", value="auto"),
                                                                          Parameter("far_rows", value="none")]))
    det = node.pipeline.detector
    assert isinstance(det, SplitDetector) and det.split.near == CropSpec(448, 960, 0, 1920, 4)
    core = Pipeline(CALIB, SplitDetector.load(default_model_path(), band_split_for("auto", CALIB)))
    data = rendered_frames(CALIB, 1)[0]
    a = node.pipeline.process_raw("yuv422_yuy2", 1920, 1080, 3840, data).boxes
    b = core.process_raw("yuv422_yuy2", 1920, 1080, 3840, data).boxes
    assert len(a) == len(b) > 0
    np.testing.assert_allclose(np.sort(a["v2"]), np.sort(b["v2"]), atol=0.05)
    node._set_threshold("conf", 0.5)
    assert det.upper_detector.conf == det.near_detector.conf == 0.5
    with pytest.raises(ConfigError, match="parameter band_split"):
        PipelineNode(context=ros.context, parameter_overrides=[Parameter("band_split", value="1,2")])
    plain = ros.add(PipelineNode(context=ros.context, parameter_overrides=[Parameter("far_rows", value="none")]))
    assert not isinstance(plain.pipeline.detector, SplitDetector)  # the default: one band


def test_a_camera_with_a_lens_splits_like_its_pinhole():
    """A barrel lens (k1 -0.126, the #27 drives' calibrations) was refused ("no cone ahead is 48 px tall"): the
    search started 5 cm ahead, far out of view, where the lens model folds points back. It starts at the nearest
    feet in view; at the image's centre column the lens barely changes the split."""
    cam = CALIB.pinhole_camera()
    lens = type(cam)(cam.K, 1920, 1080, CALIB.mount_pose, np.array([-0.126, 0.0, 0.0, 0.0, 0.0]))
    p, q = plan_split(lens, (368, 1080), 2), plan_split(cam, (368, 1080), 2)
    assert p.upper == q.upper and p.near == q.near and p.split_m == pytest.approx(q.split_m, rel=0.02)


def test_detect_and_replay_refuse_a_split_they_cannot_run(tmp_path, capsys):
    """``detect --band-split auto`` needs --calib, a hand-set split needs the band (--crop or --calib); ``replay
    --live`` runs the band in one piece: each refused naming --band-split, before any model loads."""
    out = str(tmp_path / "p.jsonl")
    assert cli_main(["detect", str(tmp_path), "--out", out, "--band-split", "auto"]) != 0
    assert "auto needs --calib" in capsys.readouterr().err
    assert cli_main(["detect", str(tmp_path), "--out", out, "--band-split", "448,576"]) != 0
    assert "needs --crop or --calib" in capsys.readouterr().err
    assert cli_main(["replay", str(tmp_path / "bag"), "--live", "fused", "--band-split", "auto"]) != 0
    assert "--band-split" in capsys.readouterr().err
