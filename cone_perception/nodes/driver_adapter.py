"""driver_adapter node: camera frames -> ``image_cropped`` (bgr8) + ``image_cropped/camera_info``.

Parameters (generated from cone_perception/params.py by ``cone-perception params --write``):
  calibration (string, default example_mainhoop; a YAML path or a camera name in calib/): the
    camera's calibration YAML: a path, or a camera name in the package's calib/ (its image size,
    crop and downscale define the band; its homography and mount pose map boxes to metres)
  input_transport (string, default raw; raw | compressed): camera input: raw subscribes image_raw
    (sensor_msgs/Image: yuv422_yuy2 / yuyv, bgr8, rgb8), compressed subscribes image_raw/compressed
    (sensor_msgs/CompressedImage, JPEG/PNG)
  Also those of every node (input_timeout_s, max_frame_age_s, input_rate_hz).
"""

from __future__ import annotations

from ._common import QOS_IMAGE_OUT, PerceptionNode, run_node  # noqa: I001 (sets DDS env first)

from sensor_msgs.msg import CameraInfo, CompressedImage, Image

from ..adapter import DriverAdapter
from ..geometry.calib import load_calibration
from . import _msgs
from ._params import declare


class DriverAdapterNode(PerceptionNode):
    def __init__(self, **node_kwargs):
        super().__init__("driver_adapter", **node_kwargs)
        calib_name = declare(self, "calibration")
        transport = declare(self, "input_transport")
        calib = load_calibration(calib_name)
        self.adapter = DriverAdapter(calib.crop, calib.image_width, calib.image_height)
        self.camera_matrix = calib.camera_matrix
        self.info_fields = self.adapter.camera_info_fields()
        self.pub_image = self.create_publisher(Image, "image_cropped", QOS_IMAGE_OUT)
        self.pub_info = self.create_publisher(CameraInfo, "image_cropped/camera_info", QOS_IMAGE_OUT)
        self.subscribe_camera(transport)
        c = calib.crop
        self.get_logger().info(
            f"calibration {calib.source}: band rows {c.v0}-{c.v1} cols {c.u0}-{c.u1} of "
            f"{calib.image_width}x{calib.image_height}, downscale {c.downscale} -> {c.out_width}x{c.out_height}"
        )

    def on_raw(self, msg: Image) -> None:
        bgr = self.adapter.from_raw(msg.encoding, msg.width, msg.height, msg.step, msg.data)
        self._publish(bgr, msg.header)

    def on_compressed(self, msg: CompressedImage) -> None:
        self._publish(self.adapter.from_compressed(msg.data), msg.header)

    def _publish(self, bgr, header) -> None:
        # camera_info first: the detection node needs the crop before the image
        self.pub_info.publish(_msgs.camera_info(self.info_fields, header, self.camera_matrix))
        self.pub_image.publish(_msgs.bgr_image(bgr, header))


def main(args=None) -> int:
    return run_node(DriverAdapterNode, args, "driver_adapter")


if __name__ == "__main__":
    raise SystemExit(main())
