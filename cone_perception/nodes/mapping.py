"""mapping node: ``cone_boxes`` (full-image px) -> ``/cones`` (rear_axle metres) + ``/cones/markers``.

Parameters (generated from cone_perception/params.py by ``cone-perception params --write``):
  calibration (string, default example_mainhoop; a YAML path or a camera name in calib/): the
    camera's calibration YAML: a path, or a camera name in the package's calib/ (its image size,
    crop and downscale define the band; its homography and mount pose map boxes to metres)
  publish_markers (bool, default true; set at run time): also publish /cones/markers
    (visualization_msgs/MarkerArray) for rviz2
  attitude (string, default ""; "" | fixed | image | imu | fused): the camera attitude per frame
    (docs/attitude.md): fixed, image (from the boxes), imu or fused; empty = image when the
    calibration has a mount pose, else fixed (ask for imu / fused explicitly)
  imu_rest_deg (double[2], default [0.0, 0.0]): the IMU's pitch and roll (degrees) with the car at
    rest on the level ground of the calibration (cone-perception imu-rest measures it); for attitude
    imu / fused
  box_model (string, default auto; auto | model | rendered): how the image attitude reads the
    detector's boxes (docs/attitude.md, Box model): model = the box model measured on real frames
    beside the model file (MODEL.box_model.yaml; a model without one: a wide default, warned),
    rendered = the rendered drives' box-top table, auto = rendered for a synthetic camera's
    calibration (camera: synth), else model; shown on /diagnostics (attitude:box_model)
  min_height_ratio (double, default 0.8; 0.0 .. 0.99): a box lower than this x the height a cone of
    its class has where its foot maps, scoring under 0.5, is a mark on the ground (a painted line),
    not a cone: dropped, counted on /diagnostics (boxes_dropped: flat); 0 = off; needs a mount pose
    in the calibration, else it cannot act
  one_ray_range_m (double, default 40.0; 0.0 .. 200.0): two cones of one class (of two classes from
    15 m on) nearly on one viewing ray (under 0.15 m across it, under 2 m apart along it), the
    better-scored nearer than this (m from the camera), are one cone seen twice (two boxes of one
    far cone a few pixels apart): the better-scored stays, its covariance stretched to cover the
    other, the other is dropped, counted on /diagnostics (boxes_dropped: one_ray); 0 = off
  model (string, default ""; a .pt, .onnx or .torchscript path): the model file of the detection
    node that draws cone_boxes, for its box model (box_model); empty = the shipped default model
    (models/cone_detector.pt)
  Also those of every node (input_timeout_s, max_frame_age_s, input_rate_hz).
"""

from __future__ import annotations

from ._common import QOS_DATA, PerceptionNode, run_node  # noqa: I001 (sets DDS env first)

from sensor_msgs.msg import PointCloud2

from ..attitude import attitude_estimator, attitude_for_boxes
from ..geometry.calib import load_calibration
from ..mapping import ConeMapper, one_box_per_cone, validate_boxes
from ..records import BoxColumns
from . import _msgs
from ._attitude import declare_attitude, declare_box_model, report_attitude
from ._params import RuntimeParameters, declare


class MappingNode(PerceptionNode):
    def __init__(self, **node_kwargs):
        super().__init__("mapping", **node_kwargs)
        calib_name = declare(self, "calibration")
        markers = bool(declare(self, "publish_markers"))
        calib = load_calibration(calib_name)
        self.mapper = ConeMapper(calib, float(declare(self, "min_height_ratio")), float(declare(self, "one_ray_range_m")))
        self.health.watch("boxes_dropped", self.mapper.dropped)  # by cause (mapping.DROP_CAUSES)
        self.advertise_cones(calib.frame_id, markers)
        self.runtime = RuntimeParameters(self)
        self.runtime.register("publish_markers", lambda v: setattr(self, "publish_markers", bool(v)))
        mode, imu = declare_attitude(self)
        config, box_model = declare_box_model(self, calib, declare(self, "model"))
        self.attitude_mode, self.attitude = attitude_estimator(self.mapper, mode, imu, config)
        report_attitude(self, self.attitude_mode, self.attitude, box_model)
        self.subscribe_frames(PointCloud2, "cone_boxes", self.on_boxes, QOS_DATA)
        self.get_logger().info(f"calibration {calib.source}, frame {calib.frame_id}, max range {calib.max_range_m} m, "
                               f"attitude {self.attitude_mode}" + (f", box model {box_model}" if self.attitude else ""))

    def on_boxes(self, msg: PointCloud2) -> None:
        boxes = BoxColumns.of(_msgs.boxes_from_msg(msg))  # the message's boxes as columns, once
        validate_boxes(boxes)  # a bad message is dropped before it can move the attitude filter
        n_boxes = len(boxes)
        boxes = one_box_per_cone(boxes)  # as the fused pipeline does: a second box of one cone goes
        self.mapper.dropped["second_box"] += n_boxes - len(boxes)
        att = attitude_for_boxes(self.attitude, boxes, _msgs.stamp_ns(msg.header))
        self.publish_cones(self.mapper.map_boxes(boxes, att), msg.header)
        self.publish_attitude(att, msg.header)


def main(args=None) -> int:
    return run_node(MappingNode, args, "mapping")


if __name__ == "__main__":
    raise SystemExit(main())
