"""What every node shares: start-up, QoS, dropped-frame handling, diagnostics."""

from __future__ import annotations

import sys
from typing import Callable

from .. import ros_env
from ..errors import ConePerceptionError, ConfigError, FrameError
from ..stats import FrameStats

try:
    ros_env.apply()  # before rclpy loads the middleware
except ConfigError as _e:  # an unknown CONE_PERCEPTION_DDS: one line, exit 1
    raise SystemExit(f"[cone_perception] error: {_e}") from None

import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from sensor_msgs.msg import CompressedImage, Image, PointCloud2  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from . import _msgs  # noqa: E402
from rclpy.executors import ExternalShutdownException  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402

#: Images in: best effort, newest frame only (a slow frame never builds a queue of stale ones).
QOS_IMAGE_IN = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT)
#: Images out: reliable, so both reliable and best-effort subscribers match.
QOS_IMAGE_OUT = QoSProfile(depth=2, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
#: Small messages (boxes, cones, markers): reliable, short queue.
QOS_DATA = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)

WARN_THROTTLE_S = 2.0


class PerceptionNode(Node):
    """A node that counts ok/dropped frames and publishes them on ``/diagnostics`` once a second."""

    def __init__(self, name: str, **kwargs):
        super().__init__(name, **kwargs)
        self.stats = FrameStats()
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._diag_timer = self.create_timer(1.0, self._publish_diagnostics)

    def guarded(self, handler: Callable) -> Callable:
        """Wrap a subscription callback: a :class:`FrameError` drops that frame, counted and logged.

        A handler that returns ``False`` has put the frame aside for later (not counted yet).
        """

        def callback(msg):
            try:
                done = handler(msg)
            except FrameError as e:
                n = self.stats.count_drop(e.reason)
                self.get_logger().warning(
                    f"dropped frame ({e.reason}, {n} so far): {e}", throttle_duration_sec=WARN_THROTTLE_S
                )
            else:
                if done is not False:
                    self.stats.count_ok()

        return callback

    def subscribe_camera(self, transport: str) -> None:
        """Subscribe ``image_raw`` (``transport`` "raw") or ``image_raw/compressed`` ("compressed")
        to ``self.on_raw`` / ``self.on_compressed``, newest frame only."""
        if transport == "raw":
            self.create_subscription(Image, "image_raw", self.guarded(self.on_raw), QOS_IMAGE_IN)
        elif transport == "compressed":
            self.create_subscription(
                CompressedImage, "image_raw/compressed", self.guarded(self.on_compressed), QOS_IMAGE_IN
            )
        else:
            raise ConfigError("parameter", "input_transport", f"must be 'raw' or 'compressed', got {transport!r}")

    def advertise_cones(self, frame_id: str, markers: bool) -> None:
        """Publishers of ``/cones`` (and ``/cones/markers`` if ``markers``) in ``frame_id``."""
        self.cones_frame_id, self.publish_markers = frame_id, markers
        self.pub_cones = self.create_publisher(PointCloud2, "/cones", QOS_DATA)
        self.pub_markers = self.create_publisher(MarkerArray, "/cones/markers", QOS_DATA)

    def publish_cones(self, cones, header) -> None:
        """Publish ``CONE_DTYPE`` records with the camera frame's stamp, in the cones frame."""
        h = _msgs.copy_header(header, self.cones_frame_id)
        self.pub_cones.publish(_msgs.cones_msg(cones, h))
        if self.publish_markers:
            self.pub_markers.publish(_msgs.cone_markers(cones, h))

    def _publish_diagnostics(self) -> None:
        st = DiagnosticStatus()
        st.name = f"cone_perception/{self.get_name()}"
        st.hardware_id = "camera"
        st.level = DiagnosticStatus.WARN if self.stats.dropped else DiagnosticStatus.OK
        st.message = self.stats.summary()
        st.values = [KeyValue(key="frames_ok", value=str(self.stats.ok))] + [
            KeyValue(key=f"dropped_{k}", value=str(v)) for k, v in sorted(self.stats.dropped.items())
        ]
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [st]
        self._diag_pub.publish(arr)


def run_node(factory: Callable[[], Node], args: list[str] | None = None, name: str = "cone_perception") -> int:
    """``main()`` of a node: init, build (a config error exits 1 with one line), spin, shut down."""
    args = sys.argv if args is None else args
    rclpy.init(args=args)
    node = None
    try:
        node = factory()
        rclpy.spin(node)
    except ConePerceptionError as e:
        print(f"[{name}] error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        pass
    except ExternalShutdownException:
        pass
    finally:
        if node is not None:
            if hasattr(node, "stats"):
                print(f"[{name}] stopping: {node.stats.summary()}", file=sys.stderr)
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
