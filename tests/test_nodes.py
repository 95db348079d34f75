"""Live ROS 2 tests of the driver_adapter and mapping nodes (pip ROS 2 Jazzy, Fast DDS).

In-process: the node classes in an executor with a test node. As processes: the installed
executables with ``--ros-args --params-file`` and remapping, as ``ros2 run`` starts them.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from visualization_msgs.msg import Marker, MarkerArray

from cone_perception.adapter import DriverAdapter, bgr_to_yuyv
from cone_perception.classes import BLUE, YELLOW
from cone_perception.crop import CropSpec
from cone_perception.geometry.calib import load_calibration, save_calibration
from cone_perception.geometry.camera import MountPose, PinholeCamera, default_intrinsics
from cone_perception.mapping import ConeMapper
from cone_perception.nodes import _msgs
from cone_perception.nodes.driver_adapter import DriverAdapterNode
from cone_perception.nodes.mapping import MappingNode
from cone_perception.params import PARAMS
from cone_perception.records import boxes_from_arrays

from rosutil import Inbox, RosFixture, ros, start_node_process, stop_process  # noqa: F401 (ros is a fixture)

W, H = 1920, 1080
CALIB = load_calibration("example_mainhoop")


def _yuyv_msg(seed: int, sec: int, width: int = W) -> Image:
    bgr = np.random.default_rng(seed).integers(0, 256, (H, width - width % 2, 3), dtype=np.uint8)
    yuyv = bgr_to_yuyv(bgr)
    msg = Image()
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, 500
    msg.header.frame_id = "camera_optical"
    msg.height, msg.width = H, width
    msg.encoding = "yuv422_yuy2"
    msg.step = width * 2
    msg.data = yuyv.tobytes() if width % 2 == 0 else yuyv.tobytes() + bytes(H * 2)
    return msg


def _boxes_msg(sec: int, boxes, classes) -> PointCloud2:
    msg = _msgs.boxes_msg(boxes_from_arrays(np.asarray(boxes, float), [0.9] * len(classes), classes), Image().header)
    msg.header.stamp.sec = sec
    msg.header.frame_id = "camera_optical"
    return msg


def test_adapter_node_yuyv_frame_to_band_and_camera_info(ros: RosFixture) -> None:
    node = ros.add(DriverAdapterNode(context=ros.context))
    t = ros.node("tester")
    images, infos = Inbox(), Inbox()
    t.create_subscription(Image, "image_cropped", images, 2)
    t.create_subscription(CameraInfo, "image_cropped/camera_info", infos, 2)
    pub = t.create_publisher(Image, "image_raw", 2)
    msg = _yuyv_msg(1, 42)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0 and node.count_publishers("image_cropped") > 0)
    ros.spin_until(lambda: (pub.publish(msg) or True) and len(images.msgs) > 0 and len(infos.msgs) > 0, 15)
    img, info = images.msgs[0], infos.msgs[0]
    assert (img.width, img.height, img.encoding) == (960, 288, "bgr8")
    assert img.header.stamp.sec == 42 and img.header.stamp.nanosec == 500
    assert img.header.frame_id == "camera_optical"
    expect = DriverAdapter(CALIB.crop, W, H).from_raw("yuv422_yuy2", W, H, W * 2, msg.data)
    np.testing.assert_array_equal(np.frombuffer(bytes(img.data), np.uint8).reshape(288, 960, 3), expect)
    assert info.header.stamp.sec == 42 and (info.width, info.height) == (W, H)
    assert _msgs.crop_from_camera_info(info) == CALIB.crop
    assert node.stats.ok >= 1


def test_adapter_node_drops_bad_frame_and_keeps_running(ros: RosFixture) -> None:
    node = ros.add(DriverAdapterNode(context=ros.context))
    t = ros.node("tester")
    images = Inbox()
    t.create_subscription(Image, "image_cropped", images, 2)
    pub = t.create_publisher(Image, "image_raw", 2)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0)
    bad = _yuyv_msg(2, 7, width=W - 1)  # odd width: not YUYV
    short = _yuyv_msg(2, 8)
    short.data = bytes(short.data)[:-100]
    assert ros.spin_until(lambda: (pub.publish(bad) or True) and node.stats.dropped["odd_width"] > 0)
    assert ros.spin_until(lambda: (pub.publish(short) or True) and node.stats.dropped["data_too_short"] > 0)
    assert not images.msgs
    good = _yuyv_msg(3, 9)
    assert ros.spin_until(lambda: (pub.publish(good) or True) and len(images.msgs) > 0, 15)
    assert images.msgs[0].header.stamp.sec == 9


def test_mapping_node_boxes_to_cones_and_markers(ros: RosFixture) -> None:
    # the calibrated H alone (two boxes are too few for an attitude fit; `image` would add its prior's covariance)
    node = ros.add(MappingNode(context=ros.context, parameter_overrides=[Parameter("attitude", value="fixed")]))
    t = ros.node("tester")
    cones, markers = Inbox(), Inbox()
    t.create_subscription(PointCloud2, "/cones", cones, 10)
    t.create_subscription(MarkerArray, "/cones/markers", markers, 10)
    pub = t.create_publisher(PointCloud2, "cone_boxes", 10)
    cam = PinholeCamera(default_intrinsics(W, H, 90.0), W, H, MountPose())
    uv, _ = cam.project(np.array([[7.0, 2.0, 0.0], [9.0, -2.0, 0.0]]))
    uv = uv + 0.5  # box edges
    boxes = [[uv[0, 0] - 20, uv[0, 1] - 40, uv[0, 0], uv[0, 1]], [uv[1, 0], uv[1, 1] - 30, uv[1, 0] + 15, uv[1, 1]]]
    msg = _boxes_msg(77, boxes, [BLUE, YELLOW])
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0)
    assert ros.spin_until(lambda: (pub.publish(msg) or True) and cones.msgs and markers.msgs, 15)
    out = _msgs.cones_from_msg(cones.msgs[0])
    assert cones.msgs[0].header.stamp.sec == 77 and cones.msgs[0].header.frame_id == "rear_axle"
    expect = ConeMapper(CALIB).map_boxes(_msgs.boxes_from_msg(msg))
    for f in ("x", "y", "cov_xx", "cov_xy", "cov_yy"):
        np.testing.assert_allclose(out[f], expect[f], rtol=1e-6)
    # the example calibration maps each box's bottom centre and adds the 0.15 m foot offset
    np.testing.assert_allclose(np.c_[out["x"], out["y"]], [[7.0, 2.0], [9.0, -2.0]], atol=0.2)
    assert out["class_id"].tolist() == [BLUE, YELLOW]
    ma = markers.msgs[0].markers
    assert ma[0].action == Marker.DELETEALL and [m.type for m in ma[1:] if m.ns == "cones"] == [Marker.CYLINDER] * 2
    assert ma[1].header.frame_id == "rear_axle" and ma[1].color.b > ma[1].color.r  # blue cone drawn blue
    ell = [m for m in ma if m.ns == "cones_2sigma"]  # each cone's 2-sigma position ellipse
    assert len(ell) == 2 and (ell[0].pose.position.x, ell[0].pose.position.y) == (ma[1].pose.position.x, ma[1].pose.position.y)
    assert ell[0].scale.x >= ell[0].scale.y > 0
    assert node.stats.ok >= 1


def test_mapping_node_drops_bad_boxes_and_keeps_running(ros: RosFixture) -> None:
    node = ros.add(MappingNode(context=ros.context, parameter_overrides=[Parameter("publish_markers", value=False)]))
    t = ros.node("tester")
    cones = Inbox()
    t.create_subscription(PointCloud2, "/cones", cones, 10)
    pub = t.create_publisher(PointCloud2, "cone_boxes", 10)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0)
    pub.publish(_boxes_msg(1, [[100, 600, 90, 650]], [BLUE]))  # u2 < u1
    pub.publish(_boxes_msg(2, [[100, 600, 120, 650]], [9]))  # unknown class
    pub.publish(_boxes_msg(3, [[900, 600, 930, 650]], [YELLOW]))
    # one cone boxed as yellow and blue on one spot (IoU 0.9): one cone on /cones, as the fused pipeline gives (issue 26g)
    pub.publish(_boxes_msg(4, [[900, 600, 930, 650], [901, 601, 931, 651], [1300, 600, 1330, 650]], [YELLOW, BLUE, BLUE]))
    assert ros.spin_until(lambda: len(cones.msgs) >= 2, 10)
    assert [m.header.stamp.sec for m in cones.msgs] == [3, 4]
    assert _msgs.cones_from_msg(cones.msgs[1])["class_id"].tolist() == [YELLOW, BLUE]
    assert node.stats.dropped["bad_box"] == 1 and node.stats.dropped["bad_class"] == 1


def test_node_processes_with_params_file_and_remapping(ros: RosFixture, tmp_path: Path) -> None:
    # a camera of our own: downscale 4 and another band, given through a params file
    calib = load_calibration("example_mainhoop")
    calib.crop = CropSpec(400, 912, 0, W, 4)
    calib.camera = "test_cam"
    cal_path = save_calibration(calib, tmp_path / "test_cam.yaml")
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"calibration": str(cal_path)}}}))
    adapter = start_node_process(
        "driver_adapter", "--params-file", str(params), "-r", "image_raw:=/cam0/image_raw", "-r", "__ns:=/front"
    )
    mapping = start_node_process("mapping", "--params-file", str(params), "-r", "/cones:=/front/cones")
    try:
        t = ros.node("tester")
        images, cones = Inbox(), Inbox()
        t.create_subscription(Image, "/front/image_cropped", images, 2)
        t.create_subscription(PointCloud2, "/front/cones", cones, 10)
        pub_img = t.create_publisher(Image, "/cam0/image_raw", 2)
        pub_box = t.create_publisher(PointCloud2, "/cone_boxes", 10)
        img = _yuyv_msg(5, 11)
        box = _boxes_msg(12, [[900, 600, 930, 650]], [YELLOW])
        ok = ros.spin_until(
            lambda: (pub_img.publish(img) or pub_box.publish(box) or time.sleep(0.05) or True)
            and images.msgs
            and cones.msgs,
            30,
        )
        assert ok, "no output from node processes:\n" + stop_process(adapter) + stop_process(mapping)
        assert (images.msgs[0].width, images.msgs[0].height) == (480, 128)  # params file honoured
        assert images.msgs[0].header.stamp.sec == 11
        assert cones.msgs[0].header.stamp.sec == 12 and cones.msgs[0].header.frame_id == "rear_axle"
    finally:
        out = stop_process(adapter) + stop_process(mapping)
    assert "test_cam.yaml" in out  # the node said which calibration it loaded


def test_node_process_with_bad_calibration_exits_nonzero_naming_file(tmp_path: Path) -> None:
    bad = tmp_path / "broken.yaml"
    bad.write_text("camera: x\nimage_width: 1920\n")
    p = start_node_process("mapping", "-p", f"calibration:={bad}")
    out, _ = p.communicate(timeout=30)
    assert p.returncode == 1
    assert "broken.yaml" in out and "image_height" in out


@pytest.mark.parametrize("params", sorted((Path(__file__).parents[1] / "launch_configs").glob("*.params.yaml")), ids=lambda p: p.name)
def test_shipped_params_files_start_the_nodes(params: Path) -> None:
    """Every shipped parameter file is accepted by the nodes it configures (as car.launch.py passes it)."""
    procs = {n: start_node_process(n, "--params-file", str(params)) for n in ("driver_adapter", "mapping")}
    time.sleep(3.0)
    alive = {n: p.poll() is None for n, p in procs.items()}
    outs = {n: stop_process(p) for n, p in procs.items()}
    for n in procs:
        assert alive[n], f"{n} exited with {params.name}:\n{outs[n]}"
        assert "calibration" in outs[n] and "error" not in outs[n].lower(), outs[n]


def test_detection_node_builds_a_fixed_size_network_for_the_band(ros: RosFixture) -> None:
    """With the CPU default (ONNX Runtime, fixed input size) and a band other than the model's
    960x288, the node rebuilds the network for the band on the first camera_info: its boxes are
    eager torch's on the band as it is, not those of a letterboxed (half-resolution) band."""
    from std_msgs.msg import Header

    from cone_perception.bench.frames import rendered_frames
    from cone_perception.detector import Detector, default_model_path
    from cone_perception.nodes.detection import DetectionNode

    node = ros.add(DetectionNode(context=ros.context))
    assert node.detector.backend == "onnx" and node.detector.imgsz == (960, 288)
    crop = replace(CALIB.crop, downscale=1)  # the full-resolution band, 1920x576
    band = DriverAdapter(crop, W, H).from_raw("yuv422_yuy2", W, H, 2 * W, rendered_frames(CALIB, 1)[0])
    t = ros.node("tester")
    boxes = Inbox()
    t.create_subscription(PointCloud2, "cone_boxes", boxes, 2)
    pub_info = t.create_publisher(CameraInfo, "image_cropped/camera_info", 2)
    pub_img = t.create_publisher(Image, "image_cropped", 2)
    assert ros.spin_until(lambda: pub_img.get_subscription_count() > 0 and pub_info.get_subscription_count() > 0)
    header = Header(frame_id="camera_optical")
    header.stamp.sec = 5
    info = _msgs.camera_info(crop.camera_info_fields(W, H), header)
    img = _msgs.bgr_image(band, header)
    assert ros.spin_until(lambda: (pub_info.publish(info) or pub_img.publish(img) or True) and len(boxes.msgs) > 0, 30)
    assert node.detector.backend == "onnx" and node.detector.imgsz == (1920, 576)
    got = _msgs.boxes_from_msg(boxes.msgs[0])
    want = Detector.load(default_model_path(), backend="torch", max_det=PARAMS["max_det"].default).detect(band, crop)
    assert len(got) == len(want) > 0
    np.testing.assert_allclose(np.sort(got["u1"]), np.sort(want["u1"]), atol=0.05)
