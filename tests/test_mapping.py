"""Mapping core: composed homography, sign, foot points, horizon and range cuts, covariance."""

from __future__ import annotations

import numpy as np
import pytest

from cone_perception.classes import BLUE, CLASS_NAMES, LARGE_ORANGE, ORANGE, UNKNOWN, YELLOW
from cone_perception.crop import CropSpec
from cone_perception.errors import FrameError
from cone_perception.geometry import GroundMapper, apply_homography, fix_homography_sign
from cone_perception.geometry.calib import DEFAULT_FOOT_POINTS, Calibration, load_calibration
from cone_perception.geometry.camera import MountPose, PinholeCamera, default_intrinsics
from cone_perception.mapping import ConeMapper
from cone_perception.records import CONE_DTYPE, boxes_from_arrays

CAM = PinholeCamera(default_intrinsics(1920, 1080, 90.0), 1920, 1080, MountPose())


def _calib(H_S_B, T_F_S, **kw) -> Calibration:
    return Calibration(
        camera="test",
        image_width=1920,
        image_height=1080,
        H_S_B=np.asarray(H_S_B, float),
        T_F_S=np.asarray(T_F_S, float),
        crop=CropSpec(384, 960, 0, 1920, 2),
        foot_points=tuple(DEFAULT_FOOT_POINTS[n] for n in CLASS_NAMES),
        **kw,
    )


def test_composed_homography_against_hand_computation() -> None:
    # A made-up H_S_B and the thesis's pure x offset T_F_S (board 2.5 m ahead of the rear axle).
    H_S_B = np.array([[0.004, 0.0, -3.84], [0.0, 0.01, -8.0], [0.0, 0.0015, -0.4]])
    T_F_S = np.array([[1.0, 0.0, 2.5], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    c = _calib(H_S_B, T_F_S)
    u, v = 1000.0, 900.0
    # by hand: w = 0.0015*900 - 0.4 = 0.95; x_S = (4 - 3.84)/0.95; y_S = (9 - 8)/0.95
    w = 0.0015 * v - 0.4
    x_s, y_s = (0.004 * u - 3.84) / w, (0.01 * v - 8.0) / w
    xy, w_out = apply_homography(c.H_F_B, np.array([[u, v]]))
    np.testing.assert_allclose(xy[0], [x_s + 2.5, y_s], rtol=1e-12)
    assert w_out[0] > 0


def test_sign_is_fixed_when_findhomography_scale_leaves_w_negative() -> None:
    H = CAM.H_F_B()
    H_neg = -H  # the same homography (scale -1): w < 0 on every ground pixel
    assert apply_homography(H_neg, np.array([[960.0, 1079.0]]))[1][0] < 0
    fixed = fix_homography_sign(H_neg, (960.0, 1079.0))
    m = GroundMapper(fixed, 50.0)
    uv, _ = CAM.project(np.array([[8.0, 1.0, 0.0]]))
    xy, valid = m.map_pixels(uv)
    assert valid[0]
    np.testing.assert_allclose(xy[0], [8.0, 1.0], atol=1e-9)


def test_example_calibration_maps_projected_ground_points_back() -> None:
    c = load_calibration("example_mainhoop")
    pts = np.array([[x, y, 0.0] for x in (3.0, 5.0, 10.0, 20.0, 29.0) for y in (-4.0, 0.0, 3.0)])
    uv, _ = CAM.project(pts)
    xy, valid = GroundMapper(c.H_F_B, c.max_range_m).map_pixels(uv)
    assert valid.all()
    np.testing.assert_allclose(xy, pts[:, :2], atol=1e-6)


def test_horizon_and_range_cuts() -> None:
    m = GroundMapper(CAM.H_F_B(), max_range_m=20.0)
    horizon = CAM.horizon_v()
    uv_near, _ = CAM.project(np.array([[10.0, 0.0, 0.0]]))
    uv_far, _ = CAM.project(np.array([[25.0, 0.0, 0.0]]))
    px = np.array([[960.0, horizon - 50.0], [960.0, horizon - 0.5], uv_near[0], uv_far[0]])
    xy, valid = m.map_pixels(px)
    assert valid.tolist() == [False, False, True, False]
    assert np.isnan(xy[~valid]).all()
    np.testing.assert_allclose(xy[2], [10.0, 0.0], atol=1e-9)


def test_foot_point_per_class() -> None:
    mapper = ConeMapper(_calib(np.linalg.inv(CAM.H_B_F()), np.eye(3)))  # the thesis's rules (defaults)
    box = [100.0, 500.0, 140.0, 560.0]
    recs = boxes_from_arrays(np.array([box] * 5), np.full(5, 0.9), [BLUE, YELLOW, ORANGE, LARGE_ORANGE, UNKNOWN])
    fp = mapper.foot_points(recs)  # pixel-centre coordinates: box edges - 0.5
    np.testing.assert_allclose(fp, np.array([[140, 560], [100, 560], [120, 560], [120, 560], [120, 560]]) - 0.5)


def test_foot_point_rule_is_configurable() -> None:
    rules = list(DEFAULT_FOOT_POINTS[n] for n in CLASS_NAMES)
    rules[BLUE] = "bottom_center"
    c = _calib(np.linalg.inv(CAM.H_B_F()), np.eye(3))
    c.foot_points = tuple(rules)
    recs = boxes_from_arrays(np.array([[100.0, 500.0, 140.0, 560.0]]), [0.9], [BLUE])
    np.testing.assert_allclose(ConeMapper(c).foot_points(recs), [[119.5, 559.5]])


def test_map_boxes_positions_classes_scores_and_cuts() -> None:
    c = _calib(np.linalg.inv(CAM.H_B_F()), np.eye(3), max_range_m=25.0)
    mapper = ConeMapper(c)
    # blue cone at (6, 1.8): its foot (box bottom-right) projects from that ground point
    truth = np.array([[6.0, 1.8, 0.0], [12.0, -1.7, 0.0], [40.0, 0.0, 0.0]])
    uv, _ = CAM.project(truth)
    uv = uv + 0.5  # pixel-centre projection -> pixel-edge box coordinates
    boxes = np.array(
        [
            [uv[0, 0] - 30, uv[0, 1] - 60, uv[0, 0], uv[0, 1]],  # blue: bottom-right = foot
            [uv[1, 0], uv[1, 1] - 30, uv[1, 0] + 15, uv[1, 1]],  # yellow: bottom-left = foot
            [uv[2, 0] - 2, uv[2, 1] - 5, uv[2, 0] + 2, uv[2, 1]],  # beyond range -> dropped
            [900, 100, 920, 150],  # above the horizon -> dropped
        ]
    )
    recs = boxes_from_arrays(boxes, [0.9, 0.8, 0.7, 0.6], [BLUE, YELLOW, ORANGE, ORANGE])
    cones = mapper.map_boxes(recs)
    assert cones.dtype == CONE_DTYPE and cones.shape == (2,)
    np.testing.assert_allclose(np.c_[cones["x"], cones["y"]], truth[:2, :2], atol=1e-4)
    assert cones["class_id"].tolist() == [BLUE, YELLOW]
    np.testing.assert_allclose(cones["score"], [0.9, 0.8], rtol=1e-6)
    assert (cones["z"] == 0).all()


def test_covariance_matches_finite_differences_and_grows_with_range() -> None:
    su, sv = 1.5, 2.0
    m = GroundMapper(CAM.H_F_B(), 50.0, (su, sv))
    uv, _ = CAM.project(np.array([[4.0, 1.0, 0.0], [10.0, -2.0, 0.0], [25.0, 3.0, 0.0]]))
    cov = m.covariance(uv)
    eps = 1e-3
    for k in range(uv.shape[0]):
        J = np.empty((2, 2))
        for j in range(2):
            d = np.zeros(2)
            d[j] = eps
            J[:, j] = (m.map_pixels(uv[k : k + 1] + d)[0][0] - m.map_pixels(uv[k : k + 1] - d)[0][0]) / (2 * eps)
        np.testing.assert_allclose(cov[k], J @ np.diag([su**2, sv**2]) @ J.T, rtol=1e-5)
        assert np.all(np.linalg.eigvalsh(cov[k]) > 0)
    # the far cone's longitudinal variance is much larger than the near one's
    assert cov[2, 0, 0] > 20 * cov[0, 0, 0]


def test_lens_distortion_is_undone_on_foot_points() -> None:
    dist = np.array([-0.28, 0.08, 0.0, 0.0, 0.0])
    cam = PinholeCamera(CAM.K, 1920, 1080, MountPose(), dist)
    pts = np.array([[5.0, 3.0, 0.0], [15.0, -6.0, 0.0], [8.0, 0.0, 0.0]])
    uv, _ = cam.project(pts)
    plain = GroundMapper(cam.H_F_B(), 50.0)
    lens = GroundMapper(cam.H_F_B(), 50.0, camera_matrix=cam.K, dist_coeffs=dist)
    xy_plain, _ = plain.map_pixels(uv)
    xy_lens, _ = lens.map_pixels(uv)
    np.testing.assert_allclose(xy_lens, pts[:, :2], atol=1e-3)
    assert np.abs(xy_plain - pts[:, :2]).max() > 0.3  # without the lens model it is far off
    np.testing.assert_allclose(lens.ground_to_pixels(pts[:, :2]), uv, atol=1e-3)  # and back to raw pixels


@pytest.mark.parametrize(
    "box,cls,reason",
    [
        ([np.nan, 1, 2, 3], 0, "bad_box"),
        ([10, 1, 5, 3], 0, "bad_box"),
        ([1, 10, 5, 3], 0, "bad_box"),
        ([1, 1, 5, 3], 7, "bad_class"),
    ],
)
def test_bad_boxes_drop_the_frame(box, cls, reason) -> None:
    mapper = ConeMapper(load_calibration("example_mainhoop"))
    recs = boxes_from_arrays(np.array([[100, 500, 120, 560], box], dtype=np.float32), [0.5, 0.5], [0, cls])
    with pytest.raises(FrameError) as e:
        mapper.map_boxes(recs)
    assert e.value.reason == reason


def test_no_boxes_no_cones() -> None:
    mapper = ConeMapper(load_calibration("example_mainhoop"))
    assert mapper.map_boxes(boxes_from_arrays(np.zeros((0, 4)), [], [])).shape == (0,)


def _boxes(rows):
    """rows of (u1, v1, u2, v2, score, class_id) -> BOX_DTYPE records."""
    a = np.asarray(rows, float).reshape(-1, 6)
    return boxes_from_arrays(a[:, :4], a[:, 4], a[:, 5].astype(int))


def test_one_box_per_cone_drops_the_weaker_class_of_one_spot_only() -> None:
    """Issue 26g: the detector's NMS is per class, so a far cone came out as a blue and a yellow box on one spot
    (two cones on /cones, one false). Of boxes of different classes overlapping at IoU >= 0.6 the better-scored
    stays; one class's boxes, other classes overlapping less, and the order are left alone."""
    from cone_perception.mapping import CROSS_CLASS_IOU, box_iou, one_box_per_cone

    b = _boxes([[100, 400, 110, 420, 0.40, YELLOW],   # the weaker class of the blue cone below: goes
                [300, 400, 320, 440, 0.70, BLUE],     # another blue box of the cone at 300: one class, kept (NMS's)
                [100, 401, 110, 421, 0.55, BLUE],     # IoU 0.9 with the first
                [302, 400, 322, 440, 0.90, BLUE],
                [500, 400, 510, 420, 0.80, BLUE],
                [500, 407, 510, 427, 0.60, YELLOW]])  # IoU 13/27 = 0.48 < 0.6: two cones, kept
    assert CROSS_CLASS_IOU == 0.6
    assert box_iou(b[:1], b[2:3])[0, 0] == pytest.approx(19 / 21)
    out = one_box_per_cone(b)
    np.testing.assert_array_equal(out["score"], np.array([0.70, 0.55, 0.90, 0.80, 0.60], np.float32))
    # a chain: a box suppressed by a better one suppresses nothing itself
    c = _boxes([[0, 0, 10, 20, 0.9, BLUE], [0, 3, 10, 23, 0.8, YELLOW], [0, 6, 10, 26, 0.7, BLUE]])
    assert box_iou(c[:1], c[2:3])[0, 0] < 0.6 <= box_iou(c[1:2], c[2:3])[0, 0]
    np.testing.assert_array_equal(one_box_per_cone(c)["score"], np.array([0.9, 0.7], np.float32))
    assert len(one_box_per_cone(b[:0])) == 0 and len(one_box_per_cone(b[:1])) == 1


def test_pipeline_maps_one_cone_for_a_cone_boxed_in_two_classes() -> None:
    """The fused pipeline keeps one box per spot before the attitude and the mapping: a detector that boxes a cone
    as blue 0.8 and yellow 0.5 gives one blue cone (and one box); without the yellow box the same cone."""
    from cone_perception.pipeline import Pipeline

    calib = load_calibration("example_mainhoop")

    class TwoClasses:
        timing: dict = {}

        def __init__(self, rows):
            self.rows = rows

        def detect(self, band, crop):
            return _boxes(self.rows)

    one = [[950, 600, 980, 640, 0.8, BLUE]]
    frame = np.zeros((1080, 1920, 3), np.uint8).tobytes()
    a = Pipeline(calib, TwoClasses(one + [[951, 601, 981, 641, 0.5, YELLOW]]), "fixed").process_raw("bgr8", 1920, 1080, 5760, frame)
    b = Pipeline(calib, TwoClasses(one), "fixed").process_raw("bgr8", 1920, 1080, 5760, frame)
    assert len(a.boxes) == 1 and len(a.cones) == 1 and int(a.cones["class_id"][0]) == BLUE
    np.testing.assert_allclose([a.cones["x"][0], a.cones["y"][0]], [b.cones["x"][0], b.cones["y"][0]])


def test_one_box_per_cone_drops_a_much_weaker_small_box_of_one_class_on_one_far_cone() -> None:
    """Issue 26g: the strip's NMS (IoU 0.45) left two boxes of one 10 px far cone, shifted by 3-4 px (IoU about
    0.35). A small box of the same class overlapping a better one at IoU >= 0.3 and scored under 0.6x of it goes;
    a box scored nearly as well (a neighbouring cone of the row), a big box, or one overlapping less stays."""
    from cone_perception.mapping import SMALL_BOX_PX, SMALL_SAME_IOU, SMALL_WEAKER, box_iou, one_box_per_cone

    assert (SMALL_BOX_PX, SMALL_SAME_IOU, SMALL_WEAKER) == (16.0, 0.3, 0.6)
    b = _boxes([[100, 400, 110, 410, 0.80, BLUE],
                [103, 401, 113, 411, 0.40, BLUE],     # IoU 63/137 = 0.46 but 0.5x: the second box of the cone above
                [300, 400, 310, 410, 0.80, BLUE],
                [303, 401, 313, 411, 0.60, BLUE],     # 0.75x: another cone of the row, kept
                [500, 400, 520, 420, 0.80, BLUE],
                [506, 402, 526, 422, 0.40, BLUE],     # 20 px tall: left to the NMS
                [700, 400, 710, 410, 0.80, BLUE],
                [706, 401, 716, 411, 0.30, BLUE]])    # IoU 36/164 = 0.22: kept
    assert box_iou(b[6:7], b[7:8])[0, 0] < 0.3 <= box_iou(b[:1], b[1:2])[0, 0]
    np.testing.assert_array_equal(one_box_per_cone(b)["score"], np.array([0.8, 0.8, 0.6, 0.8, 0.4, 0.8, 0.3], np.float32))
    assert len(one_box_per_cone(b, small_weaker=0.0)) == len(b)  # the small rule off


def test_one_box_per_cone_drops_a_box_of_a_part_of_a_taller_box_cone() -> None:
    """Issue 41: the upper half of a large orange cone that another cone overlaps got a box of its own (the start
    line of the held-out-like camera: a second cone 1-2 m behind the true one). A box lying inside a taller box (at
    least 32 px), at most 0.8x as tall, its top at that box's top (within 15 % of its height), goes whatever the
    classes while the taller box scores at least 0.6x its score. A far cone behind a near one stands with its top
    above the near cone's (flat ground), so its box is not taken; nor is a part that outscores the tall box
    1/0.6-fold, or a part of a box under 32 px (two boxes of one far cone: the shorter is as often the better)."""
    from cone_perception.mapping import (PART_INSIDE, PART_MAX_HEIGHT, PART_MIN_PX, PART_TOP_FRAC, PART_WEAKER,
                                         one_box_per_cone, part_of)

    assert (PART_INSIDE, PART_MAX_HEIGHT, PART_TOP_FRAC, PART_MIN_PX, PART_WEAKER) == (0.8, 0.8, 0.15, 32.0, 0.6)
    b = _boxes([[100, 400, 160, 500, 0.50, 3],      # a large orange cone, 100 px
                [110, 402, 150, 460, 0.60, 2],      # its top 58 %, another class: a part, goes
                [300, 400, 360, 500, 0.50, 3],
                [312, 430, 348, 480, 0.60, 3],      # inside but its top 30 px lower: kept
                [500, 400, 560, 500, 0.30, 3],
                [510, 400, 550, 460, 0.60, 3],      # a part scored 2x the tall box (0.3 < 0.6 x 0.6): kept
                [700, 400, 720, 430, 0.50, 0],      # 30 px: too small to judge
                [703, 400, 717, 420, 0.45, 0],      # kept
                [900, 400, 960, 500, 0.50, 3],
                [905, 401, 955, 487, 0.45, 3]])     # 0.86x as tall: a second box, left to the NMS
    xyxy = np.c_[b["u1"], b["v1"], b["u2"], b["v2"]]
    assert part_of(xyxy)[0, 1] and not part_of(xyxy)[1, 0]
    out = one_box_per_cone(b)
    assert sorted(out["u1"].tolist()) == [100, 300, 312, 500, 510, 700, 703, 900, 905]
    assert len(one_box_per_cone(b, part_inside=2.0)) == len(b)  # the part rule off


def _cone_box(mapper, xy, cls, scale=1.0, score=0.4):
    """The box of a cone of class ``cls`` standing at ``xy`` (m): its foot where the mapping expects it, its height
    the image fit's cone model's (``scale`` x: a lower box) and as wide as tall."""
    foot = mapper.box_foot_of(np.array([xy], float), np.array([cls]))[0]
    h = scale * mapper.image_attitude().model_heights(np.array([xy], float), np.array([cls]))[0]
    u1, u2 = mapper.box_u_range(np.array([foot[0]]), np.array([h]), np.array([cls]))
    return [float(u1[0]), foot[1] - h, float(u2[0]), foot[1], score, cls]


def test_a_box_too_low_for_a_cone_where_its_foot_maps_is_dropped_and_counted() -> None:
    """Issue 26: a worn line painted on the ground was taken for yellow cones. A mark on the ground is flat: its box
    is lower than a cone standing at the range its foot row gives (0.70x, median, on the rendered drives). A box of
    a cone's height has the ratio 1 and is kept at any range; one 0.6x as tall goes with min_height_ratio 0.8 (counted
    as flat) when it scores under FLAT_MAX_SCORE, not with the gate off; the ratio is not known for a class of
    unknown size (kept)."""
    from cone_perception.mapping import DROP_CAUSES, FLAT_MAX_SCORE

    calib = load_calibration("example_mainhoop")
    off, on = ConeMapper(calib), ConeMapper(calib, 0.8)
    rows = [_cone_box(on, (d, 1.0), YELLOW) for d in (5.0, 12.0, 25.0)] + [_cone_box(on, (12.0, -1.5), BLUE, 0.6)]
    rows.append(_cone_box(on, (20.0, -1.5), ORANGE, 0.6, FLAT_MAX_SCORE))  # as low, but the detector is sure: kept
    b = _boxes(rows)
    xy = off.map_boxes(b)
    r = on.height_ratios(b, np.c_[xy["x"], xy["y"]])
    np.testing.assert_allclose(r, [1.0, 1.0, 1.0, 0.6, 0.6], atol=0.03)
    assert len(off.map_boxes(b)) == 5 and off.dropped == dict.fromkeys(DROP_CAUSES, 0)
    kept = on.map_boxes(b)
    assert len(kept) == 4 and set(kept["class_id"].tolist()) == {YELLOW, ORANGE}
    assert on.dropped == {"second_box": 0, "off_ground": 0, "flat": 1, "one_ray": 0}
    u = _boxes([rows[3][:5] + [UNKNOWN]])
    assert np.isnan(on.height_ratios(u, np.array([[12.0, -1.5]])))[0] and len(on.map_boxes(u)) == 1
    on.map_boxes(_boxes([[900, 100, 920, 120, 0.5, BLUE]]))  # above the horizon: counted off the ground
    assert on.dropped["off_ground"] == 1 and on.dropped["flat"] == 1


def test_the_height_gate_cannot_act_without_a_mount_pose_and_refuses_a_bad_ratio() -> None:
    import dataclasses

    calib = load_calibration("example_mainhoop")
    flat = _boxes([_cone_box(ConeMapper(calib), (12.0, 0.0), BLUE, 0.5)])
    bare = ConeMapper(dataclasses.replace(calib, mount_pose=None), 0.8)
    assert np.isnan(bare.height_ratios(flat, np.array([[12.0, 0.0]])))[0]
    assert len(bare.map_boxes(flat)) == 1 and bare.dropped["flat"] == 0
    for bad in (1.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="min_height_ratio"):
            ConeMapper(calib, bad)


def test_pipeline_drops_flat_boxes_by_default_and_counts_every_dropped_box() -> None:
    """The fused pipeline runs the gate at the parameter's default; its mapper counts the second boxes of a cone
    (one_box_per_cone) and the flat ones; min_height_ratio 0 turns the gate off."""
    from cone_perception.params import PARAMS
    from cone_perception.pipeline import Pipeline

    calib = load_calibration("example_mainhoop")
    m = ConeMapper(calib)
    cone = _cone_box(m, (10.0, 1.0), BLUE, 1.0, 0.8)
    rows = [cone, cone[:4] + [0.5, YELLOW], _cone_box(m, (14.0, -1.0), YELLOW, 0.6, 0.4)]

    class Fixed:
        timing: dict = {}

        def detect(self, band, crop):
            return _boxes(rows)

    frame = np.zeros((1080, 1920, 3), np.uint8).tobytes()
    p = Pipeline(calib, Fixed(), "fixed")
    assert p.mapper.min_height_ratio == PARAMS["min_height_ratio"].default > 0.6
    r = p.process_raw("bgr8", 1920, 1080, 5760, frame)
    assert len(r.cones) == 1 and int(r.cones["class_id"][0]) == BLUE
    assert p.mapper.dropped == {"second_box": 1, "off_ground": 0, "flat": 1, "one_ray": 0}
    q = Pipeline(calib, Fixed(), "fixed", min_height_ratio=0.0)
    assert len(q.process_raw("bgr8", 1920, 1080, 5760, frame).cones) == 2 and q.mapper.dropped["flat"] == 0


def _cones(rows):
    """rows of (x, y, score, class_id) -> CONE_DTYPE records with a covariance of 0.5 m along x, 0.1 m along y."""
    out = np.zeros(len(rows), CONE_DTYPE)
    for k, (x, y, s, c) in enumerate(rows):
        out[k]["x"], out[k]["y"], out[k]["score"], out[k]["class_id"] = x, y, s, c
        out[k]["cov_xx"], out[k]["cov_yy"] = 0.25, 0.01
    return out


def test_one_cone_per_ray_makes_one_cone_of_two_boxes_of_one_far_cone_only() -> None:
    """Issue 26 (session 15): two boxes of one far cone a few pixels apart map about 1.5 m apart along the viewing
    ray, on one bearing. Such a pair of one class becomes one cone (the better-scored, its covariance stretched to
    cover the other); two cones of a row 4 m apart along the ray, a pair off the ray, and two classes stay."""
    from cone_perception.mapping import one_cone_per_ray

    cam = np.array([1.0, 0.0])
    c = _cones([(31.0, 0.0, 0.45, BLUE),     # 1.5 m behind the cone below, on its ray: the same cone
                (29.5, 0.0, 0.70, BLUE),
                (21.0, 5.0, 0.60, YELLOW),   # a row pointing at the camera: 4 m apart along the ray, both stay
                (17.0, 4.0, 0.65, YELLOW),
                (30.0, 3.0, 0.70, BLUE),     # 1.5 m apart along x but 0.6 m off the ray (bearing): two cones
                (31.5, 3.6, 0.40, BLUE),
                (16.0, -3.0, 0.70, BLUE),    # one spot, two classes: not this rule's (one_box_per_cone's)
                (17.0, -3.2, 0.40, YELLOW)])
    out, keep = one_cone_per_ray(c, cam, across_m=0.2, along_m=2.5, mode="keep")
    np.testing.assert_array_equal(keep, [False, True, True, True, True, True, True, True])
    assert len(out) == 7 and out["score"][0] == pytest.approx(0.70)
    assert (out["x"][0], out["y"][0]) == (pytest.approx(29.5), pytest.approx(0.0))
    # its covariance covers both positions: the other one within one sigma along the ray, across unchanged
    d = np.array([31.0 - 29.5, 0.0])
    cov = np.array([[out["cov_xx"][0], out["cov_xy"][0]], [out["cov_xy"][0], out["cov_yy"][0]]])
    assert d @ np.linalg.solve(cov, d) <= 1.0
    assert out["cov_yy"][0] == pytest.approx(0.01)
    np.testing.assert_array_equal(out[1:], c[2:])  # the others untouched, in order
    # any_class (the mapper's): the two classes on one spot are one cone too, the better-scored's class
    np.testing.assert_array_equal(one_cone_per_ray(c, cam, 0.2, 2.5, cross_class_from_m=0.0)[1],
                                  [False, True, True, True, True, True, True, False])
    # two classes only from cross_class_from_m on: the pair's better cone stands 15.3 m from the camera
    assert one_cone_per_ray(c, cam, 0.2, 2.5, cross_class_from_m=16.0)[1][7]
    assert not one_cone_per_ray(c, cam, 0.2, 2.5, cross_class_from_m=15.0)[1][7]
    # the rule off (across 0), a single cone, none
    assert one_cone_per_ray(c, cam, 0.0, 2.5)[1].all()
    assert len(one_cone_per_ray(c[:1], cam, 0.2, 2.5)[0]) == 1 and len(one_cone_per_ray(c[:0], cam, 0.2, 2.5)[0]) == 0
    # farther apart than along_m: two cones; a share of the range instead (0.06 x 29.5 m = 1.77 m): one
    assert one_cone_per_ray(c, cam, 0.2, 1.0)[1].all()
    assert not one_cone_per_ray(c, cam, 0.2, 1.0, along_frac=0.06)[1][0]


def test_one_cone_per_ray_merge_places_the_cone_at_the_score_weighted_mean() -> None:
    """``merge``: the pair's score-weighted mean position and the mixture's covariance (its own plus the spread);
    ``drop``: the better cone as it was. A bad mode is refused, naming it."""
    from cone_perception.mapping import one_cone_per_ray

    c = _cones([(31.0, 0.0, 0.25, BLUE), (29.5, 0.0, 0.75, BLUE)])
    out, _ = one_cone_per_ray(c, np.zeros(2), 0.2, 2.5, mode="merge")
    assert len(out) == 1 and out["x"][0] == pytest.approx(0.25 * 31.0 + 0.75 * 29.5)
    assert out["cov_xx"][0] == pytest.approx(0.25 + 0.25 * 0.75 * 1.5 ** 2, rel=1e-6)
    assert out["cov_yy"][0] == pytest.approx(0.01) and out["cov_xy"][0] == pytest.approx(0.0)
    out, _ = one_cone_per_ray(c, np.zeros(2), 0.2, 2.5, mode="drop")
    np.testing.assert_array_equal(out, c[1:])
    with pytest.raises(ValueError, match="mode"):
        one_cone_per_ray(c, np.zeros(2), 0.2, 2.5, mode="mean")


def test_the_mapper_and_the_pipeline_make_one_cone_of_two_boxes_of_a_far_cone_on_one_ray() -> None:
    """Two boxes of one far cone 2 px apart in foot row (scores 0.7 and 0.45: one_box_per_cone keeps both) map under 2 m
    apart along one viewing ray: with one_ray_range_m (the pipeline's default) one cone, the better-scored, and
    one_ray counted; off, two. Two cones of one row 4 m apart on one ray stay two; so does the pair beyond the range."""
    from cone_perception.params import PARAMS
    from cone_perception.pipeline import Pipeline

    calib = load_calibration("example_mainhoop")
    off = ConeMapper(calib)
    cam = calib.camera_ground_xy()
    far = _cone_box(off, (30.0, 1.0), BLUE, 1.0, 0.7)
    twice = [far, [far[0], far[1] + 2, far[2], far[3] + 2, 0.45, BLUE]]
    c = off.map_boxes(_boxes(twice))
    d = np.hypot(c["x"][1] - c["x"][0], c["y"][1] - c["y"][0])
    assert len(c) == 2 and 0.5 < d < 2.0  # the precondition: nearer, on one bearing, under 2 m along the ray
    near = np.array([18.0, -2.0])
    behind = cam + (near - cam) * (1 + 4.0 / np.hypot(*(near - cam)))  # 4 m behind it on its ray
    row = [_cone_box(off, tuple(near), YELLOW, 1.0, 0.6), _cone_box(off, tuple(behind), YELLOW, 1.0, 0.6)]
    on = ConeMapper(calib, 0.0, PARAMS["one_ray_range_m"].default)
    out = on.map_boxes(_boxes(twice + row))
    assert len(out) == 3 and on.dropped["one_ray"] == 1
    assert out["score"][0] == pytest.approx(0.7) and (out["x"][0], out["y"][0]) == (c["x"][0], c["y"][0])
    assert out["cov_xx"][0] + out["cov_yy"][0] > c["cov_xx"][0] + c["cov_yy"][0] + 0.5 * d ** 2
    assert len(ConeMapper(calib, 0.0, 25.0).map_boxes(_boxes(twice))) == 2  # the better one beyond 25 m: left alone
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="one_ray_range_m"):
            ConeMapper(calib, 0.0, bad)

    class Fixed:
        timing: dict = {}

        def detect(self, band, crop):
            return _boxes(twice)

    frame = np.zeros((1080, 1920, 3), np.uint8).tobytes()
    p = Pipeline(calib, Fixed(), "fixed")
    r = p.process_raw("bgr8", 1920, 1080, 5760, frame)
    assert len(r.boxes) == 2 and len(r.cones) == 1 and p.mapper.dropped["one_ray"] == 1
    q = Pipeline(calib, Fixed(), "fixed", one_ray_range_m=0.0)
    assert len(q.process_raw("bgr8", 1920, 1080, 5760, frame).cones) == 2
