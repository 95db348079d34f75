"""The tracker in a node (``cone_tracker``, and ``pipeline`` with ``track: true``): its parameters
(``odom_topic``, ``odom_type``, ``odom_max_age_s``, ``publish_tracked_markers``: the ``cone_tracker``
table of :mod:`cone_perception.params`), odometry in, ``/cones/tracked`` and ``/cones/tracked/markers``
out. The logic is :class:`cone_perception.tracking.TrackingStage`.

Health: the tracker's event counts (:attr:`cone_perception.tracking.ConeTracker.events`) are values
``tracker:<event>`` of the node's ``/diagnostics`` status; a gap, stale odometry, a refused twist, a
failed registration or a bad cone in the period makes it WARN.
"""

from __future__ import annotations

from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray

from ..tracking import INPUT_EVENTS, TrackingStage
from . import _msgs
from ._common import QOS_DATA, WARN_THROTTLE_S
from ._params import declare

TRACKED_TOPIC = "/cones/tracked"


class NodeTracking:
    """Declares the tracking parameters on ``node``, subscribes the odometry, publishes tracked cones."""

    def __init__(self, node, calib) -> None:
        self.node = node
        self.frame_id = calib.frame_id
        odom_topic = declare(node, "odom_topic")
        odom_type = declare(node, "odom_type")  # odometry | twist: checked by its spec
        max_age = float(declare(node, "odom_max_age_s"))  # > 0 s: checked by its spec
        self.markers = bool(declare(node, "publish_tracked_markers"))
        self.stage = TrackingStage(calib, odom_max_age_s=max_age)
        # on /diagnostics as tracker:<event>; stamps are warned as dropped frames already
        node.health.watch("tracker", self.stage.events, warn=[e for e in INPUT_EVENTS if not e.startswith("stamp_")])
        self.pub = node.create_publisher(PointCloud2, TRACKED_TOPIC, QOS_DATA)
        self.pub_markers = node.create_publisher(MarkerArray, TRACKED_TOPIC + "/markers", QOS_DATA)
        if odom_topic:
            if odom_type == "odometry":
                node.create_subscription(Odometry, odom_topic, node.guarded(
                    lambda m: self._twist(m.header, m.twist.twist), odom_topic, frames=False, optional=True), QOS_DATA)
            else:
                node.create_subscription(TwistStamped, odom_topic, node.guarded(
                    lambda m: self._twist(m.header, m.twist), odom_topic, frames=False, optional=True), QOS_DATA)
        self._reported = {}

    def _twist(self, header, tw) -> None:
        if not self.stage.add_twist(_msgs.stamp_ns(header), tw.linear.x, tw.linear.y, tw.angular.z):
            self._report()

    def process(self, cones, header, attitude=None) -> None:
        """Track one frame's ``CONE_DTYPE`` records; publish with the frame's stamp. ``attitude``: the
        :class:`~cone_perception.attitude.Attitude` they were mapped with (the fused pipeline knows it).
        Raises ``FrameError`` (stamp not after the last frame: not fused)."""
        tracked, _ = self.stage.process(_msgs.stamp_ns(header), cones, attitude)
        h = _msgs.copy_header(header, self.frame_id)
        self.pub.publish(_msgs.tracked_msg(tracked, h))
        if self.markers:
            self.pub_markers.publish(_msgs.tracked_markers(tracked, h))
        self._report()

    def _report(self) -> None:
        """Log each tracker event count when it grows (throttled): gaps, stale odometry, failed registrations..."""
        ev = self.stage.events
        grown = {k: v for k, v in ev.items() if v > self._reported.get(k, 0)}
        if grown:
            self._reported.update(grown)
            self.node.get_logger().warning("tracker: " + ", ".join(f"{k}={v}" for k, v in sorted(ev.items())),
                                           throttle_duration_sec=WARN_THROTTLE_S)
