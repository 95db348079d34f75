"""The attitude parameters (``attitude``, ``imu_rest_deg``: :mod:`cone_perception.params`) and the IMU
subscription shared by the ``mapping`` and ``pipeline`` nodes (the logic is in
:mod:`cone_perception.attitude`; the nodes publish ``cones/attitude`` themselves:
:meth:`~cone_perception.nodes._common.PerceptionNode.publish_attitude`).
"""

from __future__ import annotations

from sensor_msgs.msg import Imu

from ..attitude import ImuAttitude, QUAT_NORM_TOL
from . import _msgs
from ..errors import FrameError
from ._params import declare

#: IMU in: best effort (IMU drivers publish so), a short queue (100 Hz and more).
IMU_QUEUE = 50


def declare_attitude(node) -> tuple[str, ImuAttitude | None]:
    """Declare ``attitude`` and ``imu_rest_deg``; subscribe ``imu`` for modes imu / fused.
    Returns ``(requested mode or "", ImuAttitude or None)``."""
    mode = str(declare(node, "attitude"))
    rest = [float(v) for v in declare(node, "imu_rest_deg")]  # two numbers: checked by its spec
    imu = None
    if mode in ("imu", "fused"):
        imu = ImuAttitude((rest[0], rest[1]))

        def on_imu(msg: Imu) -> None:
            q = msg.orientation
            before = imu.counts.as_dict()
            if not imu.add(_msgs.stamp_ns(msg.header), (q.x, q.y, q.z, q.w)):
                cause = next(k for k, v in imu.counts.as_dict().items() if v != before[k])
                raise FrameError(f"imu_{cause.removeprefix('dropped_')}",
                                 f"IMU message not used ({cause}; quaternion norm tolerance {QUAT_NORM_TOL})")

        node.create_subscription(Imu, "imu", node.guarded(on_imu, "imu", frames=False), IMU_QUEUE)
    return mode, imu
