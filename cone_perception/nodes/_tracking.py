"""The tracker in a node (``cone_tracker``, and ``pipeline`` with ``track: true``): parameters,
odometry in, ``/cones/tracked`` and ``/cones/tracked/markers`` out. The logic is
:class:`cone_perception.tracking.TrackingStage`.

Parameters
  odom_topic (str, "odom"): the car's motion; "" = none (motion estimated from the cones).
  odom_type ("odometry" | "twist"): nav_msgs/Odometry (twist.twist) or geometry_msgs/TwistStamped.
  odom_max_age_s (float, 0.1): odometry older than this at a frame is not used for it (counted).
  publish_tracked_markers (bool, true): cylinders with the track ids as text, for rviz2.

Health: the tracker's event counts (:attr:`cone_perception.tracking.ConeTracker.events`) are values
``tracker:<event>`` of the node's ``/diagnostics`` status; a gap, stale odometry, a refused twist, a
failed registration or a bad cone in the period makes it WARN.
"""

from __future__ import annotations

from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray

from ..errors import ConfigError
from ..tracking import INPUT_EVENTS, TrackingStage
from . import _msgs
from ._common import QOS_DATA, WARN_THROTTLE_S

TRACKED_TOPIC = "/cones/tracked"


class NodeTracking:
    """Declares the tracking parameters on ``node``, subscribes the odometry, publishes tracked cones."""

    def __init__(self, node, calib) -> None:
        self.node = node
        self.frame_id = calib.frame_id
        odom_topic = node.declare_parameter("odom_topic", "odom").value
        odom_type = node.declare_parameter("odom_type", "odometry").value
        max_age = float(node.declare_parameter("odom_max_age_s", 0.1).value)
        self.markers = bool(node.declare_parameter("publish_tracked_markers", True).value)
        if not max_age > 0:
            raise ConfigError("parameter", "odom_max_age_s", f"must be > 0 s, got {max_age}")
        self.stage = TrackingStage(calib, odom_max_age_s=max_age)
        # on /diagnostics as tracker:<event>; stamps are warned as dropped frames already
        node.health.watch("tracker", self.stage.events, warn=[e for e in INPUT_EVENTS if not e.startswith("stamp_")])
        self.pub = node.create_publisher(PointCloud2, TRACKED_TOPIC, QOS_DATA)
        self.pub_markers = node.create_publisher(MarkerArray, TRACKED_TOPIC + "/markers", QOS_DATA)
        if odom_topic:
            if odom_type == "odometry":
                node.create_subscription(Odometry, odom_topic, node.guarded(
                    lambda m: self._twist(m.header, m.twist.twist), odom_topic, frames=False, optional=True), QOS_DATA)
            elif odom_type == "twist":
                node.create_subscription(TwistStamped, odom_topic, node.guarded(
                    lambda m: self._twist(m.header, m.twist), odom_topic, frames=False, optional=True), QOS_DATA)
            else:
                raise ConfigError("parameter", "odom_type", f"must be 'odometry' or 'twist', got {odom_type!r}")
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
