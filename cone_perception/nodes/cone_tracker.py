"""cone_tracker node: ``/cones`` (+ ``odom``) -> ``/cones/tracked`` + ``/cones/tracked/markers``.

A local map of the cones around the car with ids (:mod:`cone_perception.tracking`): tracks survive
missed frames, positions are fused over frames, each output keeps the capture stamp of its frame.

Parameters
  calibration (str, "example_mainhoop"): the camera's calibration (its band's ground footprint
    tells where a cone should be seen).
  and those of :mod:`cone_perception.nodes._tracking` (odom_topic, odom_type, odom_max_age_s,
  publish_tracked_markers).
"""

from __future__ import annotations

from ._common import QOS_DATA, PerceptionNode, run_node  # noqa: I001 (sets DDS env first)

from sensor_msgs.msg import PointCloud2

from ..geometry.calib import DEFAULT_CAMERA, load_calibration
from . import _msgs
from ._tracking import NodeTracking


class ConeTrackerNode(PerceptionNode):
    def __init__(self, **node_kwargs):
        super().__init__("cone_tracker", **node_kwargs)
        calib = load_calibration(self.declare_parameter("calibration", DEFAULT_CAMERA).value)
        self.tracking = NodeTracking(self, calib)
        self.subscribe_frames(PointCloud2, "/cones", self.on_cones, QOS_DATA)
        self.get_logger().info(f"calibration {calib.source}, frame {calib.frame_id}")

    def on_cones(self, msg: PointCloud2) -> None:
        self.tracking.process(_msgs.cones_from_msg(msg), msg.header)


def main(args=None) -> int:
    return run_node(ConeTrackerNode, args, "cone_tracker")


if __name__ == "__main__":
    raise SystemExit(main())
