"""mapping node: ``cone_boxes`` (full-image px) -> ``/cones`` (rear_axle metres) + ``/cones/markers``.

Parameters
  calibration (str, "example_mainhoop"): calibration YAML path or shipped camera name.
  publish_markers (bool, true): also publish ``/cones/markers`` for rviz2; changeable at run time.
"""

from __future__ import annotations

from ._common import QOS_DATA, PerceptionNode, run_node  # noqa: I001 (sets DDS env first)

from sensor_msgs.msg import PointCloud2

from ..calib import load_calibration
from ..mapping import ConeMapper
from . import _msgs
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
        self.create_subscription(PointCloud2, "cone_boxes", self.guarded(self.on_boxes), QOS_DATA)
        self.get_logger().info(f"calibration {calib.source}, frame {calib.frame_id}, max range {calib.max_range_m} m")

    def on_boxes(self, msg: PointCloud2) -> None:
        self.publish_cones(self.mapper.map_boxes(_msgs.boxes_from_msg(msg)), msg.header)


def main(args=None) -> int:
    return run_node(MappingNode, args, "mapping")


if __name__ == "__main__":
    raise SystemExit(main())
