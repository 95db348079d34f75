"""Node parameters: descriptors, run-time changes through rclpy's parameter service, the debug image."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from cone_perception import detector
from cone_perception.geometry.calib import load_calibration
from cone_perception.nodes import _msgs
from cone_perception.params import PARAMS, ParamSpec
from cone_perception.records import boxes_from_arrays

from rosutil import Inbox, RosFixture, ros  # noqa: F401 (ros is a fixture)

CALIB = load_calibration("example_mainhoop")


# -- the table (no ROS) ---------------------------------------------------------------------------
def test_param_table_defaults_match_the_code_they_configure():
    assert PARAMS["backend"].default == detector.DEFAULT_BACKEND
    assert PARAMS["threads"].default == detector.RUNTIME_THREADS
    for spec in PARAMS.values():
        assert spec.check(spec.default) is None, spec.name
        assert spec.description


def test_detector_defaults_have_one_home(capsys):
    """Issue 19: the nodes' conf / iou / max_det, the API's (Detector, Detector.load) and the CLI's are one set."""
    import inspect

    from cone_perception.cli import main

    for fn in (detector.Detector.__init__, detector.Detector.load):
        sig = inspect.signature(fn).parameters
        assert {k: sig[k].default for k in ("conf", "iou", "max_det")} == \
            {k: PARAMS[k].default for k in ("conf", "iou", "max_det")}, fn.__qualname__
    for argv, texts in ((["detect"], ("confidence threshold", "NMS IoU threshold")), (["replay"], ("confidence threshold",))):
        with pytest.raises(SystemExit):
            main([*argv, "--help"])
        out = " ".join(capsys.readouterr().out.split())
        for text, key in zip(texts, ("conf", "iou")):
            assert f"{text} (default {PARAMS[key].default})" in out, (argv, text)


@pytest.mark.parametrize(
    ("name", "value", "words"),
    [
        ("conf", 1.5, "<= 1.0"),
        ("conf", -0.1, ">= 0.0"),
        ("conf", "high", "must be a float"),
        ("conf", True, "must be a float"),
        ("conf", math.nan, "finite"),
        ("max_det", 2.5, "must be a int"),
        ("max_det", 0, ">= 1"),
        ("publish_markers", 1, "must be a bool"),
        ("backend", "tensorrt", "one of auto, torch, torchscript, onnx"),
        ("debug_image_hz", 0.0, ">= 0.1"),
    ],
)
def test_param_check_names_the_reason(name, value, words):
    why = PARAMS[name].check(value)
    assert why is not None and words in why and name in why


def test_param_check_accepts_good_values():
    assert PARAMS["conf"].check(0.4) is None
    assert PARAMS["conf"].check(1) is None  # an int where a float is wanted is fine
    assert PARAMS["max_det"].check(300) is None
    assert PARAMS["input_transport"].check("compressed") is None
    assert ParamSpec("x", 1.0, "d", min=0.0, max=2.0).range_text() == "0.0 .. 2.0"


# -- live: a real client calling the node's parameter services ------------------------------------
def _set(ros: RosFixture, client: AsyncParameterClient, **values):
    fut = client.set_parameters([Parameter(k, value=v) for k, v in values.items()])
    assert ros.spin_until(fut.done, 10), "no answer from the parameter service"
    return fut.result().results


def _client(ros: RosFixture, node_name: str) -> AsyncParameterClient:
    client = AsyncParameterClient(ros.node("param_tester"), node_name)
    assert ros.spin_until(lambda: client.services_are_ready(), 10)
    return client


def test_mapping_node_publish_markers_at_run_time(ros: RosFixture) -> None:
    from cone_perception.nodes.mapping import MappingNode

    node = ros.add(MappingNode(context=ros.context))
    client = _client(ros, "mapping")
    t = ros.node("tester")
    markers, cones = Inbox(), Inbox()
    t.create_subscription(MarkerArray, "/cones/markers", markers, 10)
    t.create_subscription(PointCloud2, "/cones", cones, 10)
    pub = t.create_publisher(PointCloud2, "cone_boxes", 10)
    msg = _msgs.boxes_msg(boxes_from_arrays(np.array([[900.0, 700, 960, 800]]), [0.9], [0]), Header())
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0 and t.count_publishers("/cones/markers") > 0)
    assert ros.spin_until(lambda: (pub.publish(msg) or True) and len(markers.msgs) > 0, 10)

    (res,) = _set(ros, client, publish_markers=False)
    assert res.successful and node.publish_markers is False
    ros.spin_until(lambda: False, 0.3)  # what was in flight before the change arrives
    n_markers, n_cones = len(markers.msgs), len(cones.msgs)
    assert ros.spin_until(lambda: (pub.publish(msg) or True) and len(cones.msgs) >= n_cones + 3, 10)
    ros.spin_until(lambda: False, 0.3)
    assert len(markers.msgs) == n_markers  # no markers any more, cones still

    (res,) = _set(ros, client, publish_markers="yes")  # wrong type: refused, old value kept
    assert not res.successful and res.reason
    assert node.publish_markers is False and node.get_parameter("publish_markers").value is False
    (res,) = _set(ros, client, calibration="other")  # read-only once the node runs
    assert not res.successful and "read-only" in res.reason.lower().replace("read only", "read-only")


def test_detection_node_thresholds_and_descriptors(ros: RosFixture) -> None:
    from cone_perception.nodes.detection import DetectionNode

    node = ros.add(DetectionNode(context=ros.context))
    client = _client(ros, "detection")

    fut = client.describe_parameters(["conf", "max_det", "model", "debug_image_hz"])
    assert ros.spin_until(fut.done, 10)
    conf_d, max_det_d, model_d, hz_d = fut.result().descriptors
    assert conf_d.type == ParameterType.PARAMETER_DOUBLE and "confidence" in conf_d.description
    assert (conf_d.floating_point_range[0].from_value, conf_d.floating_point_range[0].to_value) == (0.0, 1.0)
    assert (max_det_d.integer_range[0].from_value, max_det_d.integer_range[0].to_value) == (1, 1000)
    assert model_d.read_only and not conf_d.read_only
    assert hz_d.floating_point_range[0].from_value == pytest.approx(0.1)

    (res,) = _set(ros, client, conf=0.6)
    assert res.successful and node.detector.conf == pytest.approx(0.6) and node.loader.kw["conf"] == pytest.approx(0.6)
    results = _set(ros, client, iou=0.3, max_det=7)
    assert all(r.successful for r in results)
    assert (node.detector.iou, node.detector.max_det) == (pytest.approx(0.3), 7)

    for bad in ({"conf": 1.5}, {"conf": "high"}, {"max_det": 0}, {"debug_image_hz": -1.0}):
        (res,) = _set(ros, client, **bad)
        assert not res.successful and res.reason, bad
    assert node.detector.conf == pytest.approx(0.6) and node.get_parameter("conf").value == pytest.approx(0.6)
    assert node.detector.max_det == 7 and node.debug.debug.limit.hz == 5.0


def test_detection_node_debug_image_only_when_on_and_subscribed(ros: RosFixture) -> None:
    """Switched on at run time; no drawing while nobody subscribes; a frame without boxes still gives
    an image (the band, "0 boxes"); a frame with cones gives their boxes drawn."""
    from cone_perception.adapter import DriverAdapter
    from cone_perception.bench.frames import rendered_frames
    from cone_perception.nodes.detection import DetectionNode

    node = ros.add(DetectionNode(context=ros.context))
    client = _client(ros, "detection")
    t = ros.node("tester")
    pub_info = t.create_publisher(CameraInfo, "image_cropped/camera_info", 2)
    pub_img = t.create_publisher(Image, "image_cropped", 2)
    boxes = Inbox()
    t.create_subscription(PointCloud2, "cone_boxes", boxes, 10)
    assert ros.spin_until(lambda: pub_img.get_subscription_count() > 0 and pub_info.get_subscription_count() > 0)
    w, h = CALIB.image_width, CALIB.image_height
    band = DriverAdapter(CALIB.crop, w, h).from_raw("yuv422_yuy2", w, h, 2 * w, rendered_frames(CALIB, 1)[0])
    empty = np.zeros_like(band)
    debug = Inbox()

    def stamped(inbox, sec):
        return [m for m in inbox.msgs if m.header.stamp.sec == sec]

    def send_until(img, sec, cond):
        """Publish ``img`` (camera_info first) stamped ``sec`` until ``cond()``; frames in flight from an
        earlier call carry another stamp, so they are told apart."""
        header = Header(frame_id="camera_optical")
        header.stamp.sec = sec
        info = _msgs.camera_info(CALIB.crop.camera_info_fields(w, h), header)
        msg = _msgs.bgr_image(img, header)
        assert ros.spin_until(lambda: (pub_info.publish(info) or pub_img.publish(msg) or True) and cond(), 30)

    assert node.debug.pub is None  # off by default: not even advertised
    assert all(r.successful for r in _set(ros, client, debug_image=True, debug_image_hz=100.0))
    assert node.debug.enabled and node.debug.pub is not None
    send_until(band, 1, lambda: len(stamped(boxes, 1)) >= 2)
    assert node.debug.published == 0  # nobody subscribed: nothing drawn

    t.create_subscription(Image, "image_cropped/debug", debug, 2)
    assert ros.spin_until(lambda: node.debug.pub.get_subscription_count() > 0)
    send_until(empty, 2, lambda: len(stamped(debug, 2)) > 0)
    first = stamped(debug, 2)[0]
    assert (first.encoding, first.width, first.height) == ("bgr8", band.shape[1], band.shape[0])
    assert all(len(_msgs.boxes_from_msg(m)) == 0 for m in stamped(boxes, 2))  # an empty frame: an image, no error
    assert node.stats.dropped_total == 0

    send_until(band, 3, lambda: len(stamped(debug, 3)) > 0)
    img = np.frombuffer(bytes(stamped(debug, 3)[0].data), np.uint8).reshape(band.shape)
    assert all(len(_msgs.boxes_from_msg(m)) > 0 for m in stamped(boxes, 3))
    assert (img != band).any(axis=2).mean() > 0.001  # boxes and labels drawn on the band


# -- every node declares exactly its table of the schema (issue 28) ----------------------------------
_NODE_CLASSES = {
    "driver_adapter": ("cone_perception.nodes.driver_adapter", "DriverAdapterNode"),
    "detection": ("cone_perception.nodes.detection", "DetectionNode"),
    "mapping": ("cone_perception.nodes.mapping", "MappingNode"),
    "pipeline": ("cone_perception.nodes.pipeline", "PipelineNode"),
    "cone_tracker": ("cone_perception.nodes.cone_tracker", "ConeTrackerNode"),
}


@pytest.mark.parametrize("kind", sorted(_NODE_CLASSES))
def test_each_node_declares_exactly_its_schema_table(ros: RosFixture, kind: str) -> None:
    """Names, types, defaults, read-only and descriptions as ``ros2 param describe`` sees them come from
    cone_perception/params.py (the pipeline with ``track: true`` declares the tracker's too)."""
    import importlib

    from cone_perception.params import node_params

    module, cls = _NODE_CLASSES[kind]
    overrides = [Parameter("track", value=True)] if kind == "pipeline" else []
    node = ros.add(getattr(importlib.import_module(module), cls)(context=ros.context, parameter_overrides=overrides))
    table = node_params(kind)
    declared = {n for n in node._parameters if n not in ("use_sim_time", "start_type_description_service")}
    assert declared == set(table)
    for name, spec in table.items():
        d = node.describe_parameter(name)
        assert d.description == spec.description and d.read_only == (not spec.dynamic), name
        value = node.get_parameter(name).value
        want = True if (kind, name) == ("pipeline", "track") else spec.ros_default
        assert (list(value) if isinstance(spec.default, tuple) else value) == want, name


def test_detection_node_needs_no_calibration_but_uses_one_for_the_debug_distances(ros: RosFixture) -> None:
    from cone_perception.nodes.detection import DetectionNode

    bare = ros.add(DetectionNode(context=ros.context))
    assert bare.debug.debug.mapper is None  # nothing loaded: the debug image shows no distances
    with_calib = ros.add(DetectionNode(context=ros.context, namespace="second",
                                       parameter_overrides=[Parameter("calibration", value="example_mainhoop")]))
    assert with_calib.debug.debug.mapper is not None and with_calib.debug.debug.mapper.calib.source == CALIB.source
