"""mapping node: ``cone_boxes`` (full-image px) -> ``/cones`` (rear_axle metres) + ``/cones/markers``.

Parameters
  calibration (str, "example_mainhoop"): calibration YAML path or shipped camera name.
  publish_markers (bool, true): also publish ``/cones/markers`` for rviz2; changeable at run time.
  attitude (str, ""), imu_rest_deg (double[2]): camera attitude per frame (nodes/_attitude.py); the
    attitude used is published on ``cones/attitude`` (geometry_msgs/Vector3Stamped, x = roll,
    y = pitch, radians); ``imu`` (sensor_msgs/Imu) in for attitude ``imu`` / ``fused``.
"""

from __future__ import annotations

from ._common import QOS_DATA, PerceptionNode, run_node  # noqa: I001 (sets DDS env first)

from sensor_msgs.msg import PointCloud2

from ..attitude import attitude_estimator, attitude_for_boxes
from ..geometry.calib import load_calibration
from ..mapping import ConeMapper, validate_boxes
from . import _msgs
from ._attitude import declare_attitude, publish_attitude
from ._params import RuntimeParameters, declare


class MappingNode(PerceptionNode):
    def __init__(self, **node_kwargs):
        super().__init__("mapping", **node_kwargs)
        calib_name = declare(self, "calibration")
        markers = bool(declare(self, "publish_markers"))
        calib = load_calibration(calib_name)
        self.mapper = ConeMapper(calib)
        self.advertise_cones(calib.frame_id, markers)
        self.runtime = RuntimeParameters(self)
        self.runtime.register("publish_markers", lambda v: setattr(self, "publish_markers", bool(v)))
        mode, imu = declare_attitude(self)
        self.attitude_mode, self.attitude = attitude_estimator(self.mapper, mode, imu)
        self.subscribe_frames(PointCloud2, "cone_boxes", self.on_boxes, QOS_DATA)
        self.get_logger().info(f"calibration {calib.source}, frame {calib.frame_id}, max range {calib.max_range_m} m, "
                               f"attitude {self.attitude_mode}")

    def on_boxes(self, msg: PointCloud2) -> None:
        boxes = _msgs.boxes_from_msg(msg)
        validate_boxes(boxes)  # a bad message is dropped before it can move the attitude filter
        att = attitude_for_boxes(self.attitude, boxes, _msgs.stamp_ns(msg.header))
        self.publish_cones(self.mapper.map_boxes(boxes, att), msg.header)
        publish_attitude(self, att, msg.header)


def main(args=None) -> int:
    return run_node(MappingNode, args, "mapping")


if __name__ == "__main__":
    raise SystemExit(main())
