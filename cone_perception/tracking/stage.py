"""The tracker as a pipeline stage (:class:`TrackingStage`): a frame's ``/cones`` plus odometry twists in,
``/cones/tracked`` out; used by the ``pipeline`` and ``cone_tracker`` nodes and ``replay``. ROS-free.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from ..mapping import ConeMapper
from ..geometry.motion import TwistBuffer
from .tracker import ConeTracker, FrameInfo, TrackerConfig
from .view import FieldOfView


class TrackingStage:
    """The tracker as a pipeline stage: ``/cones`` of a frame (+ odometry twists when the car has them)
    -> ``/cones/tracked`` records. Used by the ``pipeline`` and ``cone_tracker`` nodes and ``replay``.

    Twists (:meth:`add_twist`) are used for a frame when fresh (:attr:`TwistBuffer.max_age_s`); once
    any twist has come, a frame without a fresh one is counted as ``odom_stale`` and its motion is
    estimated from the cones. Refused twists are counted (``twist_nan``, ``twist_stamp``).
    """

    def __init__(self, calib=None, config: TrackerConfig | None = None, odom_max_age_s: float = 0.1):
        self.tracker = ConeTracker(config or TrackerConfig(), FieldOfView.from_calibration(calib) if calib is not None else None)
        self.attitude_jacobian = None  # d(x, y)/d(pitch, roll) of a mapped cone, with a mount pose
        if calib is not None and calib.has_attitude_model:
            self.attitude_jacobian = ConeMapper(calib).attitude_jacobian
        self.twists = TwistBuffer(max_age_s=odom_max_age_s)
        self.last_info: FrameInfo | None = None

    @property
    def events(self) -> Counter:
        return self.tracker.events

    def add_twist(self, stamp_ns: int, vx: float, vy: float, wz: float) -> bool:
        """One body twist (m/s, m/s, rad/s); False (and counted) when refused."""
        why = self.twists.add(stamp_ns, vx, vy, wz)
        if why is not None:
            self.tracker.events[why] += 1
        return why is None

    def process(self, stamp_ns: int, cones: np.ndarray, attitude=None) -> tuple[np.ndarray, FrameInfo]:
        """Fuse one frame; returns (:data:`TRACKED_CONE_DTYPE` records, :class:`FrameInfo`).
        ``attitude``: the :class:`~cone_perception.attitude.Attitude` the cones were mapped with (its
        1-sigma is the frame-common part of their covariance, see :meth:`ConeTracker.update`); None: all
        of each cone's covariance is taken as independent.
        Raises ``FrameError`` for a stamp not after the last fused frame."""
        motion = None
        last = self.tracker.last_stamp_ns
        if self.twists.stamps and last is not None and stamp_ns > last:
            motion = self.twists.motion(last, stamp_ns)
            if motion is None:
                self.tracker.events["odom_stale"] += 1
        cov = None
        if attitude is not None and self.attitude_jacobian is not None and self.tracker.config.attitude_common:
            cov = attitude.covariance_deg2()
        self.last_info = self.tracker.update(stamp_ns, cones, motion, self.attitude_jacobian, cov)
        return self.tracker.output(), self.last_info
