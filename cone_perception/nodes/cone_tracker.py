"""cone_tracker node: ``/cones`` (+ ``odom``) -> ``/cones/tracked`` + ``/cones/tracked/markers``.

A local map of the cones around the car with ids (:mod:`cone_perception.tracking`): tracks survive
missed frames, positions are fused over frames, each output keeps the capture stamp of its frame.

Parameters (generated from cone_perception/params.py by ``cone-perception params --write``):
  calibration (string, default example_mainhoop; a YAML path or a camera name in calib/): the
    camera's calibration YAML: a path, or a camera name in calib/ (its band's ground footprint tells
    where a cone should be seen)
  odom_topic (string, default odom): the car's motion (odom_type); empty = none (motion estimated
    from the cones)
  odom_type (string, default odometry; odometry | twist): odom_topic's type: odometry =
    nav_msgs/Odometry (twist.twist), twist = geometry_msgs/TwistStamped
  odom_max_age_s (double, default 0.1; > 0.0): odometry older than this (s) at a frame is not used
    for it (counted)
  publish_tracked_markers (bool, default true): also publish /cones/tracked/markers: cylinders with
    the track ids as text, for rviz2
  Also those of every node (input_timeout_s, max_frame_age_s, input_rate_hz).
"""

from __future__ import annotations

from ._common import QOS_DATA, PerceptionNode, run_node  # noqa: I001 (sets DDS env first)

from sensor_msgs.msg import PointCloud2

from ..geometry.calib import load_calibration
from . import _msgs
from ._params import declare
from ._tracking import NodeTracking


class ConeTrackerNode(PerceptionNode):
    def __init__(self, **node_kwargs):
        super().__init__("cone_tracker", **node_kwargs)
        calib = load_calibration(declare(self, "calibration"))
        self.tracking = NodeTracking(self, calib)
        self.subscribe_frames(PointCloud2, "/cones", self.on_cones, QOS_DATA)
        self.get_logger().info(f"calibration {calib.source}, frame {calib.frame_id}")

    def on_cones(self, msg: PointCloud2) -> None:
        self.tracking.process(_msgs.cones_from_msg(msg), msg.header)


def main(args=None) -> int:
    return run_node(ConeTrackerNode, args, "cone_tracker")


if __name__ == "__main__":
    raise SystemExit(main())
