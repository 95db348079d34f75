"""detection node: ``image_cropped`` (bgr8) + its ``camera_info`` -> ``cone_boxes`` (full-image px).

Parameters
  model (str, "" = the shipped default model), backend ("auto" | "torch" | "torchscript" | "onnx";
  auto: ONNX Runtime on the CPU where installed, else torch), device ("cpu" | "cuda" | "cuda:N"),
  fp16 (bool, CUDA only), bf16 (bool, CPU autocast, backend torch), conf (0.25), iou (0.45),
  max_det (100), threads (1, see detector.RUNTIME_THREADS; 0 = library default), calibration
  (for the debug image's distances), debug_image (false), debug_image_hz (5).
  Changeable at run time (``ros2 param set``): conf, iou, max_det, debug_image, debug_image_hz.
  Descriptions and ranges: ``cone_perception/params.py`` (``ros2 param describe``).
The crop and downscale of each image come from the newest ``image_cropped/camera_info``
(``roi``, ``binning``), so boxes go out in full-image pixels whatever the band. A fixed-size network
built from a checkpoint (ONNX Runtime, the CPU default) is rebuilt for the band's size when the
first ``camera_info`` shows another one (once; frames meanwhile are dropped as any late frame).
"""

from __future__ import annotations

from ._common import QOS_DATA, QOS_IMAGE_IN, PerceptionNode, run_node  # noqa: I001 (sets DDS env first)

import time

from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from ..calib import load_calibration
from ..errors import FrameError
from ..mapping import ConeMapper
from . import _msgs
from ._debug import DebugImagePublisher
from ._detector_params import DetectorLoader
from ._params import RuntimeParameters, declare


class DetectionNode(PerceptionNode):
    def __init__(self, **node_kwargs):
        super().__init__("detection", **node_kwargs)
        self.loader = DetectorLoader(self)
        self.detector = self.loader.load()
        self.runtime = RuntimeParameters(self)
        for name in DetectorLoader.RUNTIME:
            self.runtime.register(name, lambda v, name=name: self.loader.set_threshold(self.detector, name, v))
        self.debug = DebugImagePublisher(self, ConeMapper(load_calibration(declare(self, "calibration"))), self.runtime)
        self.crop = None
        self.pending = None  # newest image received before any camera_info
        self.pub_boxes = self.create_publisher(PointCloud2, "cone_boxes", QOS_DATA)
        self.create_subscription(CameraInfo, "image_cropped/camera_info", self.on_info, QOS_IMAGE_IN)
        self.create_subscription(Image, "image_cropped", self.guarded(self.on_image), QOS_IMAGE_IN)

    def on_info(self, msg: CameraInfo) -> None:
        try:
            self.crop = _msgs.crop_from_camera_info(msg)
        except ValueError as e:
            self.get_logger().warning(f"ignoring camera_info: {e}", throttle_duration_sec=5.0)
            return
        band = (self.crop.out_width, self.crop.out_height)
        if not self.detector.runs_band_as_is(band):  # a fixed-size network would letterbox this band
            self.get_logger().info(f"band {band[0]}x{band[1]} is not the model input "
                                   f"{self.detector.imgsz[0]}x{self.detector.imgsz[1]}: building the network for it")
            self.detector = self.loader.load(band)
        if self.pending is not None:  # an image that came before the first camera_info
            pending, self.pending = self.pending, None
            self.guarded(self.on_image)(pending)

    def on_image(self, msg: Image) -> bool | None:
        if self.crop is None:
            if self.pending is not None:
                self.pending = msg  # keep the newest only; the older one is dropped, counted below
                raise FrameError("no_camera_info", "no image_cropped/camera_info received yet: crop unknown")
            self.pending = msg
            return False  # processed when the first camera_info arrives
        if (msg.width, msg.height) != (self.crop.out_width, self.crop.out_height):
            raise FrameError(
                "size_mismatch",
                f"image {msg.width}x{msg.height} does not match camera_info crop "
                f"{self.crop.out_width}x{self.crop.out_height}",
            )
        t0 = time.perf_counter()
        band = _msgs.image_to_bgr(msg)
        boxes = self.detector.detect(band, self.crop)
        self.pub_boxes.publish(_msgs.boxes_msg(boxes, msg.header))
        self.debug.publish(band, boxes, self.crop, msg.header)
        self.get_logger().debug(
            f"{len(boxes)} boxes in {(time.perf_counter() - t0) * 1e3:.1f} ms "
            + " ".join(f"{k}={v:.1f}" for k, v in self.detector.timing.items())
        )


def main(args=None) -> int:
    return run_node(DetectionNode, args, "detection")


if __name__ == "__main__":
    raise SystemExit(main())
