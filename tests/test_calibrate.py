"""Calibration core: a chessboard rendered on the ground through a known camera must give back that
camera's ground homography; bad point sets must be refused with a clear message."""

from __future__ import annotations

import numpy as np
import pytest

from cone_perception.calibrate import (
    Board, Intrinsics, PointPairs, board_pairs, calibrate_intrinsics, detect_board, estimate_homography,
    fit_calibration, from_pose, planar_transform, pose_from_homography, quality_report, read_points_csv,
)
from cone_perception.errors import ConfigError
from cone_perception.geometry import apply_homography, undistort_pixels
from cone_perception.geometry.camera import MountPose, PinholeCamera, default_intrinsics

from _board_scene import board_texture, render_on_ground, render_views

W, H = 1920, 1080
BOARD = (9, 6)
SQUARE_M = 0.2
BOARD_X_M = 4.0  # board centre ahead of the rear axle; S = board frame, so T_F_S = shift by 4 m
DIST = np.array([-0.25, 0.07, 0.0005, -0.0003, -0.01])  # strong barrel distortion, wide-angle-like


def _camera(dist: np.ndarray | None = None) -> PinholeCamera:
    return PinholeCamera(default_intrinsics(W, H, 90.0), W, H, MountPose(), np.zeros(0) if dist is None else dist)


def _cone_pairs(cam: PinholeCamera, xy_F: np.ndarray) -> PointPairs:
    """Extra reference points (cones at measured spots), clicked exactly at their raw pixel."""
    uv, _ = cam.project(np.column_stack([xy_F, np.zeros(len(xy_F))]))
    xy_S = xy_F - [BOARD_X_M, 0.0]
    return PointPairs(uv, xy_S, [f"cone{i}" for i in range(len(xy_F))], np.zeros(len(xy_F), bool))


CONES_F = np.array([[x, y] for x in (7.0, 10.0, 13.0) for y in (-3.0, 3.0)] + [[5.0, -4.5], [5.0, 4.5]])


def _ground_errors(cam: PinholeCamera, res, max_x_m: float = 10.0) -> np.ndarray:
    """|H_F_B(pixel) - truth| (m) for ground points 2..max_x m ahead, |y| <= 4 m, that the camera sees."""
    xy = np.array([[x, y] for x in np.arange(2.0, max_x_m + 1e-9, 0.5) for y in np.arange(-4.0, 4.01, 0.5)])
    ideal, _ = PinholeCamera(cam.K, W, H, cam.pose).project(np.column_stack([xy, np.zeros(len(xy))]))
    seen = (ideal[:, 0] >= 0) & (ideal[:, 0] < W) & (ideal[:, 1] >= 0) & (ideal[:, 1] < H)
    raw, _ = cam.project(np.column_stack([xy[seen], np.zeros(seen.sum())]))
    mapped, w = apply_homography(res.H_F_B, res.undistort(raw))
    assert np.all(w > 0)
    assert seen.sum() > 150
    return np.linalg.norm(mapped - xy[seen], axis=1)


@pytest.fixture(scope="module")
def scene():
    cam = _camera()
    img = render_on_ground(cam, board_texture(*BOARD, 40), SQUARE_M / 40, BOARD_X_M)
    corners = detect_board(img, BOARD)
    assert corners is not None
    return cam, img, corners


@pytest.fixture(scope="module")
def scene_distorted():
    cam = _camera(DIST)
    img = render_on_ground(cam, board_texture(*BOARD, 40), SQUARE_M / 40, BOARD_X_M)
    corners = detect_board(img, BOARD)
    assert corners is not None
    return cam, img, corners


def test_board_corners_found_where_the_camera_puts_them(scene):
    cam, _, corners = scene
    T = planar_transform(BOARD_X_M)
    pairs = board_pairs(corners, Board(*BOARD, SQUARE_M), T)
    xy_F = pairs.xy_S + [BOARD_X_M, 0.0]
    truth, _ = cam.project(np.column_stack([xy_F, np.zeros(len(xy_F))]))
    err = np.linalg.norm(pairs.uv_px - truth, axis=1)
    assert err.max() < 1.0  # sub-pixel; orientation resolved correctly (a wrong one is off by many px)
    assert np.abs(pairs.xy_S).max() == pytest.approx(0.8)  # 9 corners * 0.2 m: +-0.8 m along x


def test_board_orientation_does_not_depend_on_corner_order(scene):
    _, _, corners = scene
    T = planar_transform(BOARD_X_M)
    ref = board_pairs(corners, Board(*BOARD, SQUARE_M), T)
    grid = corners.reshape(BOARD[1], BOARD[0], 2)
    for other, size in (
        (grid[::-1, ::-1], BOARD),  # detector started at the opposite corner
        (grid.transpose(1, 0, 2), BOARD[::-1]),  # board given as 6x9
        (grid[:, ::-1].transpose(1, 0, 2), BOARD[::-1]),
    ):
        pairs = board_pairs(other.reshape(-1, 2), Board(*size, SQUARE_M), T)
        order = [np.flatnonzero(np.all(ref.uv_px == p, axis=1))[0] for p in pairs.uv_px]
        np.testing.assert_allclose(pairs.xy_S, ref.xy_S[order], atol=1e-12)


def test_board_plus_cones_maps_ground_within_1cm_to_10m(scene):
    cam, _, corners = scene
    T = planar_transform(BOARD_X_M)
    pairs = board_pairs(corners, Board(*BOARD, SQUARE_M), T) + _cone_pairs(cam, CONES_F)
    res = fit_calibration(pairs, W, H, T)
    assert res.inliers.all()
    err = _ground_errors(cam, res)
    assert err.max() < 0.01, f"max ground error {err.max():.4f} m"


def test_board_alone_warns_that_far_field_and_edges_are_not_covered(scene):
    cam, _, corners = scene
    T = planar_transform(BOARD_X_M)
    res = fit_calibration(board_pairs(corners, Board(*BOARD, SQUARE_M), T), W, H, T)
    rep = quality_report(res, far_m=10.0)
    text = " ".join(rep["warnings"])
    assert "far field not covered" in text and "LEFT" in text and "RIGHT" in text
    assert rep["rms_reproj_px"] < 0.5
    assert rep["coverage"]["max_x_m"] == pytest.approx(4.8)
    # the one-pixel error grows with distance and matches the camera's own Jacobian at 10 m
    d = [r["m_per_px_v"] for r in rep["one_px_error"]]
    assert all(a < b for a, b in zip(d, d[1:]))
    uv10, _ = cam.project(np.array([[10.0, 0.0, 0.0]]))
    eps = 0.5
    a, _ = apply_homography(cam.H_F_B(), uv10 + [0, eps])
    b, _ = apply_homography(cam.H_F_B(), uv10 - [0, eps])
    assert d[1] == pytest.approx(np.linalg.norm(a - b) / (2 * eps), rel=0.1)


def test_outliers_are_rejected(scene):
    cam, _, corners = scene
    T = planar_transform(BOARD_X_M)
    cones = _cone_pairs(cam, CONES_F)
    bad = _cone_pairs(cam, np.array([[8.0, 1.0], [11.0, -2.0], [6.0, 2.0]]))
    bad.uv_px = bad.uv_px + [[25.0, -12.0], [-30.0, 8.0], [0.0, 20.0]]  # mis-clicked
    bad.labels = ["bad0", "bad1", "bad2"]
    res = fit_calibration(board_pairs(corners, Board(*BOARD, SQUARE_M), T) + cones + bad, W, H, T)
    assert not res.inliers[-3:].any()
    assert res.inliers[:-3].all()
    assert _ground_errors(cam, res).max() < 0.01
    assert quality_report(res)["outliers"] == ["bad0", "bad1", "bad2"]


def test_lens_distortion_board_plus_cones_within_1cm_to_10m(scene_distorted):
    cam, _, corners = scene_distorted
    T = planar_transform(BOARD_X_M)
    intr = Intrinsics(cam.K, cam.dist_coeffs, "test")
    pairs = board_pairs(corners, Board(*BOARD, SQUARE_M), T) + _cone_pairs(cam, CONES_F)
    res = fit_calibration(pairs, W, H, T, intr)
    err = _ground_errors(cam, res)
    assert err.max() < 0.01, f"max ground error {err.max():.4f} m"
    # ignoring the lens bends the far field by decimetres: the test would notice a missing undistortion
    raw = fit_calibration(pairs, W, H, T, None)
    assert _ground_errors(cam, raw).max() > 0.1
    est = pose_from_homography(res.H_F_B, cam.K).pose
    assert est.height_m == pytest.approx(1.2, abs=0.01) and est.pitch_deg == pytest.approx(10.0, abs=0.1)


@pytest.mark.parametrize(
    "pose",
    [MountPose(), MountPose(0.3, -0.2, 1.05, 6.5, 1.5, -3.0), MountPose(1.6, 0.25, 0.45, 2.0, -0.7, 4.0)],
)
def test_from_pose_is_the_camera_homography_and_pose_from_h_inverts_it(pose):
    K = default_intrinsics(W, H, 80.0)
    H_F_B = from_pose(K, W, H, pose)
    cam = PinholeCamera(K, W, H, pose)
    np.testing.assert_allclose(H_F_B, cam.H_F_B(), atol=1e-12)
    # and it really maps the camera's pixels of ground points back to them
    xy = np.array([[4.0, 1.0], [9.0, -2.0], [15.0, 0.5]])
    uv, _ = cam.project(np.column_stack([xy, np.zeros(3)]))
    np.testing.assert_allclose(apply_homography(H_F_B, uv)[0], xy, atol=1e-9)
    est = pose_from_homography(5.0 * H_F_B, K)  # any scale
    for name in ("x_m", "y_m", "height_m", "pitch_deg", "roll_deg", "yaw_deg"):
        assert getattr(est.pose, name) == pytest.approx(getattr(pose, name), abs=1e-6), name
    assert est.column_ratio == pytest.approx(1.0) and est.column_angle_deg == pytest.approx(90.0)


def test_fewer_than_4_points_and_collinear_points_are_refused():
    uv = np.array([[100.0, 800.0], [900.0, 700.0], [1500.0, 820.0]])
    with pytest.raises(ConfigError, match="at least 4"):
        estimate_homography(uv, uv / 100.0)
    line_xy = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [4.0, 0.0], [5.0, 0.0]])
    line_uv = np.array([[960.0, 1000.0], [960.0, 800.0], [960.0, 700.0], [960.0, 650.0], [960.0, 620.0]])
    with pytest.raises(ConfigError, match="collinear"):
        estimate_homography(line_uv, line_xy)


def test_upside_down_image_puts_points_above_the_horizon_and_is_refused():
    cam = _camera()
    pairs = _cone_pairs(cam, CONES_F)
    pairs.uv_px = pairs.uv_px * [1.0, -1.0] + [0.0, H - 1.0]  # camera mounted upside down, image not flipped
    with pytest.raises(ConfigError, match="above the horizon"):
        fit_calibration(pairs, W, H, planar_transform(BOARD_X_M))


def test_mirrored_ground_frame_is_refused():
    cam = _camera()
    pairs = _cone_pairs(cam, CONES_F)
    pairs.xy_S = pairs.xy_S * [1.0, -1.0]  # y measured to the right
    with pytest.raises(ConfigError, match="mirrored"):
        fit_calibration(pairs, W, H, planar_transform(BOARD_X_M))


def test_point_file_header_comments_and_bad_lines(tmp_path):
    f = tmp_path / "pts.csv"
    f.write_text("u,v,x_s,y_s\n# a comment\n\n100,800,3.5,1.0\n 900 , 700 , 5.0 , -1.5\n")
    p = read_points_csv(f)
    np.testing.assert_allclose(p.uv_px, [[100, 800], [900, 700]])
    np.testing.assert_allclose(p.xy_S, [[3.5, 1.0], [5.0, -1.5]])
    assert p.labels == ["pts.csv:4", "pts.csv:5"]
    for body, what in (
        ("100,800,3.5\n", "line 1.*needs 4 values"),
        ("100,800,3.5,1\n100,abc,3,1\n", "line 2.*numbers"),
        ("100,800,3.5,1\n100,800,nan,1\n", "line 2.*finite"),
        ("# only a comment\n", "no point lines"),
    ):
        f.write_text(body)
        with pytest.raises(ConfigError, match=what) as e:
            read_points_csv(f)
        assert str(f) in str(e.value)


def test_intrinsics_from_tilted_views_recover_the_lens():
    w, h = 1280, 720
    K = default_intrinsics(w, h, 85.0)
    cam = PinholeCamera(K, w, h, MountPose(), DIST)
    views = [(f"view{k}", img) for k, img in enumerate(render_views(cam, *BOARD, 0.04))]
    intr, missed = calibrate_intrinsics(views, BOARD, 0.04)
    assert len(missed) <= 1 and intr.rms_px < 0.5
    assert intr.K[0, 0] == pytest.approx(K[0, 0], rel=0.02)
    # the recovered lens undistorts like the true one over the image
    grid = np.array([[u, v] for u in np.linspace(100, w - 100, 9) for v in np.linspace(80, h - 80, 7)])
    d = np.linalg.norm(undistort_pixels(grid, intr.K, intr.dist) - undistort_pixels(grid, K, DIST), axis=1)
    assert np.median(d) < 1.0
    with pytest.raises(ConfigError, match="only"):
        calibrate_intrinsics(views[:2], BOARD, 0.04)


def test_undistort_pixels_inverts_the_lens_in_wide_angle_corners():
    """Bug fixed: cv2.undistortPoints' default 5 iterations leave pixels off in the corners of a wide lens."""
    import cv2

    from cone_perception.geometry import distort_pixels

    K = default_intrinsics(W, H, 90.0)
    d = np.array([-0.3, 0.1, 0.001, -0.001, -0.02])
    uv = np.array([[u, v] for u in np.linspace(0, W - 1, 13) for v in np.linspace(0, H - 1, 9)])
    raw = distort_pixels(uv, K, d)
    assert np.abs(undistort_pixels(raw, K, d) - uv).max() < 1e-3
    old = cv2.undistortPoints(raw.reshape(-1, 1, 2), K, d, P=K).reshape(-1, 2)
    assert np.abs(old - uv).max() > 1.0  # what the mapper did before
