"""detection node: ``image_cropped`` (bgr8) + its ``camera_info`` -> ``cone_boxes`` (full-image px).

The crop and downscale of each image come from the newest ``image_cropped/camera_info``
(``roi``, ``binning``), so boxes go out in full-image pixels whatever the band. A ``camera_info`` is
validated as an image is (sizes, roi inside the image, binning 1/2/4, band size:
:func:`cone_perception.crop.camera_info_crop`); a bad one is dropped and counted, the node keeps its
crop. A fixed-size network built from a checkpoint (ONNX Runtime, the CPU default) is built for the
band's size when a ``camera_info`` shows another one: once per distinct band, at most
:data:`MAX_NETWORK_BANDS` (kept; frames meanwhile are dropped as any late frame). The node needs no
calibration; given one (``calibration``), its debug image shows each cone's distance.

Parameters (generated from cone_perception/params.py by ``cone-perception params --write``):
  model (string, default ""; a .pt, .onnx or .torchscript path): model file (.pt checkpoint,
    TorchScript or ONNX); empty = the shipped default model (models/cone_detector.pt)
  backend (string, default auto; auto | torch | torchscript | onnx): inference backend; auto = ONNX
    Runtime for a checkpoint on the CPU where installed, else eager torch; an exported file runs
    with its own
  device (string, default cpu; cpu, cuda, cuda:N): where the network runs: torch's device, or with
    backend onnx ONNX Runtime's TensorRT (first) or CUDA provider on that GPU (docs/jetson.md)
  fp16 (bool, default false): half precision on the GPU (CUDA only): torch in fp16, or with backend
    onnx TensorRT's engine built in fp16
  bf16 (bool, default false): bfloat16 autocast on the CPU (backend torch); pays only on CPUs with
    native bf16
  threads (int, default 1; 0 .. 256): the network's CPU threads; 0 = the library's default (all
    cores); 1 leaves the other cores to the rest of the car (docs/benchmarks.md, Backend and
    threads); with a far strip and 2 or more, the band's and the strip's forwards run at once,
    threads // 2 each (docs/detector.md, Far band)
  conf (double, default 0.25; 0.0 .. 1.0; set at run time): confidence threshold: boxes scoring at
    most this are dropped
  iou (double, default 0.45; 0.0 .. 1.0; set at run time): NMS IoU threshold (class-aware): a box
    overlapping a better one of its class by more is dropped
  max_det (int, default 300; 1 .. 1000; set at run time): most boxes per frame (best first)
  debug_image (bool, default false; set at run time): publish image_cropped/debug (bgr8): the band
    with boxes, classes, scores and each cone's distance; drawn only while someone subscribes
  debug_image_hz (double, default 5.0; 0.1 .. 100.0; set at run time): most debug images per second
  calibration (string, default ""; empty, a YAML path or a camera name in calib/): optional: a
    calibration (a path, or a camera name in calib/) for the cones' distances on the debug image;
    empty = none loaded, the debug image shows no distances (the node itself needs none: the crop
    comes with each camera_info)
  Also those of every node (input_timeout_s, max_frame_age_s, input_rate_hz).
"""

from __future__ import annotations

from ._common import QOS_DATA, PerceptionNode, run_node  # noqa: I001 (sets DDS env first)

import time

from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from ..geometry.calib import load_calibration
from ..errors import FrameError
from ..mapping import ConeMapper
from . import _msgs
from ._debug import DebugImagePublisher
from ._detector_params import DetectorLoader
from ._params import RuntimeParameters, declare

#: Distinct band sizes the node builds a fixed-size network for (each 1-3 s, blocking); a camera_info
#: with yet another band is dropped (``band_limit``) and the node keeps its band.
MAX_NETWORK_BANDS = 3


class DetectionNode(PerceptionNode):
    def __init__(self, **node_kwargs):
        super().__init__("detection", **node_kwargs)
        self.loader = DetectorLoader(self)
        self.detector = self.loader.load()
        self.runtime = RuntimeParameters(self)
        for name in DetectorLoader.RUNTIME:
            self.runtime.register(name, lambda v, name=name: self.loader.set_threshold(self.detector, name, v))
        calib_name = declare(self, "calibration")  # optional: only the debug image's distances use it
        self.debug = DebugImagePublisher(self, ConeMapper(load_calibration(calib_name)) if calib_name else None,
                                         self.runtime)
        self.crop = None
        self.pending = None  # newest image received before any camera_info
        self.networks = [self.detector]  # the model's own and those built for a band (MAX_NETWORK_BANDS more)
        self.pub_boxes = self.create_publisher(PointCloud2, "cone_boxes", QOS_DATA)
        self.subscribe_frames(CameraInfo, "image_cropped/camera_info", self.on_info, frames=False)  # not a frame
        self.subscribe_frames(Image, "image_cropped", self.on_image)
        self.image_stream = self.health.streams[self.resolve_topic_name("image_cropped")]

    def on_info(self, msg: CameraInfo) -> None:
        crop = _msgs.crop_from_camera_info(msg)  # validated: a bad camera_info is dropped and counted
        band = (crop.out_width, crop.out_height)
        # a fixed-size network would letterbox a band of another size: use (or build, once) one for it
        det = next((d for d in (self.detector, *self.networks) if d.runs_band_as_is(band)), None)
        if det is None:
            if len(self.networks) > MAX_NETWORK_BANDS:
                raise FrameError("band_limit", f"camera_info band {band[0]}x{band[1]} would need another network; "
                                               f"{MAX_NETWORK_BANDS} bands built already: keeping the current band")
            self.get_logger().info(f"band {band[0]}x{band[1]} is not the model input "
                                   f"{self.detector.imgsz[0]}x{self.detector.imgsz[1]}: building the network for it")
            det = self.loader.load(band)
            self.networks.append(det)
        self.detector = det
        self.crop = crop
        if self.pending is not None:  # an image that came before the first camera_info
            pending, self.pending = self.pending, None
            self.run_guarded(self.on_image, pending, self.image_stream)

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
