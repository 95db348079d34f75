"""Attitude parameters, the IMU subscription and the ``cones/attitude`` publisher shared by the
``mapping`` and ``pipeline`` nodes (the logic is in :mod:`cone_perception.attitude`).

Parameters
  attitude (str, ""): ``fixed`` | ``image`` | ``imu`` | ``fused``; "" = ``image`` when the calibration
    has a mount pose, else ``fixed`` (a node does not know at start whether an IMU will publish:
    ask for ``imu`` / ``fused`` explicitly).
  imu_rest_deg (double[2], [0, 0]): the IMU's pitch and roll (degrees) with the car at rest on the
    level ground of the calibration (``cone-perception imu-rest REST_BAG`` measures it).
"""

from __future__ import annotations

from geometry_msgs.msg import Vector3Stamped
from sensor_msgs.msg import Imu

from ..attitude import ImuAttitude, QUAT_NORM_TOL
from . import _msgs
from ..errors import FrameError
from ._common import QOS_DATA

#: IMU in: best effort (IMU drivers publish so), a short queue (100 Hz and more).
IMU_QUEUE = 50


def declare_attitude(node) -> tuple[str, ImuAttitude | None]:
    """Declare ``attitude`` and ``imu_rest_deg``; subscribe ``imu`` for modes imu / fused.
    Returns ``(requested mode or "", ImuAttitude or None)``; creates ``node.pub_attitude``."""
    mode = str(node.declare_parameter("attitude", "").value)
    rest = [float(v) for v in node.declare_parameter("imu_rest_deg", [0.0, 0.0]).value]
    imu = None
    if mode in ("imu", "fused"):
        if len(rest) != 2:
            from ..errors import ConfigError

            raise ConfigError("parameter", "imu_rest_deg", f"must be [pitch, roll] in degrees, got {rest}")
        imu = ImuAttitude((rest[0], rest[1]))

        def on_imu(msg: Imu) -> None:
            q = msg.orientation
            before = imu.counts.as_dict()
            if not imu.add(_msgs.stamp_ns(msg.header), (q.x, q.y, q.z, q.w)):
                cause = next(k for k, v in imu.counts.as_dict().items() if v != before[k])
                raise FrameError(f"imu_{cause.removeprefix('dropped_')}",
                                 f"IMU message not used ({cause}; quaternion norm tolerance {QUAT_NORM_TOL})")

        node.create_subscription(Imu, "imu", node.guarded(on_imu, "imu", frames=False), IMU_QUEUE)
    node.pub_attitude = node.create_publisher(Vector3Stamped, "cones/attitude", QOS_DATA)
    return mode, imu


def publish_attitude(node, att, header) -> None:
    """Publish the attitude a frame was mapped with, the frame's stamp, in the cones frame."""
    node.pub_attitude.publish(_msgs.attitude_msg(att, _msgs.copy_header(header, node.cones_frame_id)))
