"""``cone-perception calibrate`` end to end: image / bag / mount pose -> YAML that the mapping stage
loads and that maps boxes to the true cone positions; every bad input stops with exit 2, a message and
no YAML."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from cone_perception.classes import CLASS_NAMES
from cone_perception.cli import main
from cone_perception.geometry.calib import load_calibration
from cone_perception.geometry.camera import MountPose, PinholeCamera, default_intrinsics
from cone_perception.mapping import ConeMapper
from cone_perception.records import boxes_from_arrays

from _board_scene import board_texture, render_on_ground, render_views

W, H = 1920, 1080
BOARD_X_M = 4.0
DIST = np.array([-0.25, 0.07, 0.0005, -0.0003, -0.01])
CONES_F = np.array([[x, y] for x in (7.0, 10.0, 13.0) for y in (-3.0, 3.0)] + [[5.0, -4.5], [5.0, 4.5]])
BASE = ["--board", "9x6", "--square", "0.2", "--x-offset", str(BOARD_X_M)]


def _camera(dist=None) -> PinholeCamera:
    return PinholeCamera(default_intrinsics(W, H, 90.0), W, H, MountPose(), np.zeros(0) if dist is None else dist)


def _write_points(path: Path, cam: PinholeCamera, xy_F: np.ndarray) -> Path:
    uv, _ = cam.project(np.column_stack([xy_F, np.zeros(len(xy_F))]))
    lines = ["u,v,x_s,y_s"] + [f"{u:.3f},{v:.3f},{x - BOARD_X_M:.3f},{y:.3f}" for (u, v), (x, y) in zip(uv, xy_F)]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("calib_cli")
    cam = _camera()
    img = render_on_ground(cam, board_texture(9, 6, 40), 0.2 / 40, BOARD_X_M)
    cv2.imwrite(str(d / "board.png"), img)
    _write_points(d / "cones.csv", cam, CONES_F)
    camd = _camera(DIST)
    cv2.imwrite(str(d / "board_dist.png"), render_on_ground(camd, board_texture(9, 6, 40), 0.2 / 40, BOARD_X_M))
    _write_points(d / "cones_dist.csv", camd, CONES_F)
    (d / "lens.yaml").write_text(
        yaml.safe_dump(
            {"camera_matrix": camd.K.tolist(), "dist_coeffs": DIST.tolist(), "image_width": W, "image_height": H}
        )
    )
    return d


def _mapped_errors(yaml_path: Path, cam: PinholeCamera) -> np.ndarray:
    """Boxes whose bottom-centre foot points are the (raw) pixels of true cones -> ConeMapper error (m).

    Boxes are in pixel-edge coordinates: the pixel-centre coordinate of a foot is its edge coordinate - 0.5."""
    xy = np.array([[x, y] for x in np.arange(3.0, 10.01, 1.0) for y in (-3.0, -1.0, 0.0, 1.5, 3.0)])
    calib = load_calibration(yaml_path)
    off = calib.foot_offset_m[CLASS_NAMES.index("orange")]
    ray = xy - np.array([cam.pose.x_m, cam.pose.y_m])  # the TRUE camera, not the recovered one
    foot = xy - off * ray / np.linalg.norm(ray, axis=1, keepdims=True)  # the base edge the camera sees
    uv, _ = cam.project(np.column_stack([foot, np.zeros(len(xy))]))
    uv = uv + 0.5
    boxes = np.column_stack([uv[:, 0] - 10, uv[:, 1] - 30, uv[:, 0] + 10, uv[:, 1]])
    orange = CLASS_NAMES.index("orange")  # bottom-centre foot point
    recs = boxes_from_arrays(boxes, np.full(len(xy), 0.9), np.full(len(xy), orange))
    cones = ConeMapper(load_calibration(yaml_path)).map_boxes(recs)
    assert len(cones) == len(xy)
    return np.hypot(cones["x"] - xy[:, 0], cones["y"] - xy[:, 1])


def test_image_board_and_points_round_trip_through_the_mapper(files, tmp_path, capsys):
    out = tmp_path / "cam.yaml"
    board_and_cones = ["calibrate", "--image", str(files / "board.png"), *BASE, "--points", str(files / "cones.csv")]
    rc = main([*board_and_cones, "--hfov", "90", "--out", str(out)])
    assert rc == 0
    assert _mapped_errors(out, _camera()).max() < 0.01
    text = capsys.readouterr().out
    assert "RMS" in text and "1 px up/down" in text and "camera pose from H" in text
    for suffix in (".report.txt", ".report.json", ".points.png", ".birdseye.png"):
        assert (tmp_path / f"cam{suffix}").is_file(), suffix
    assert cv2.imread(str(tmp_path / "cam.points.png")).shape[1] == W
    calib = load_calibration(out)
    assert calib.camera == "cam" and calib.extra["mount_estimate"]["height_m"] == pytest.approx(1.2, abs=0.01)
    # the image fit writes the mount pose recovered from H (it agrees with H, so the file loads)
    mp = calib.mount_pose
    assert (mp.height_m, mp.pitch_deg, mp.x_m) == (pytest.approx(1.2, abs=0.01), pytest.approx(10.0, abs=0.1), pytest.approx(0.5, abs=0.05))
    assert "--points" in out.read_text().splitlines()[0]  # the command that made it is in the header

    # a second run keeps what the team set by hand: crop, foot points, sigmas, other keys
    d = yaml.safe_load(out.read_text())
    d["crop"] = {"v0": 400, "v1": 1000, "u0": 0, "u1": 1920}
    d["pixel_sigma"] = {"u": 2.5, "v": 3.0}
    d["foot_points"]["blue"] = "bottom_center"
    d["team_note"] = "mount re-torqued"
    out.write_text(yaml.safe_dump(d, sort_keys=False))
    before = out.read_text()
    assert main([*board_and_cones, "--out", str(out)]) == 2  # issue 20: never overwritten silently
    assert "--force" in capsys.readouterr().err and out.read_text() == before
    rc = main([*board_and_cones, "--out", str(out), "--force"])  # K now comes from the file
    assert rc == 0
    printed = capsys.readouterr().out
    assert all(f"calibrate: wrote {out.with_suffix('')}{s}" in printed for s in (".report.txt", ".report.json"))
    again = load_calibration(out)
    assert (again.crop.v0, again.crop.v1, again.pixel_sigma_u, again.pixel_sigma_v) == (400, 1000, 2.5, 3.0)
    assert again.foot_points[CLASS_NAMES.index("blue")] == "bottom_center"
    assert again.extra["team_note"] == "mount re-torqued"
    np.testing.assert_allclose(again.camera_matrix, calib.camera_matrix)  # kept from the file


def test_lens_distortion_end_to_end_with_intrinsics_file(files, tmp_path):
    out = tmp_path / "wide.yaml"
    rc = main(
        [
            "calibrate",
            "--image",
            str(files / "board_dist.png"),
            *BASE,
            "--points",
            str(files / "cones_dist.csv"),
            "--intrinsics",
            str(files / "lens.yaml"),
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    calib = load_calibration(out)
    np.testing.assert_allclose(calib.dist_coeffs, DIST)
    assert _mapped_errors(out, _camera(DIST)).max() < 0.01  # the mapper undistorts the foot points


def test_from_pose_writes_the_synthetic_cameras_homography(tmp_path):
    out = tmp_path / "pose.yaml"
    rc = main(
        [
            "calibrate",
            "--from-pose",
            "--hfov",
            "90",
            "--size",
            "1920x1080",
            "--cam-x",
            "0.5",
            "--height",
            "1.2",
            "--pitch",
            "10",
            "--x-offset",
            "3",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    calib = load_calibration(out)
    np.testing.assert_allclose(calib.H_F_B, _camera().H_F_B(), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(calib.T_F_S[:2, 2], [3.0, 0.0])
    assert calib.extra["mount"]["height_m"] == 1.2
    assert calib.mount_pose == MountPose(0.5, 0.0, 1.2, 10.0, 0.0, 0.0)  # attitude per frame possible
    assert _mapped_errors(out, _camera()).max() < 1e-5  # float32 records
    # the shipped example is this very command (see calib/README.md)
    np.testing.assert_allclose(load_calibration("example_mainhoop").H_F_B, calib.H_F_B, rtol=1e-9, atol=1e-12)


def test_views_estimate_the_lens_into_the_yaml(tmp_path):
    w, h = 1280, 720
    cam = PinholeCamera(default_intrinsics(w, h, 85.0), w, h, MountPose(), DIST)
    paths = []
    for k, img in enumerate(render_views(cam, 9, 6, 0.04)):
        paths.append(tmp_path / f"v{k}.png")
        cv2.imwrite(str(paths[-1]), img)
    out = tmp_path / "lens.yaml"
    rc = main(
        [
            "calibrate",
            "--from-pose",
            "--views",
            *map(str, paths),
            "--views-board",
            "9x6",
            "--views-square",
            "0.04",
            "--height",
            "1.2",
            "--pitch",
            "10",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    calib = load_calibration(out)
    assert (calib.image_width, calib.image_height) == (w, h)  # the size of the views
    assert calib.camera_matrix[0, 0] == pytest.approx(cam.K[0, 0], rel=0.02)
    assert calib.dist_coeffs[0] == pytest.approx(DIST[0], abs=0.05)
    assert "calibrateCamera RMS" in (tmp_path / "lens.report.txt").read_text()


def test_bag_frame(files, tmp_path):
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    from cone_perception.adapter import bgr_to_yuyv

    ts = get_typestore(Stores.ROS2_JAZZY)
    Image, Header, Time = (
        ts.types[n] for n in ("sensor_msgs/msg/Image", "std_msgs/msg/Header", "builtin_interfaces/msg/Time")
    )
    bag = tmp_path / "bag"
    board = cv2.imread(str(files / "board.png"))
    with Writer(bag, version=9) as w:
        conn = w.add_connection("/camera/image_raw", Image.__msgtype__, typestore=ts)
        for k, frame in enumerate([np.full_like(board, 90), board]):  # frame 0: empty road
            data = bgr_to_yuyv(frame).reshape(-1)
            msg = Image(Header(Time(k, 0), "camera"), H, W, "yuv422_yuy2", 0, 2 * W, data)
            w.write(conn, k * 10**9, ts.serialize_cdr(msg, Image.__msgtype__))
    out = tmp_path / "bag.yaml"
    args = ["calibrate", "--bag", str(bag), *BASE, "--points", str(files / "cones.csv"), "--out", str(out)]
    assert main(args + ["--frame", "1"]) == 0
    assert _mapped_errors(out, _camera()).max() < 0.02  # YUYV chroma subsampling costs a little
    out.unlink()
    assert main(args + ["--frame", "5"]) == 2 and not out.exists()


def _fails(args: list[str], out: Path, capsys, *needles: str) -> str:
    rc = main(["calibrate", *args, "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert not out.exists()
    for n in needles:
        assert n in err, err
    return err


def test_board_not_found(files, tmp_path, capsys):
    out = tmp_path / "c.yaml"
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((H, W, 3), 100, np.uint8))
    _fails(["--image", str(blank), *BASE], out, capsys, "no 9x6 chessboard found", "board_not_found.png")
    assert (tmp_path / "c.board_not_found.png").is_file()
    # a wrong size gets a hint at the size that is there
    _fails(
        ["--image", str(files / "board.png"), "--board", "10x6", "--square", "0.2"],
        out,
        capsys,
        "9x6 board was found instead",
    )


def test_bad_point_sets(files, tmp_path, capsys):
    out = tmp_path / "c.yaml"
    img = str(files / "board.png")
    three = tmp_path / "three.csv"
    three.write_text("1000,700,3,0\n900,750,2.5,0.5\n1200,650,4,-1\n")
    _fails(["--image", img, "--points", str(three)], out, capsys, "at least 4")
    line = tmp_path / "line.csv"
    line.write_text("".join(f"{960 + 0 * k},{1000 - 80 * k},{2 + k},0\n" for k in range(5)))
    _fails(["--image", img, "--points", str(line)], out, capsys, "collinear")
    badline = tmp_path / "bad.csv"
    badline.write_text("u,v,x_s,y_s\n1000,700,3,0\n900;750;2.5;0.5\n")
    _fails(["--image", img, "--points", str(badline)], out, capsys, "bad.csv: line 3")
    upside = tmp_path / "upside.csv"
    uv, _ = _camera().project(np.column_stack([CONES_F, np.zeros(len(CONES_F))]))
    upside.write_text("".join(f"{u},{H - 1 - v},{x},{y}\n" for (u, v), (x, y) in zip(uv, CONES_F)))
    _fails(["--image", img, "--points", str(upside)], out, capsys, "above the horizon")
    _fails(["--image", img], out, capsys, "--board/--points")
    _fails(["--image", img, "--board", "9by6", "--square", "0.2"], out, capsys, "COLSxROWS")
    _fails(["--from-pose", "--hfov", "90", "--height", "1.2"], out, capsys, "--pitch")
