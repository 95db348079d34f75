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
