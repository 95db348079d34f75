"""The nodes' parameters: one table of name, default, type, range and description. ROS-free.

The nodes declare their parameters from :data:`PARAMS` (``nodes/_params.py`` turns a
:class:`ParamSpec` into an rclpy ``ParameterDescriptor``), so ``ros2 param describe`` shows the
same text and range as the README's parameter table. Parameters marked ``dynamic`` can be changed
at run time (``ros2 param set``): :meth:`ParamSpec.check` says why a value is refused, and the
node keeps its old value then.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Union

from .geometry.calib import DEFAULT_CAMERA

# -- the detector's defaults: one home. The nodes' parameters below, the API (``detector.Detector``,
# which imports them from here: this module loads no torch, the mapping node imports it) and the CLI
# (``detect``, ``replay``, ``eval``, ``bench table``) all read these.
#: What ``backend`` is unless chosen: ONNX Runtime on the CPU where installed, else torch.
DEFAULT_BACKEND = "auto"
#: The network's CPU threads where the car runs it (the nodes, ``bench``, ``replay``): one. With
#: every core busy, any other process that wakes (SLAM, planning, the OS) takes a core from one of
#: the threads for a scheduler tick and the whole forward waits for it; one thread leaves a core
#: free for them. Measured per backend and thread count: docs/benchmarks.md, "Backend and threads".
RUNTIME_THREADS = 1
#: Score threshold: boxes scoring at most this are dropped (also the operating point of ``eval``).
DEFAULT_CONF = 0.25
#: NMS IoU threshold (class-aware).
DEFAULT_IOU = 0.45
#: Most boxes per frame, best first. 300 (COCO's maxDets, what ``eval``'s mAP counts) for the nodes too:
#: a frame never holds that many cones above ``conf``, so on the car it only bounds NMS's output, and a
#: lower cap (the nodes' 100 before) would drop cones silently in a crowded frame (a start area, skidpad).
DEFAULT_MAX_DET = 300

Value = Union[bool, int, float, str]


@dataclass(frozen=True)
class ParamSpec:
    """One parameter. Its type is the type of ``default`` (bool, int, float or str)."""

    name: str
    default: Value
    description: str
    min: float | None = None
    max: float | None = None
    choices: tuple[str, ...] | None = None
    dynamic: bool = False  # changeable at run time; otherwise read-only once the node runs

    @property
    def type(self) -> type:
        return type(self.default)

    def check(self, value: object) -> str | None:
        """Why ``value`` is not acceptable (one line), or ``None`` when it is."""
        want = self.type
        if want is bool:
            ok = isinstance(value, bool)
        elif want is int:
            ok = isinstance(value, int) and not isinstance(value, bool)
        elif want is float:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        else:
            ok = isinstance(value, str)
        if not ok:
            return f"{self.name} must be a {want.__name__}, got {type(value).__name__} {value!r}"
        if want in (int, float):
            if not math.isfinite(float(value)):  # type: ignore[arg-type]
                return f"{self.name} must be finite, got {value!r}"
            if self.min is not None and value < self.min:  # type: ignore[operator]
                return f"{self.name} must be >= {self.min}, got {value!r}"
            if self.max is not None and value > self.max:  # type: ignore[operator]
                return f"{self.name} must be <= {self.max}, got {value!r}"
        if self.choices is not None and value not in self.choices:
            return f"{self.name} must be one of {', '.join(self.choices)}, got {value!r}"
        return None

    def range_text(self) -> str:
        """The constraint in words, for the descriptor and the README ("0.0 .. 1.0", "raw | compressed")."""
        if self.choices is not None:
            return " | ".join(self.choices)
        if self.min is not None or self.max is not None:
            lo = "" if self.min is None else f"{self.min}"
            hi = "" if self.max is None else f"{self.max}"
            return f"{lo} .. {hi}".strip()
        return ""


_SPECS = (
    ParamSpec("calibration", DEFAULT_CAMERA, "calibration YAML: a path, or a camera name in the package's calib/"),
    ParamSpec("input_transport", "raw", "camera input: raw (sensor_msgs/Image on image_raw) or compressed "
              "(sensor_msgs/CompressedImage on image_raw/compressed)", choices=("raw", "compressed")),
    ParamSpec("publish_markers", True, "also publish /cones/markers (visualization_msgs/MarkerArray) for rviz2",
              dynamic=True),
    ParamSpec("model", "", "model file (.pt checkpoint, TorchScript or ONNX); empty = the shipped default model"),
    ParamSpec("backend", DEFAULT_BACKEND, "inference backend; auto = ONNX Runtime on the CPU where installed, "
              "else torch", choices=("auto", "torch", "torchscript", "onnx")),
    ParamSpec("device", "cpu", "torch device: cpu, cuda or cuda:N"),
    ParamSpec("fp16", False, "half precision (CUDA only)"),
    ParamSpec("bf16", False, "bfloat16 autocast on the CPU (backend torch)"),
    ParamSpec("threads", RUNTIME_THREADS, "CPU threads of the network; 0 = the library's default", min=0, max=256),
    ParamSpec("conf", DEFAULT_CONF, "confidence threshold: boxes scoring at most this are dropped", min=0.0, max=1.0,
              dynamic=True),
    ParamSpec("iou", DEFAULT_IOU, "NMS IoU threshold: a box overlapping a better one of its class by more is dropped",
              min=0.0, max=1.0, dynamic=True),
    ParamSpec("max_det", DEFAULT_MAX_DET, "most boxes per frame (best first)", min=1, max=1000, dynamic=True),
    ParamSpec("debug_image", False, "publish image_cropped/debug (bgr8): the band with boxes, classes, scores "
              "and each cone's distance; drawn only while someone subscribes", dynamic=True),
    ParamSpec("far_rows", "", "pipeline: image rows V0,V1 also run at full resolution, the whole width (the far band "
              "for small, far cones; a second forward); empty = off"),
    ParamSpec("debug_image_hz", 5.0, "most debug images per second", min=0.1, max=100.0, dynamic=True),
)

#: Every node parameter by name.
PARAMS: dict[str, ParamSpec] = {s.name: s for s in _SPECS}
