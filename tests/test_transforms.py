"""The camera's static transform from the calibration's mount pose, and the launch file that starts it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from cone_perception.calibrate import from_pose
from cone_perception.errors import ConfigError
from cone_perception.geometry.calib import calibration_from_dict, load_calibration, resolve_calibration_path
from cone_perception.geometry.camera import MountPose, PinholeCamera, default_intrinsics
from cone_perception.geometry.transforms import (
    calibration_in_params_file, mount_pose_of, optical_frame_transform, quaternion_xyzw,
)

ROOT = Path(__file__).resolve().parents[1]
POSE = MountPose(x_m=0.7, y_m=-0.1, height_m=1.05, pitch_deg=8.0, roll_deg=1.5, yaw_deg=-3.0)
K = default_intrinsics(1920, 1080, 90.0)


def _rot(q):
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _calib_dict(with_k=True, mount_pose=None):
    d = yaml.safe_load(resolve_calibration_path("example_mainhoop").read_text())
    d.pop("mount", None)
    d.pop("mount_pose", None)  # the shipped file's pose is for its own H; this helper sets H and the pose itself
    H_F_B = from_pose(K, 1920, 1080, POSE)
    d["H_S_B"] = (np.array([[1, 0, -3.0], [0, 1, 0], [0, 0, 1]]) @ H_F_B).tolist()  # T_F_S is a 3 m x shift
    if with_k:
        d["camera_matrix"] = K.tolist()
    else:
        d.pop("camera_matrix", None)
    if mount_pose is not None:
        d["mount_pose"] = mount_pose
    return d


def _check_transform(tf, pose: MountPose):
    cam = PinholeCamera(K, 1920, 1080, pose)
    assert tf.parent == "rear_axle" and tf.child == "example_mainhoop_optical_frame"
    np.testing.assert_allclose(tf.xyz_m, [pose.x_m, pose.y_m, pose.height_m], atol=1e-6)
    R_F_C = _rot(tf.xyzw)
    # a ground point seen through the published transform lands where the camera model puts it
    ground = np.array([[6.0, 1.0, 0.0], [12.0, -2.5, 0.0], [3.0, 0.4, 0.0]])
    p_c = (ground - np.array(tf.xyz_m)) @ R_F_C  # = R_C_F @ (p - t)
    uv = p_c @ K.T
    np.testing.assert_allclose(uv[:, :2] / uv[:, 2:], cam.project(ground)[0], atol=1e-3)
    # optical z (viewing direction) points forward and down by the pitch
    z_axis = R_F_C[:, 2]
    assert z_axis[0] > 0.9 and np.degrees(np.arcsin(-z_axis[2])) == pytest.approx(pose.pitch_deg, abs=0.05)


def test_transform_from_the_homography_and_camera_matrix():
    calib = calibration_from_dict(_calib_dict(), "known_pose.yaml")
    pose, source = mount_pose_of(calib)
    assert source == "H_F_B + camera_matrix"
    _check_transform(optical_frame_transform(calib), POSE)


def test_transform_from_mount_pose_fields_wins():
    mp = {"x_m": 0.7, "y_m": -0.1, "z_m": 1.05, "yaw_deg": -3.0, "pitch_deg": 8.0, "roll_deg": 1.5}
    calib = calibration_from_dict(_calib_dict(with_k=False, mount_pose=mp), "known_pose.yaml")
    assert mount_pose_of(calib) == (POSE, "mount_pose")
    tf = optical_frame_transform(calib)
    _check_transform(tf, POSE)
    args = tf.args()
    assert args[-4:] == ["--frame-id", "rear_axle", "--child-frame-id", "example_mainhoop_optical_frame"]
    assert float(args[args.index("--z") + 1]) == pytest.approx(1.05)
    assert calibration_from_dict(calib.to_dict(), "again").mount_pose == POSE  # saved and loaded back


def test_shipped_calibration_transform_is_its_calibrate_pose():
    calib = load_calibration("example_mainhoop")  # calibrate --from-pose --cam-x 0.5 --height 1.2 --pitch 10
    tf = optical_frame_transform(calib)
    np.testing.assert_allclose(tf.xyz_m, [0.5, 0.0, 1.2], atol=1e-6)
    _check_transform(tf, MountPose(0.5, 0.0, 1.2, 10.0, 0.0, 0.0))


@pytest.mark.parametrize(
    ("mp", "field"),
    [({"x_m": 0.5}, "mount_pose.z_m"), ({"x_m": 0.5, "z_m": -1.0}, "mount_pose.z_m"),
     ({"x_m": 0.5, "z_m": 1.0, "pitch_deg": 95}, "mount_pose.pitch_deg"),
     ({"x_m": 0.5, "z_m": 1.0, "height_m": 1.0}, "mount_pose.height_m"), ("up", "mount_pose"),
     ({"x_m": "front", "z_m": 1.0}, "mount_pose.x_m")],
)
def test_bad_mount_pose_names_the_field(mp, field):
    with pytest.raises(ConfigError, match=f"cal.yaml: {field}"):
        calibration_from_dict(_calib_dict(mount_pose=mp), "cal.yaml")


def test_no_pose_at_all_is_a_clear_error():
    calib = calibration_from_dict(_calib_dict(with_k=False), "cal.yaml")
    with pytest.raises(ConfigError, match="cal.yaml: mount_pose: missing"):
        optical_frame_transform(calib)


def test_quaternion_of_rotations_near_180_degrees():
    rng = np.random.default_rng(3)
    for _ in range(200):
        a, b, c = rng.uniform(-np.pi, np.pi, 3)
        R = MountPose(0, 0, 1, np.degrees(b), np.degrees(c), np.degrees(a)).R_F_C()
        q = quaternion_xyzw(R)
        assert q[3] >= 0 and np.linalg.norm(q) == pytest.approx(1.0)
        np.testing.assert_allclose(_rot(q), R, atol=1e-9)
    np.testing.assert_allclose(_rot(quaternion_xyzw(np.diag([1.0, -1.0, -1.0]))), np.diag([1.0, -1, -1]), atol=1e-12)


def test_calibration_in_params_file(tmp_path):
    assert calibration_in_params_file(ROOT / "launch_configs" / "example_mainhoop.params.yaml") == "example_mainhoop"
    p = tmp_path / "p.yaml"
    p.write_text("/**:\n  ros__parameters:\n    calibration: a\nmapping:\n  ros__parameters:\n    calibration: b\n")
    assert calibration_in_params_file(p) == "b" and calibration_in_params_file(p, "detection") == "a"
    p.write_text("mapping:\n  ros__parameters:\n    publish_markers: true\n")
    assert calibration_in_params_file(p) is None
    with pytest.raises(ConfigError, match="cannot read"):
        calibration_in_params_file(tmp_path / "missing.yaml")


def test_rviz_config_shows_the_package_topics():
    cfg = yaml.safe_load((ROOT / "launch_configs" / "cone_perception.rviz").read_text())
    vm = cfg["Visualization Manager"]
    assert vm["Global Options"]["Fixed Frame"] == "rear_axle"
    topics = {d["Class"].split("/")[-1]: d.get("Topic", {}).get("Value") for d in vm["Displays"]}
    assert topics["MarkerArray"] == "/cones/markers"
    assert topics["PointCloud2"] == "/cones"
    assert topics["Image"] == "/image_cropped/debug"
    assert "TF" in topics


def _launch_description():
    pytest.importorskip("launch", reason="ROS 2 `launch` is not installed here (pip has no wheel; apt on the car)")
    pytest.importorskip("launch_ros", reason="ROS 2 `launch_ros` is not installed here")
    import importlib.util

    spec = importlib.util.spec_from_file_location("car_launch", ROOT / "launch_configs" / "car.launch.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod, mod.generate_launch_description()


def test_car_launch_builds_with_tf_and_rviz(monkeypatch):
    mod, ld = _launch_description()
    from launch import LaunchContext

    names = [a.name for a in ld.entities if hasattr(a, "name") and type(a).__name__ == "DeclareLaunchArgument"]
    assert {"camera", "image_topic", "fused", "tf", "rviz", "camera_frame"} <= set(names)
    monkeypatch.setattr(mod, "get_package_share_directory", lambda pkg: str(ROOT))
    ctx = LaunchContext()
    assert {"respawn", "respawn_delay"} <= set(names)
    for k, v in {"camera": "example_mainhoop", "image_topic": "/camera/image_raw", "fused": "false", "tf": "true",
                 "rviz": "true", "camera_frame": "", "respawn": "true", "respawn_delay": "1.0"}.items():
        ctx.launch_configurations[k] = v
    nodes = mod._nodes(ctx)
    execs = [n.node_executable for n in nodes]
    assert execs[:2] == ["static_transform_publisher", "rviz2"] and "detection" in execs
    ctx.launch_configurations["respawn_delay"] = "soon"
    with pytest.raises(RuntimeError, match="respawn_delay"):
        mod._nodes(ctx)
