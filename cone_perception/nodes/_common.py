"""What every node shares: start-up, QoS, dropped-frame handling, diagnostics."""

from __future__ import annotations

import sys
import time
import traceback
from typing import Callable

from .. import ros_env
from ..errors import ConePerceptionError, ConfigError, FrameError
from ..stats import ERROR, NodeHealth, StreamMonitor

try:
    ros_env.apply()  # before rclpy loads the middleware
except ConfigError as _e:  # an unknown CONE_PERCEPTION_DDS: one line, exit 1
    raise SystemExit(f"[cone_perception] error: {_e}") from None

import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from geometry_msgs.msg import Vector3Stamped  # noqa: E402
from sensor_msgs.msg import CompressedImage, Image, PointCloud2  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from . import _msgs  # noqa: E402
from ._params import declare, specs_of  # noqa: E402
from ..params import NODES, help_text  # noqa: E402
from .executables import wants_help  # noqa: E402
try:  # noqa: E402 - Jazzy; Humble has the same classes in rclpy.qos_event
    from rclpy.event_handler import SubscriptionEventCallbacks, UnsupportedEventTypeError
except ImportError:  # pragma: no cover - Humble
    from rclpy.qos_event import SubscriptionEventCallbacks, UnsupportedEventTypeError
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
    """A node that counts every input message (processed, or dropped by cause), watches its input
    streams (stamp gaps, stamps backwards or repeated, stale frames, silence, a missing publisher:
    :class:`~cone_perception.stats.NodeHealth`) and publishes its health on ``/diagnostics`` once
    a second.

    Parameters (every node): ``input_timeout_s``, ``max_frame_age_s``, ``input_rate_hz``
    (:data:`cone_perception.params.COMMON_PARAMS`). ``name`` is the node executable's name
    (:data:`cone_perception.params.NODES`): its parameter table (:attr:`param_specs`), which
    :func:`~cone_perception.nodes._params.declare` declares from.
    """

    def __init__(self, name: str, **kwargs):
        super().__init__(name, **kwargs)
        self.param_specs = specs_of(name)
        timeout_s = float(declare(self, "input_timeout_s"))
        max_age_s = float(declare(self, "max_frame_age_s"))
        rate_hz = float(declare(self, "input_rate_hz"))
        self.health = NodeHealth(timeout_s, max_age_s, 1.0 / rate_hz if rate_hz > 0 else 0.0)
        self.stats = self.health.stats
        self._last_warn: dict[str, float] = {}
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._diag_timer = self.create_timer(1.0, self._publish_diagnostics)

    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def guarded(self, handler: Callable, topic: str, frames: bool = True, optional: bool = False) -> Callable:
        """Wrap the subscription callback of ``topic`` so that no message can end the process.

        Every message is counted once on the topic's :class:`~cone_perception.stats.StreamMonitor`
        (which also gets its header stamp), as ok or dropped: a :class:`FrameError` drops the message,
        counted under its reason and logged (throttled); any other exception drops it too, counted as
        ``exception_<Type>``, logged at warn level (throttled) and, the first time for each type, with
        its traceback at debug level. A handler that returns ``False`` has put the message aside for
        later (:meth:`run_guarded` counts it then). ``frames``: processed messages also count as
        frames ok (not for ``camera_info``); drops always go into the node's counts by cause.
        ``optional``: an input the node works without (odometry): its silence and a missing publisher
        are no error.
        """
        stream = self.health.stream(self.resolve_topic_name(topic), self._now_ns())
        if optional:
            stream.timeout_s, stream.optional = 0.0, True

        def callback(msg):
            try:
                stream.observe(_stamp_ns(msg), self._now_ns())
            except Exception:  # noqa: BLE001 - a header that is not one: the handler's guard counts the message
                pass
            self.run_guarded(handler, msg, stream, frames)

        return callback

    def _may_warn(self, reason: str) -> bool:
        """At most one warning per cause every :data:`WARN_THROTTLE_S` (checked here: rclpy's own
        throttle costs 0.2 ms a call, which a flood of bad messages would pay for each)."""
        now = time.monotonic()
        if now - self._last_warn.get(reason, -WARN_THROTTLE_S) < WARN_THROTTLE_S:
            return False
        self._last_warn[reason] = now
        return True

    def run_guarded(self, handler: Callable, msg, stream: StreamMonitor, frames: bool = True) -> None:
        """Call ``handler(msg)``; count the message on ``stream`` as ok or dropped on any exception
        (:meth:`guarded`)."""
        try:
            done = handler(msg)
        except FrameError as e:
            stream.dropped += 1
            n = self.stats.count_drop(e.reason)
            if self._may_warn(e.reason):
                self.get_logger().warning(f"dropped message on {stream.topic} ({e.reason}, {n} so far): {e}")
        except Exception as e:  # noqa: BLE001 - no message may end the node: drop it, count it, say so
            stream.dropped += 1
            reason = f"exception_{type(e).__name__}"
            if reason not in self.stats.dropped:
                self.get_logger().debug(f"first {reason} on {stream.topic}:\n{traceback.format_exc()}")
            n = self.stats.count_drop(reason)
            if self._may_warn(reason):
                self.get_logger().warning(
                    f"dropped message on {stream.topic} on unexpected {type(e).__name__} ({n} so far): {e}")
        else:
            if done is not False:
                stream.ok += 1
                if frames:
                    self.stats.count_ok()

    def subscribe_camera(self, transport: str) -> None:
        """Subscribe ``image_raw`` (``transport`` "raw") or ``image_raw/compressed`` ("compressed")
        to ``self.on_raw`` / ``self.on_compressed``, newest frame only."""
        if transport == "raw":
            self.subscribe_frames(Image, "image_raw", self.on_raw)
        elif transport == "compressed":
            self.subscribe_frames(CompressedImage, "image_raw/compressed", self.on_compressed)
        else:
            raise ConfigError("parameter", "input_transport", f"must be 'raw' or 'compressed', got {transport!r}")

    def subscribe_frames(
        self, msgtype, topic: str, handler: Callable, qos: QoSProfile = QOS_IMAGE_IN, frames: bool = True
    ):
        """A guarded subscription (:meth:`guarded`) whose middleware-lost messages are counted too
        (``lost`` on the topic's monitor; where the middleware has no such event, stamp gaps only)."""
        callback = self.guarded(handler, topic, frames)
        stream = self.health.streams[self.resolve_topic_name(topic)]

        def on_lost(info) -> None:
            stream.lost += int(info.total_count_change)

        try:
            return self.create_subscription(msgtype, topic, callback, qos,
                                            event_callbacks=SubscriptionEventCallbacks(message_lost=on_lost))
        except (UnsupportedEventTypeError, TypeError):  # no such event in this middleware / rclpy
            return self.create_subscription(msgtype, topic, callback, qos)

    def advertise_cones(self, frame_id: str, markers: bool) -> None:
        """Publishers of ``/cones``, ``/cones/markers`` (published if ``markers``) and ``cones/attitude``
        in ``frame_id``."""
        self.cones_frame_id, self.publish_markers = frame_id, markers
        self.pub_cones = self.create_publisher(PointCloud2, "/cones", QOS_DATA)
        self.pub_markers = self.create_publisher(MarkerArray, "/cones/markers", QOS_DATA)
        self.pub_attitude = self.create_publisher(Vector3Stamped, "cones/attitude", QOS_DATA)

    def publish_cones(self, cones, header) -> None:
        """Publish ``CONE_DTYPE`` records with the camera frame's stamp, in the cones frame."""
        h = _msgs.copy_header(header, self.cones_frame_id)
        self.pub_cones.publish(_msgs.cones_msg(cones, h))
        if self.publish_markers:
            self.pub_markers.publish(_msgs.cone_markers(cones, h))

    def publish_attitude(self, att, header) -> None:
        """Publish the :class:`~cone_perception.attitude.Attitude` a frame's cones were mapped with, the
        frame's stamp, in the cones frame."""
        self.pub_attitude.publish(_msgs.attitude_msg(att, _msgs.copy_header(header, self.cones_frame_id)))

    def _publish_diagnostics(self) -> None:
        try:  # a timer callback: nothing in it may end the node either
            self._publish_health()
        except Exception as e:  # noqa: BLE001
            if self._may_warn("diagnostics"):
                self.get_logger().warning(f"diagnostics not published: {type(e).__name__}: {e}")

    def _publish_health(self) -> None:
        pubs = {t: self.count_publishers(t) for t, s in self.health.streams.items() if not s.optional}
        rep = self.health.assess(self._now_ns(), pubs)
        st = DiagnosticStatus()
        st.name = f"cone_perception/{self.get_name()}"
        st.hardware_id = "camera"
        st.level = bytes([rep.level])
        st.message = rep.message
        st.values = [KeyValue(key=k, value=v) for k, v in rep.values]
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [st]
        self._diag_pub.publish(arr)
        if rep.level:
            what = "input lost" if rep.level == ERROR else "input degraded"
            self.get_logger().warning(f"{what}: {rep.message}", throttle_duration_sec=5.0)


def _stamp_ns(msg) -> int | None:
    header = getattr(msg, "header", None)
    return None if header is None else _msgs.stamp_ns(header)


def run_node(factory: Callable[[], Node], args: list[str] | None = None, name: str = "cone_perception") -> int:
    """``main()`` of a node: init, build (a config error exits 1 with one line), spin, shut down; with
    ``-h`` / ``--help`` (outside ``--ros-args``) the node's help instead (``python -m`` of a node module)."""
    args = sys.argv if args is None else args
    if name in NODES and wants_help(list(args[1:])):
        sys.stdout.write(help_text(name))
        return 0
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
                print(f"[{name}] stopping: {node.health.summary() if hasattr(node, 'health') else node.stats.summary()}",
                      file=sys.stderr)
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
