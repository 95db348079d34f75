"""What every node shares: start-up, QoS, dropped-frame handling, diagnostics."""

from __future__ import annotations

import os
import sys
import time
import traceback
from typing import Callable

from .. import ros_env
from ..errors import ConePerceptionError, ConfigError, FrameError
from ..records import cdr_stamp_ns
from ..stats import ERROR, NodeHealth, StreamMonitor
from . import _shm as shm

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
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup  # noqa: E402
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.subscription import Subscription  # noqa: E402

#: rclpy passes a callback of two arguments the message info, with the publisher's sequence number
#: (Iron and later; Humble's rclpy passes the message only).
MESSAGE_INFO = hasattr(Subscription, "CallbackType")
#: Image inputs get a counting path (a second, raw subscription) where the callbacks get no sequence numbers.
COUNTING_PATH = not MESSAGE_INFO
#: The message info's value when the middleware has no sequence numbers (RMW_MESSAGE_INFO_SEQUENCE_NUMBER_UNSUPPORTED).
_SEQ_UNSUPPORTED = 2**64 - 1

#: Images in: best effort, newest frame only (a slow frame never builds a queue of stale ones).
QOS_IMAGE_IN = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT)
#: Images out: reliable, so both reliable and best-effort subscribers match.
QOS_IMAGE_OUT = QoSProfile(depth=2, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
#: The counting path of an image input (:meth:`PerceptionNode.subscribe_frames`): every frame, as bytes,
#: with a queue deep enough for the counting thread's hiccups (0.25 s at 200 Hz); only the stamp is read.
QOS_IMAGE_COUNT = QoSProfile(depth=50, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT)
#: Small messages (boxes, cones, markers): reliable, short queue.
QOS_DATA = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)

WARN_THROTTLE_S = 2.0
#: ``CONE_PERCEPTION_SHM_CLEAN=0``: a node's start does not remove stale shared-memory files (:func:`clean_stale_shm`).
SHM_CLEAN_VAR = "CONE_PERCEPTION_SHM_CLEAN"


class PerceptionNode(Node):
    """A node that counts every input message (processed, or dropped by cause), watches its input
    streams (stamp gaps, stamps backwards or repeated, stale frames, silence, a missing publisher:
    :class:`~cone_perception.stats.NodeHealth`) and publishes its health on ``/diagnostics`` once
    a second.

    Parameters (every node): ``input_timeout_s``, ``max_frame_age_s``, ``input_rate_hz``
    (:data:`cone_perception.params.COMMON_PARAMS`). ``name`` is the node executable's name
    (:data:`cone_perception.params.NODES`): its parameter table (:attr:`param_specs`), which
    :func:`~cone_perception.nodes._params.declare` declares from.

    Every frame sent on an image input (best effort, depth 1: newest frame only) is accounted for
    (:mod:`cone_perception.stats`): the publisher's sequence number of each frame taken (in the
    message info, :data:`MESSAGE_INFO`) says how many were sent in between, replaced in the queue or
    lost in transport (the middleware's lost-message event). Where the callbacks get no sequence
    numbers (Humble), a counting path beside each image input sees every frame that reaches the node
    (:meth:`subscribe_frames`), on its own thread: :func:`run_node` then spins the node with a
    two-thread executor, every other callback in the node's default (mutually exclusive) group.
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
        self._counting_group = MutuallyExclusiveCallbackGroup()

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

        def on_message(msg, info=None):
            try:
                stream.observe(_stamp_ns(msg), self._now_ns(), _seq(info))
            except Exception:  # noqa: BLE001 - a header that is not one: the handler's guard counts the message
                pass
            self.run_guarded(handler, msg, stream, frames)

        if not MESSAGE_INFO:
            return on_message

        def callback(msg, info):  # two arguments: rclpy passes the message info
            on_message(msg, info)

        callback.message_only = on_message  # for calling it directly (tests, fuzz)
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
        (``lost`` on the topic's monitor, where the middleware has such an event).

        Where the callbacks get no sequence numbers (:data:`COUNTING_PATH`), an image input (best
        effort, depth 1) also gets a counting path: a second
        subscription (depth :data:`QOS_IMAGE_COUNT`, raw bytes, its own callback group) whose callback
        reads only the header stamp of every frame (:func:`~cone_perception.records.cdr_stamp_ns`) for
        the topic's :class:`~cone_perception.stats.StreamMonitor`: frames replaced before processing
        and frames lost upstream are counted from it."""
        callback = self.guarded(handler, topic, frames)
        stream = self.health.streams[self.resolve_topic_name(topic)]
        counting = COUNTING_PATH and frames and qos == QOS_IMAGE_IN
        if counting:
            stream.counted = True

            def on_arrival(raw: bytes) -> None:
                try:
                    stream.arrive(cdr_stamp_ns(raw), self._now_ns())
                except Exception as e:  # noqa: BLE001 - counting must never stop the node
                    if self._may_warn("counting"):
                        self.get_logger().warning(f"counting path of {stream.topic}: {type(e).__name__}: {e}")

            self._subscribe_with_lost(msgtype, topic, on_arrival, QOS_IMAGE_COUNT, stream,
                                          callback_group=self._counting_group, raw=True)
        return self._subscribe_with_lost(msgtype, topic, callback, qos, None if counting else stream)

    def _subscribe_with_lost(self, msgtype, topic: str, callback: Callable, qos: QoSProfile,
                                 stream: StreamMonitor | None, **kwargs):
        """``create_subscription`` that adds the middleware's lost messages to ``stream.lost`` (if a stream)."""
        if stream is None:
            return self.create_subscription(msgtype, topic, callback, qos, **kwargs)

        def on_lost(info) -> None:
            stream.lost += int(info.total_count_change)

        try:
            return self.create_subscription(msgtype, topic, callback, qos, **kwargs,
                                            event_callbacks=SubscriptionEventCallbacks(message_lost=on_lost))
        except (UnsupportedEventTypeError, TypeError):  # no such event in this middleware / rclpy
            return self.create_subscription(msgtype, topic, callback, qos, **kwargs)

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


def _seq(info) -> int | None:
    """The publisher's sequence number in a message info, or None where there is none."""
    try:
        seq = info["publication_sequence_number"] if info is not None else None
    except (KeyError, TypeError):
        return None
    return int(seq) if isinstance(seq, int) and 0 < seq < _SEQ_UNSUPPORTED else None


def _stamp_ns(msg) -> int | None:
    header = getattr(msg, "header", None)
    return None if header is None else _msgs.stamp_ns(header)


def clean_stale_shm(name: str) -> None:
    """Before the participant starts: remove the shared-memory files of dead processes (a node killed
    with ``kill -9``, its predecessor under launch's respawn), never a live one's
    (:func:`cone_perception.nodes._shm.clean_stale`); where a dead node's port is left because a live peer still
    maps it, start with the first participant id whose ports are free (:func:`avoid_dead_ports`). Not in the
    ``system`` DDS mode (the car's own set-up is left alone) nor with ``CONE_PERCEPTION_SHM_CLEAN=0``."""
    if ros_env.mode_of() == "system" or os.environ.get(SHM_CLEAN_VAR, "1").strip() == "0":
        return
    try:
        rep = shm.clean_stale()
        if rep.removed:
            print(f"[{name}] {rep.line()}", file=sys.stderr)
        avoid_dead_ports(name, dead=rep.dead_ports)
    except Exception as e:  # noqa: BLE001 - a failed clean-up must not keep the node from starting
        print(f"[{name}] shared-memory clean-up failed: {type(e).__name__}: {e}", file=sys.stderr)


def avoid_dead_ports(name: str, shm_dir=shm.SHM_DIR, dead: list[int] | None = None) -> int | None:
    """A node restarted after ``kill -9`` would take the dead node's participant id, so its ports, which a live peer
    still maps and writes into until its health check gives up (1-3 s without frames): where such a port is in
    ``shm_dir``, start this process's participant with the first id whose ports are free
    (:func:`cone_perception.ros_env.with_participant_id`, one line said) and return it; None where none is
    needed or possible (the package's profile not in use, no free id, the cache not writable). ``dead``: those ports
    as the clean-up found them (:attr:`~cone_perception.nodes._shm.CleanReport.dead_ports`); None: looked up."""
    dead = shm.dead_ports_in_use(shm_dir) if dead is None else dead
    if not dead:
        return None
    try:
        domain = int(os.environ.get("ROS_DOMAIN_ID", "0") or 0)
    except ValueError:
        return None
    pid = shm.free_participant_id(domain, shm_dir)
    if pid is None or ros_env.with_participant_id(pid) is None:
        return None
    ports = "/".join(str(p) for p in shm.participant_ports(domain, pid))
    print(f"[{name}] a dead node's shared-memory port(s) {', '.join(map(str, dead))} still mapped by a live peer: "
          f"starting as DDS participant {pid} (ports {ports}) so its writers reach this node at once", file=sys.stderr)
    return pid


def run_node(factory: Callable[[], Node], args: list[str] | None = None, name: str = "cone_perception") -> int:
    """``main()`` of a node: init, build (a config error exits 1 with one line), spin, shut down; with
    ``-h`` / ``--help`` (outside ``--ros-args``) the node's help instead (``python -m`` of a node module)."""
    args = sys.argv if args is None else args
    if name in NODES and wants_help(list(args[1:])):
        sys.stdout.write(help_text(name))
        return 0
    clean_stale_shm(name)
    rclpy.init(args=args)
    node = executor = None
    try:
        node = factory()
        # with counting paths (Humble) they run on a second thread beside the processing
        executor = MultiThreadedExecutor(num_threads=2) if COUNTING_PATH else SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except ConePerceptionError as e:
        print(f"[{name}] error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        pass
    except ExternalShutdownException:
        pass
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            if hasattr(node, "stats"):
                print(f"[{name}] stopping: {node.health.summary() if hasattr(node, 'health') else node.stats.summary()}",
                      file=sys.stderr)
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
