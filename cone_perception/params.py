"""Every node parameter in one place: name, type, default, range, description, and whether it can be
changed at run time; which node declares which, and each node's topics. ROS-free.

The nodes declare their parameters from here (``nodes/_params.py`` turns a :class:`ParamSpec` into an
rclpy ``ParameterDescriptor``: description, range, ``read_only`` unless ``dynamic``), so ``ros2 param
describe`` shows the same text and range as the tables of docs/nodes.md, the node modules' docstrings and each
node executable's ``--help``, which are all generated from :data:`NODES` (``cone-perception params
--write`` rewrites those tables and the docstrings; a test fails when they drift). Parameters
marked ``dynamic`` can be changed at run time (``ros2 param set``): :meth:`ParamSpec.check` says why a
value is refused, and the node keeps its old value then.
"""

from __future__ import annotations

import dataclasses
import math
import textwrap
from dataclasses import dataclass
from typing import Union

from .errors import ConfigError
from .geometry.calib import DEFAULT_CAMERA
from .resources import FAR_MODEL_DEFAULT

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

#: Boxes lower than this x the height a cone of their class has, standing where the box's foot maps, are marks on
#: the ground, not cones (``mapping.ConeMapper``'s ``min_height_ratio``; docs/benchmarks.md, "Flat boxes").
DEFAULT_MIN_HEIGHT_RATIO = 0.8
#: Two cones nearly on one viewing ray (0.15 m across, 2 m along it), the better-scored nearer than this (m), are one
#: cone seen twice (``mapping.ConeMapper``'s ``one_ray_range_m``; docs/benchmarks.md, "Duplicates on one ray"): the
#: whole range the rule was measured over.
DEFAULT_ONE_RAY_RANGE_M = 40.0

Value = Union[bool, int, float, str, "tuple[float, ...]"]

_ROS_TYPE_NAMES = {bool: "bool", int: "int", float: "double", str: "string"}


@dataclass(frozen=True)
class ParamSpec:
    """One parameter. Its type is the type of ``default`` (bool, int, float or str; a tuple of floats is a
    ROS double array of ``len(default)`` elements)."""

    name: str
    default: Value
    description: str  # plain text: ros2 param describe, --help, docstrings and docs/nodes.md
    min: float | None = None
    max: float | None = None
    choices: tuple[str, ...] | None = None
    dynamic: bool = False  # changeable at run time; otherwise read-only once the node runs
    min_exclusive: bool = False  # the value must be above ``min``, not equal to it
    values: str = ""  # the accepted values in words where no range is checked ("cpu, cuda, cuda:N")

    @property
    def type(self) -> type:
        return type(self.default)

    @property
    def ros_type(self) -> str:
        """The type as ROS names it: bool, int, double, string, double[N]."""
        if isinstance(self.default, tuple):
            return f"double[{len(self.default)}]"
        return _ROS_TYPE_NAMES[self.type]

    @property
    def ros_default(self):
        """The default as rclpy declares it (a list for an array)."""
        return list(self.default) if isinstance(self.default, tuple) else self.default

    def check(self, value: object) -> str | None:
        """Why ``value`` is not acceptable (one line), or ``None`` when it is."""
        if isinstance(self.default, tuple):
            return self._check_array(value)
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
            return self._check_number(value)
        if self.choices is not None and value not in self.choices:
            return f"{self.name} must be one of {', '.join(repr(c) if not c else c for c in self.choices)}, got {value!r}"
        return None

    def _check_number(self, value, what: str = "") -> str | None:
        what = what or self.name
        if not math.isfinite(float(value)):
            return f"{what} must be finite, got {value!r}"
        if self.min is not None and self.min_exclusive and not value > self.min:
            return f"{what} must be > {self.min}, got {value!r}"
        if self.min is not None and value < self.min:
            return f"{what} must be >= {self.min}, got {value!r}"
        if self.max is not None and value > self.max:
            return f"{what} must be <= {self.max}, got {value!r}"
        return None

    def _check_array(self, value: object) -> str | None:
        n = len(self.default)  # type: ignore[arg-type]
        try:
            items = list(value)  # type: ignore[call-overload]
        except TypeError:
            items = None
        if items is None or isinstance(value, (str, bytes)) or len(items) != n or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in items):
            return f"{self.name} must be a list of {n} numbers, got {value!r}"
        for i, v in enumerate(items):
            why = self._check_number(v, f"{self.name}[{i}]")
            if why:
                return why
        return None

    def range_text(self) -> str:
        """The constraint in words, for the descriptor and the docs ("0.0 .. 1.0", ">= 0", "raw | compressed")."""
        if self.choices is not None:
            return " | ".join(c or '""' for c in self.choices)
        if self.min is not None and self.max is not None:
            return f"{self.min} .. {self.max}"
        if self.min is not None:
            return f"{'>' if self.min_exclusive else '>='} {self.min}"
        if self.max is not None:
            return f"<= {self.max}"
        return self.values

    def default_text(self) -> str:
        """The default as written in a parameter file: ``true``, ``0.25``, ``""``, ``[0.0, 0.0]``."""
        d = self.default
        if isinstance(d, bool):
            return "true" if d else "false"
        if isinstance(d, str):
            return d if d else '""'
        if isinstance(d, tuple):
            return "[" + ", ".join(str(float(v)) for v in d) + "]"
        return str(d)


def _p(*args, **kwargs) -> ParamSpec:
    return ParamSpec(*args, **kwargs)


# -- every parameter, by theme. Descriptions are plain text (ros2 param describe shows them as they are).
_COMMON = (  # declared by every node (nodes/_common.py, PerceptionNode)
    _p("input_timeout_s", 1.0, "silence on an input longer than this (s) is an ERROR on /diagnostics; 0 = never",
       min=0.0),
    _p("max_frame_age_s", 0.0, "a frame whose header stamp is older than this (s) on arrival is counted stale; "
       "0 = off (bag replays carry old stamps; set it on the car, where the camera stamps with the node's clock)",
       min=0.0),
    _p("input_rate_hz", 0.0, "the camera's nominal rate (Hz), for counting the frames missing from its stamps; "
       "0 = learnt from the stamps (per frame sent, from the publisher's sequence numbers: right at any load)",
       min=0.0),
)
_CAMERA = (
    _p("calibration", DEFAULT_CAMERA, "the camera's calibration YAML: a path, or a camera name in the package's "
       "calib/ (its image size, crop and downscale define the band; its homography and mount pose map boxes to "
       "metres)", values="a YAML path or a camera name in calib/"),
    _p("input_transport", "raw", "camera input: raw subscribes image_raw (sensor_msgs/Image: yuv422_yuy2 / yuyv, "
       "bgr8, rgb8), compressed subscribes image_raw/compressed (sensor_msgs/CompressedImage, JPEG/PNG)",
       choices=("raw", "compressed")),
)
_DETECTOR = (
    _p("model", "", "model file (.pt checkpoint, TorchScript or ONNX); empty = the shipped default model "
       "(models/cone_detector.pt)", values="a .pt, .onnx or .torchscript path"),
    _p("backend", DEFAULT_BACKEND, "inference backend; auto = ONNX Runtime for a checkpoint on the CPU where "
       "installed, else eager torch; an exported file runs with its own", choices=("auto", "torch", "torchscript", "onnx")),
    _p("device", "cpu", "where the network runs: torch's device, or with backend onnx ONNX Runtime's TensorRT (first) "
       "or CUDA provider on that GPU (docs/jetson.md)", values="cpu, cuda, cuda:N"),
    _p("fp16", False, "half precision on the GPU (CUDA only): torch in fp16, or with backend onnx TensorRT's engine "
       "built in fp16"),
    _p("bf16", False, "bfloat16 autocast on the CPU (backend torch); pays only on CPUs with native bf16"),
    _p("threads", RUNTIME_THREADS, "the network's CPU threads; 0 = the library's default (all cores); 1 leaves the "
       "other cores to the rest of the car (docs/benchmarks.md, Backend and threads); with a far strip and 2 or more, "
       "the band's and the strip's forwards run at once, threads // 2 each (docs/detector.md, Far band)", min=0, max=256),
    _p("conf", DEFAULT_CONF, "confidence threshold: boxes scoring at most this are dropped", min=0.0, max=1.0,
       dynamic=True),
    _p("iou", DEFAULT_IOU, "NMS IoU threshold (class-aware): a box overlapping a better one of its class by more is "
       "dropped", min=0.0, max=1.0, dynamic=True),
    _p("max_det", DEFAULT_MAX_DET, "most boxes per frame (best first)", min=1, max=1000, dynamic=True),
)
_DEBUG = (
    _p("debug_image", False, "publish image_cropped/debug (bgr8): the band with boxes, classes, scores and each "
       "cone's distance; drawn only while someone subscribes", dynamic=True),
    _p("debug_image_hz", 5.0, "most debug images per second", min=0.1, max=100.0, dynamic=True),
)
_MAPPING = (
    _p("publish_markers", True, "also publish /cones/markers (visualization_msgs/MarkerArray) for rviz2", dynamic=True),
    _p("attitude", "", "the camera attitude per frame (docs/attitude.md): fixed, image (from the boxes), imu or fused; "
       "empty = image when the calibration has a mount pose, else fixed (ask for imu / fused explicitly)",
       choices=("", "fixed", "image", "imu", "fused")),
    _p("imu_rest_deg", (0.0, 0.0), "the IMU's pitch and roll (degrees) with the car at rest on the level ground of "
       "the calibration (cone-perception imu-rest measures it); for attitude imu / fused"),
    _p("box_model", "auto", "how the image attitude reads the detector's boxes (docs/attitude.md, Box model): model = "
       "the box model measured on real frames beside the model file (MODEL.box_model.yaml; a model without one: a "
       "wide default, warned), rendered = the rendered drives' box-top table, auto = rendered for a synthetic "
       "camera's calibration (camera: synth), else model; shown on /diagnostics (attitude:box_model)",
       choices=("auto", "model", "rendered")),
    _p("min_height_ratio", DEFAULT_MIN_HEIGHT_RATIO, "a box lower than this x the height a cone of its class has "
       "where its foot maps, scoring under 0.5, is a mark on the ground (a painted line), not a cone: dropped, counted on /diagnostics "
       "(boxes_dropped: flat); 0 = off; needs a mount pose in the calibration, else it cannot act", min=0.0, max=0.99),
    _p("one_ray_range_m", DEFAULT_ONE_RAY_RANGE_M, "two cones of one class (of two classes from 15 m on) nearly on one "
       "viewing ray (under 0.15 m across it, under 2 m apart along it), the better-scored nearer than this (m from the camera), are one cone seen twice (two boxes "
       "of one far cone a few pixels apart): the better-scored stays, its covariance stretched to cover the other, the "
       "other is dropped, counted on /diagnostics (boxes_dropped: one_ray); 0 = off", min=0.0, max=200.0),
)
_PIPELINE = (
    _p("far_rows", "auto", "the far band: image rows also run at full resolution, the whole width, for small, far "
       "cones (a second forward; docs/detector.md, Far band). auto = the calibration's far strip (the rows where "
       "cones 15-40 m ahead stand, moved each frame with the attitude; none where the calibration has no "
       "camera_matrix); V0,V1 = these rows, fixed; none or empty = no far band (not off: ROS reads off as a "
       "boolean)", values="auto, none, or V0,V1"),
    _p("band_rows", "crop", "the band's image rows (its columns and downscale stay the calibration's): crop = the "
       "calibration's crop (the default); auto = placed from the calibration: from the tops of cones as far as the "
       "far strip's near end (without a strip: max_range_m) to the crop's bottom, with the strip's attitude margins, "
       "a multiple of 32 rows at the band's scale (docs/detector.md, Band rows; on the shipped calibrations it is not "
       "smaller than their crop); V0,V1 = these rows", values="crop, auto, or V0,V1"),
    _p("band_split", "none", "the band in two (docs/detector.md, Row-scaled band): none = one band at the "
       "calibration's downscale (the default); auto = split from the calibration: the near rows, where every cone is "
       "at least 48 px tall, at a quarter of full resolution, the rows above at the band's half, overlapping by a "
       "cone (refused naming band_split where the calibration leaves nothing to split); N0,U1 = the near band from "
       "row N0, the upper band to row U1", values="none, auto, or N0,U1"),
    _p("far_model", FAR_MODEL_DEFAULT, "the far band's model: auto = the shipped far-strip model (models/cone_detector_far.pt, "
       "trained for its full-resolution scale: more small cones; the image attitude reads its boxes through its own "
       "box model, box_model); band or empty = the band's own model; else a model file (its box model: "
       "MODEL.box_model.yaml). Its classes must be the band model's (refused at start-up otherwise)",
       values="auto, band, or a model file"),
    _p("far_box_model", "band", "which measured box model the image attitude reads the far strip's boxes through on a "
       "real camera (box_model model; docs/attitude.md, Box model): band = the band model's, at each box's size in its "
       "input px (the default: the far model's own was measured on 640x360 video and has no measurement at the sizes "
       "where 15-25 m cones fall on a sharp camera); own = the far model's own box model (MODEL.box_model.yaml), its "
       "sizes without measurements read through the band's (counted on /diagnostics: boxes_read_by_band_model)",
       choices=("band", "own")),
    _p("far_verifier", "none", "a second look at the far strip's doubtful boxes (scored under the verifier's "
       "verify_below, small): a tiny classifier on a crop around each box drops those where it sees no cone, such as "
       "worn paint (docs/detector.md, Far band; counted on /diagnostics: far_strip verifier_dropped). Opt-in: trained "
       "on 640x360 video and rendered negatives, it dropped real far cones on a sharp camera. none or empty = off (the "
       "default), auto = the shipped models/cone_verifier.pt (none where it is not installed), else a verifier file",
       values="none, auto, or a verifier file"),
    _p("far_every", 1, "the far band's cadence: its strip runs on every this-many-th frame only, the frames between "
       "run the band alone (a far cone is seen up to far_every - 1 frames late; the tracker carries it meanwhile; "
       "docs/detector.md, Far band); 1 = every frame", min=1, max=100),
    _p("far_tiles", 0, "with far_every above 1, on the frames between: the strip's full-resolution windows around the "
       "last two frames' far cones (64 px each side), side by side in one mosaic at most this many columns wide, one "
       "forward of the far model (the whole strip where they do not fit; the band alone where there are none; "
       "docs/detector.md, Far band); 0 = off (the band alone between); else a multiple of 32 from 192 to the strip's "
       "width", min=0,
       max=8192),
    _p("track", False, "also the tracker stage: /cones/tracked out (the parameters of cone_tracker); it gets each "
       "frame's attitude, which a separate cone_tracker does not"),
)
_TRACKING = (
    _p("odom_topic", "odom", "the car's motion (odom_type); empty = none (motion estimated from the cones)"),
    _p("odom_type", "odometry", "odom_topic's type: odometry = nav_msgs/Odometry (twist.twist), twist = "
       "geometry_msgs/TwistStamped", choices=("odometry", "twist")),
    _p("odom_max_age_s", 0.1, "odometry older than this (s) at a frame is not used for it (counted)", min=0.0,
       min_exclusive=True),
    _p("publish_tracked_markers", True, "also publish /cones/tracked/markers: cylinders with the track ids as text, "
       "for rviz2"),
)

#: Every node parameter by name (a node may declare one with its own default: :data:`NODES`).
PARAMS: dict[str, ParamSpec] = {s.name: s for s in (*_COMMON, *_CAMERA, *_DETECTOR, *_DEBUG, *_MAPPING, *_PIPELINE,
                                                    *_TRACKING)}
#: The parameters every node declares (input health: nodes/_common.py).
COMMON_PARAMS: tuple[ParamSpec, ...] = _COMMON


@dataclass(frozen=True)
class NodeSpec:
    """One node executable: what it does, its topics (Markdown: backticks), its own parameters (in table
    order) and the nodes whose parameters it declares too (``(node, when)``, ``when`` "" = always)."""

    name: str
    summary: str
    subscribes: tuple[str, ...]
    publishes: tuple[str, ...]
    params: tuple[ParamSpec, ...]
    also: tuple[tuple[str, str], ...] = ()


def check_options(options: dict[str, tuple[str, object]]) -> None:
    """A command's options that stand for node parameters, checked as the nodes check them: ``{option: (parameter
    name, value)}``; ConfigError naming the option of the first value its parameter refuses."""
    for option, (name, value) in options.items():
        why = PARAMS[name].check(value)
        if why:
            raise ConfigError(option, None, why)


def _by_name(*names: str) -> tuple[ParamSpec, ...]:
    return tuple(PARAMS[n] for n in names)


_DIAG = "`/diagnostics` (diagnostic_msgs/DiagnosticArray, once a second)"

#: Every node executable (``ros2 run cone_perception <name>``), in the order of docs/nodes.md.
NODES: dict[str, NodeSpec] = {n.name: n for n in (
    NodeSpec(
        "driver_adapter", "camera frames -> the calibration's band (image_cropped, bgr8) + image_cropped/camera_info",
        ("`image_raw` (sensor_msgs/Image) or `image_raw/compressed` (sensor_msgs/CompressedImage), by `input_transport`",),
        ("`image_cropped` (sensor_msgs/Image, `bgr8`)",
         "`image_cropped/camera_info` (sensor_msgs/CameraInfo, sent first: `roi` = the crop, `binning` = the downscale)",
         _DIAG),
        _CAMERA),
    NodeSpec(
        "detection", "image_cropped (bgr8) + its camera_info -> cone_boxes (full-image px)",
        ("`image_cropped` (sensor_msgs/Image, `bgr8`)", "`image_cropped/camera_info` (sensor_msgs/CameraInfo)"),
        ("`cone_boxes` (sensor_msgs/PointCloud2, the image's header)", "`image_cropped/debug` (sensor_msgs/Image, "
         "opt-in: `debug_image`)", _DIAG),
        (*_DETECTOR, *_DEBUG, dataclasses.replace(
            PARAMS["calibration"], default="", values="empty, a YAML path or a camera name in calib/",
            description="optional: a calibration (a path, or a camera name in calib/) for the cones' distances on "
                        "the debug image; empty = none loaded, the debug image shows no distances (the node itself "
                        "needs none: the crop comes with each camera_info)"))),
    NodeSpec(
        "mapping", "cone_boxes (full-image px) -> /cones (rear_axle metres) + /cones/markers",
        ("`cone_boxes` (sensor_msgs/PointCloud2)", "`imu` (sensor_msgs/Imu, only with `attitude` `imu` or `fused`)"),
        ("`/cones` (sensor_msgs/PointCloud2, frame = the calibration's `frame_id`, default `rear_axle`)",
         "`/cones/markers` (visualization_msgs/MarkerArray)", "`cones/attitude` (geometry_msgs/Vector3Stamped: "
         "the attitude each frame was mapped with, x = roll, y = pitch, rad)", _DIAG),
        (PARAMS["calibration"], *_MAPPING, dataclasses.replace(
            PARAMS["model"], description="the model file of the detection node that draws cone_boxes, for its box "
                                         "model (box_model); empty = the shipped default model (models/cone_detector.pt)"))),
    NodeSpec(
        "pipeline", "the three stages fused in one process: image_raw -> cone_boxes, /cones, /cones/markers",
        ("`image_raw` or `image_raw/compressed` (by `input_transport`)", "`imu` (with `attitude` `imu` / `fused`)",
         "`odom` (with `track: true`, optional: `odom_topic`)"),
        ("`cone_boxes`", "`/cones`", "`/cones/markers`", "`cones/attitude`", "`image_cropped/debug` (opt-in: "
         "`debug_image`; the band of `image_raw` after the adapter)", "`/cones/tracked`, `/cones/tracked/markers` "
         "(with `track: true`)", _DIAG),
        _PIPELINE, also=(("driver_adapter", ""), ("detection", ""), ("mapping", ""), ("cone_tracker", "with track: true"))),
    NodeSpec(
        "cone_tracker", "/cones (+ odom) -> /cones/tracked + /cones/tracked/markers: a local cone map with ids",
        ("`/cones` (sensor_msgs/PointCloud2)", "`odom` (nav_msgs/Odometry or geometry_msgs/TwistStamped, optional: "
         "`odom_topic`, `odom_type`)"),
        ("`/cones/tracked` (sensor_msgs/PointCloud2, the `/cones` fields plus `track_id`)",
         "`/cones/tracked/markers` (visualization_msgs/MarkerArray)", _DIAG),
        (dataclasses.replace(PARAMS["calibration"], description="the camera's calibration YAML: a path, or a camera "
                             "name in calib/ (its band's ground footprint tells where a cone should be seen)"),
         *_TRACKING)),
)}


def node_params(node: str) -> dict[str, ParamSpec]:
    """Every parameter the node ``node`` can declare, by name: its own, those of the nodes it includes
    (its own spec of a name wins), and :data:`COMMON_PARAMS`."""
    spec = NODES[node]
    out = {p.name: p for p in spec.params}
    for other, _ in spec.also:
        for name, p in node_params(other).items():
            out.setdefault(name, p)
    for p in COMMON_PARAMS:
        out.setdefault(p.name, p)
    return out


def param_line(p: ParamSpec) -> str:
    """One parameter in one line of plain text (``--help``, docstrings)."""
    rng = p.range_text()
    return (f"{p.name} ({p.ros_type}, default {p.default_text()}{'; ' + rng if rng else ''}"
            f"{'; set at run time' if p.dynamic else ''}): {p.description}")


def param_groups(node: str) -> list[tuple[str, tuple[ParamSpec, ...]]]:
    """The node's parameters in groups ``(title, specs)``: its own, then those of each node it includes
    that it does not have already, then every node's. Every parameter of :func:`node_params` once."""
    spec = NODES[node]
    seen = {p.name for p in spec.params}
    groups = [("", spec.params)]
    for other, when in spec.also:
        more = tuple(p for p in node_params(other).values() if p.name not in seen and p not in COMMON_PARAMS)
        seen.update(p.name for p in more)
        groups.append((f"of {other}{', ' + when if when else ''}", more))
    groups.append(("of every node", COMMON_PARAMS))
    return groups


def help_text(node: str, width: int = 100) -> str:
    """What ``<node> --help`` prints: usage, topics and every parameter (plain text)."""
    spec = NODES[node]

    def wrap(text: str, first: str = "  ", rest: str = "      ") -> list[str]:
        return textwrap.wrap(text.replace("`", ""), width, initial_indent=first, subsequent_indent=rest,
                             break_on_hyphens=False, break_long_words=False)

    out = wrap(f"usage: ros2 run cone_perception {node} [-h] [--ros-args [-p NAME:=VALUE | --params-file FILE | "
               "-r FROM:=TO] ...]", "", "    ")
    out += ["", f"{node}: {spec.summary}", "", "subscribed:"]
    for t in spec.subscribes:
        out += wrap(t)
    out += ["published:"]
    for t in spec.publishes:
        out += wrap(t)
    out += [""] + wrap("parameters (ros2 param describe shows the same; those marked 'set at run time' change with "
                       "ros2 param set, the others are read-only once the node runs):", "", "")
    for title, group in param_groups(node):
        if title:
            out += [f" {title}:"]
        for p in group:
            out += wrap(param_line(p))
    out += ["", "Every node: docs/nodes.md; docs/robustness.md for the counts on /diagnostics."]
    return "\n".join(out) + "\n"


# -- the docs generated from the schema (cone-perception params --write writes them into the files) --------
#: What regenerates the tables of docs/nodes.md and the node docstrings.
REGENERATE = "cone-perception params --write"
#: The README's and docs' marker of the table of the parameters every node has.
EVERY_NODE = "every_node"


def _md(text: str) -> str:
    return text.replace("|", "\\|")


def _md_range(p: ParamSpec) -> str:
    if p.choices is not None:
        return ", ".join(f"`{c}`" if c else '`""`' for c in p.choices)
    return _md(p.range_text())


def markdown_block(key: str) -> str:
    """The Markdown between the markers of ``key`` (a node, or :data:`EVERY_NODE`): the node's topics
    and the table of its own parameters."""
    head = "| parameter | type | default | range | set at run time | meaning |\n|---|---|---|---|---|---|\n"
    if key == EVERY_NODE:
        rows, out = COMMON_PARAMS, ""
    else:
        spec = NODES[key]
        rows = spec.params
        out = f"- Subscribed: {'; '.join(spec.subscribes)}\n- Published: {'; '.join(spec.publishes)}\n\n"
    out += head + "".join(f"| `{p.name}` | {p.ros_type} | `{p.default_text()}` | {_md_range(p)} | "
                          f"{'yes' if p.dynamic else ''} | {_md(p.description)} |\n" for p in rows)
    if key != EVERY_NODE and NODES[key].also:
        more = [f"`{o}`" + (f" ({w})" if w else "") for o, w in NODES[key].also]
        mine = node_params(key)
        differ = sorted({n for o, _ in NODES[key].also for n, p in node_params(o).items() if mine[n] != p})
        where = f"; where two differ ({', '.join(f'`{n}`' for n in differ)}), the first's" if differ else ""
        out += f"\nAlso the parameters of {', '.join(more[:-1])} and {more[-1]}, as in their tables{where}.\n"
    return out


def docstring_block(node: str) -> str:
    """The ``Parameters (generated ...)`` block of the node module's docstring."""
    lines = [f"Parameters (generated from cone_perception/params.py by ``{REGENERATE}``):"]
    groups = param_groups(node)
    for p in groups[0][1]:
        lines += textwrap.wrap(param_line(p), 100, initial_indent="  ", subsequent_indent="    ",
                               break_on_hyphens=False, break_long_words=False)
    also = [f"those {title} ({', '.join(p.name for p in specs)})" for title, specs in groups[1:] if specs]
    lines += textwrap.wrap("Also " + "; ".join(also) + ".", 100, initial_indent="  ", subsequent_indent="    ",
                           break_on_hyphens=False, break_long_words=False)
    return "\n".join(lines) + "\n"
