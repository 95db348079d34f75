"""The mapping node with a per-frame attitude: ``cones/attitude`` published with the frame's stamp,
the IMU (``imu``) used for attitude ``imu``, bad IMU messages dropped and counted, the attitude from
the image by default when the calibration has a mount pose."""

from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import Vector3Stamped
from rclpy.parameter import Parameter
from sensor_msgs.msg import Image, Imu, PointCloud2

from cone_perception.classes import BLUE, YELLOW
from cone_perception.geometry.calib import save_calibration
from cone_perception.nodes import _msgs
from cone_perception.nodes.mapping import MappingNode
from cone_perception.records import boxes_from_arrays
from cone_perception.synth.config import SynthConfig
from cone_perception.synth.motion import quat_from_rpy
from cone_perception.synth.scene import CarPose, SceneCamera

from rosutil import Inbox, RosFixture, ros  # noqa: F401 (ros is a fixture)

XY = np.array([[x, s * 1.8] for x in (5.0, 7.0, 9.0, 11.0, 13.0) for s in (-1, 1)])
CLS = [BLUE if y > 0 else YELLOW for _, y in XY]


def _boxes_msg(sec: int, pitch: float) -> PointCloud2:
    """Boxes of upright cones seen from a body pitched by ``pitch`` degrees (tip and base corners)."""
    from test_attitude import _cone_boxes

    sc = SceneCamera(SynthConfig(seed=0).camera(), CarPose(0.0, 0.0, 0.0, pitch, 0.0))
    b = _cone_boxes(sc, XY, np.array(CLS))
    msg = _msgs.boxes_msg(boxes_from_arrays(b, [0.9] * len(CLS), CLS), Image().header)
    msg.header.stamp.sec = sec
    return msg


def _imu(sec: int, pitch_deg: float, quat=None) -> Imu:
    m = Imu()
    m.header.stamp.sec = sec
    q = quat_from_rpy(0.0, np.radians(pitch_deg), 0.2) if quat is None else quat
    m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w = (float(v) for v in q)
    return m


@pytest.fixture
def calib_path(tmp_path):
    return str(save_calibration(SynthConfig(seed=0).calibration(), tmp_path / "synth.yaml"))


@pytest.mark.parametrize("mode", ["", "imu"])
def test_mapping_node_publishes_the_attitude(ros: RosFixture, calib_path, mode) -> None:
    node = ros.add(MappingNode(context=ros.context, parameter_overrides=[
        Parameter("calibration", value=calib_path), Parameter("attitude", value=mode), Parameter("publish_markers", value=False)]))
    assert node.attitude_mode == (mode or "image")
    t = ros.node("tester")
    att = Inbox()
    t.create_subscription(Vector3Stamped, "cones/attitude", att, 10)
    pub = t.create_publisher(PointCloud2, "cone_boxes", 10)
    imu_pub = t.create_publisher(Imu, "imu", 10)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0)
    if mode == "imu":
        assert ros.spin_until(lambda: imu_pub.get_subscription_count() > 0)
        imu_pub.publish(_imu(40, 0.0, quat=(np.nan, 0.0, 0.0, 1.0)))  # NaN: dropped
        imu_pub.publish(_imu(40, 0.0, quat=(0.0, 0.0, 0.0, 1.2)))  # not a unit quaternion: dropped
        imu_pub.publish(_imu(41, 1.0))
        assert ros.spin_until(lambda: node.attitude.imu.counts.used >= 1, 10)
        assert node.stats.dropped["imu_nan"] == 1 and node.stats.dropped["imu_quaternion_norm"] == 1
    assert ros.spin_until(lambda: (pub.publish(_boxes_msg(41, 1.0)) or True) and att.msgs, 15)
    m = att.msgs[0]
    assert m.header.stamp.sec == 41 and m.header.frame_id == "rear_axle"
    assert np.degrees(m.vector.y) == pytest.approx(1.0, abs=0.3 if mode == "" else 1e-6)


def _diagnostics(node):
    """The node's next /diagnostics status (published at once, captured)."""
    sent = []
    pub, node._diag_pub.publish = node._diag_pub.publish, sent.append
    try:
        node._publish_diagnostics()
    finally:
        node._diag_pub.publish = pub
    return sent[-1].status[0]


@pytest.mark.parametrize("choice", ["auto", "model"])
def test_mapping_node_reads_boxes_through_the_box_model_and_reports_calibration_fallbacks(
        ros: RosFixture, calib_path, choice) -> None:
    """issue 27: the node's image fit reads the boxes through the detector's box model (``box_model``: auto =
    the rendered table for a synthetic camera, model = the measured sidecar of the model file), and
    ``/diagnostics`` carries the box model in use and the frames mapped with the calibration's H."""
    from cone_perception.attitude.box_files import read_box_model
    from cone_perception.resources import default_model_path

    node = ros.add(MappingNode(context=ros.context, parameter_overrides=[
        Parameter("calibration", value=calib_path), Parameter("box_model", value=choice),
        Parameter("publish_markers", value=False)]))
    node._diag_timer.cancel()  # the test takes the diagnostics itself
    if choice == "auto":  # a synthetic camera's calibration: the rendered drives' table
        assert node.attitude.cfg.box_model is None
    else:
        assert node.attitude.cfg.box_model == read_box_model(default_model_path()) is not None
    t = ros.node("tester")
    att = Inbox()
    t.create_subscription(Vector3Stamped, "cones/attitude", att, 10)
    pub = t.create_publisher(PointCloud2, "cone_boxes", 10)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0)
    one = _boxes_msg(50, 0.0)
    one.data, one.width, one.row_step = one.data[: one.point_step], 1, one.point_step  # a single cone: no fit
    assert ros.spin_until(lambda: (pub.publish(one) or True) and node.attitude.counts.too_few >= 1, 15)
    # no history and too few cones: each such frame is mapped with the calibration's H, counted
    c = node.attitude.counts
    assert c.calibration == c.too_few >= 1 and c.fitted == 0
    assert ros.spin_until(lambda: (pub.publish(_boxes_msg(51, 1.0)) or True) and c.fitted >= 1, 15)
    values = {kv.key: kv.value for kv in _diagnostics(node).values}
    assert values["attitude:used_calibration"] == str(c.calibration) and c.calibration >= c.too_few >= 1
    assert values["attitude:fitted"] == str(c.fitted) and values["attitude:too_few_cones"] == str(c.too_few)
    assert values["attitude:mode"] == "image"
    if choice == "auto":
        assert values["attitude:box_model"] == "rendered table (synthetic camera)"
    else:
        assert values["attitude:box_model"].startswith("measured (cone_detector.pt.box_model.yaml")


def test_mapping_node_fixed_attitude_reports_no_box_model(ros: RosFixture, calib_path) -> None:
    node = ros.add(MappingNode(context=ros.context, parameter_overrides=[
        Parameter("calibration", value=calib_path), Parameter("attitude", value="fixed")]))
    node._diag_timer.cancel()
    values = {kv.key: kv.value for kv in _diagnostics(node).values}
    assert values["attitude:mode"] == "fixed" and values["attitude:box_model"] == "none (attitude fixed)"
    assert not any(k.startswith("attitude:used") for k in values)


def test_pipeline_node_passes_its_detectors_box_model(ros: RosFixture) -> None:
    """issue 27: the pipeline node's image fit reads the boxes through the box model of the model it runs (here
    not the default one), on a real camera's calibration (``box_model`` auto = the model's)."""
    from cone_perception.attitude.box_files import read_box_model
    from cone_perception.nodes.pipeline import PipelineNode
    from cone_perception.resources import default_model_path, models_dir

    model = models_dir() / "cone_detector_n.pt"
    node = ros.add(PipelineNode(context=ros.context, parameter_overrides=[Parameter("model", value=str(model))]))
    node._diag_timer.cancel()
    bm = node.pipeline.attitude.cfg.box_model
    assert node.pipeline.attitude_mode == "image"
    assert bm == read_box_model(model) and bm != read_box_model(default_model_path())
    values = {kv.key: kv.value for kv in _diagnostics(node).values}
    assert values["attitude:box_model"].startswith("measured (cone_detector_n.pt.box_model.yaml")
    assert values["attitude:used_calibration"] == "0"
