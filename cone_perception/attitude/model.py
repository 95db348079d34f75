"""The attitude model: the calibration's ``H_F_B`` recomposed for a body pitch / roll offset.

Attitude offset: the sprung body (and the camera on it) rotates about the rear-axle origin by
``R_att = R_y(pitch) @ R_x(roll)`` (pitch positive = nose DOWN, roll positive = right side
DOWN, degrees), the convention of :class:`~cone_perception.geometry.camera.MountPose` and of the
synthetic scenes' body jitter. The camera's pose in ``rear_axle`` becomes
``R_F_C' = R_att @ R_F_C``, position ``R_att @ p``.

:class:`AttitudeModel` keeps the calibrated ``H_F_B`` exact at zero offset and applies the
offset as a pixel-to-pixel correction derived from the mount pose:
``H_F_B(att) = H_F_B @ H_B_F_pose(0) @ H_F_B_pose(att)``. :class:`Attitude` is one frame's offset.
ROS-free.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..geometry.camera import MountPose
from ..geometry.homography import fix_homography_sign
from ..geometry.linalg import inv3
from ..geometry.pose import attitude_rotation, pose_H_B_F

#: Attitude sources: ``fixed`` (the calibration's H_F_B), ``image`` (cone boxes), ``imu``, ``fused``.
ATTITUDE_MODES = ("fixed", "image", "imu", "fused")
#: Image fits farther than this from zero (degrees, pitch or roll) are rejected and counted.
MAX_ABS_DEG = 5.0


class AttitudeModel:
    """The calibration's ``H_F_B`` for any body attitude offset (pitch, roll in degrees)."""

    def __init__(self, H_F_B: np.ndarray, K: np.ndarray, pose: MountPose, ground_px: tuple[float, float]):
        self.H0 = np.asarray(H_F_B, dtype=np.float64)
        self.K = np.asarray(K, dtype=np.float64)
        self.pose = pose
        self.ground_px = ground_px
        self._H_B_F_rest = pose_H_B_F(self.K, pose)
        self._R_F_C, self._p = pose.R_F_C(), pose.position_F()
        self._H0_rest = self.H0 @ self._H_B_F_rest

    def H_F_B(self, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
        """3x3 undistorted px -> ground (m) with the body tilted by (pitch, roll); the calibrated H at 0."""
        if pitch_deg == 0.0 and roll_deg == 0.0:
            return self.H0
        R_att = attitude_rotation(pitch_deg, roll_deg)  # pose_H_B_F with the pose's rotation cached
        R_C_F = (R_att @ self._R_F_C).T
        t = -R_C_F @ (R_att @ self._p)
        H_B_F = self.K @ np.column_stack([R_C_F[:, 0], R_C_F[:, 1], t])
        return fix_homography_sign(self._H0_rest @ inv3(H_B_F), self.ground_px)


@dataclass(frozen=True)
class Attitude:
    """The attitude offset used for one frame (degrees) with its 1-sigma, and where it came from.

    ``source``: ``fixed``, ``image`` (this frame's fit), ``hold`` (no usable fit this frame: the
    filter's prediction, decaying to zero), ``calibration`` (the image attitude did not beat the calibrated
    H this frame: mapped with zero offset, the prior's 1-sigma), ``imu``, ``fused``. ``n_cones``: cones the fit used.
    """

    pitch_deg: float = 0.0
    roll_deg: float = 0.0
    sigma_pitch_deg: float = 0.0
    sigma_roll_deg: float = 0.0
    source: str = "fixed"
    n_cones: int = 0

    @property
    def is_zero(self) -> bool:
        return self.pitch_deg == 0.0 and self.roll_deg == 0.0

    def covariance_deg2(self) -> np.ndarray:
        """2x2 covariance of (pitch, roll) in degrees^2 (independent)."""
        return np.diag([self.sigma_pitch_deg**2, self.sigma_roll_deg**2])


FIXED = Attitude()


def attitude_vector(att: Attitude) -> tuple[float, float, float]:
    """(x, y, z) of the published ``geometry_msgs/Vector3Stamped``: rotation of the body about the
    ``rear_axle`` axes in RADIANS (REP 103): x = roll (+ right side down), y = pitch (+ nose down), z = 0."""
    return math.radians(att.roll_deg), math.radians(att.pitch_deg), 0.0


def default_attitude_mode(has_mount_pose: bool, has_imu: bool = False) -> str:
    """The issue's default: ``fused`` with an IMU, else ``image`` with a mount pose, else ``fixed``."""
    if has_imu and has_mount_pose:
        return "fused"
    if has_imu:
        return "imu"
    return "image" if has_mount_pose else "fixed"


@dataclass
class AttitudeCounts:
    """Frames by outcome of the image fit (:class:`~cone_perception.attitude.image.ImageAttitude`), and boxes it read."""

    fitted: int = 0
    too_few: int = 0
    rejected: int = 0
    #: frames mapped with the calibration's H because the image attitude did not beat it (any outcome above)
    calibration: int = 0
    #: cones whose box heights went into an average over frames (``size_frames``), and of them those followed
    #: from an earlier frame (the rest start their average)
    size_cones: int = 0
    size_followed: int = 0
    #: boxes whose own box model has no measurement at their size (:meth:`~cone_perception.attitude.boxes.BoxModel.measured`):
    #: far-strip boxes read through the band model's box model instead, and boxes no measured model knows (left out)
    read_by_band: int = 0
    unmeasured: int = 0

    def as_dict(self) -> dict[str, int]:
        return {"fitted": self.fitted, "too_few_cones": self.too_few, "rejected_beyond_limit": self.rejected,
                "used_calibration": self.calibration, "size_cones": self.size_cones, "size_followed": self.size_followed,
                "boxes_read_by_band_model": self.read_by_band, "boxes_unmeasured_size": self.unmeasured}


class FrameClock:
    """How long each frame of a stream is in frames of ``frame_s`` seconds (the interval a filter's settings "per
    frame" are given for), from the frames' stamps: :meth:`step` with each frame's stamp gives its :attr:`k`, the time
    since the last stamp in ``frame_s`` (0.25-4); without a stamp the last frame's, 1 at the first; ``frame_s`` 0: 1."""

    def __init__(self, frame_s: float):
        self.frame_s, self.k, self.last_ns = float(frame_s), 1.0, None

    def step(self, stamp_ns: int | None) -> float:
        """This frame's :attr:`k` from its stamp (None: the last frame's)."""
        if stamp_ns is not None and self.last_ns is not None and self.frame_s > 0 and stamp_ns > self.last_ns:
            self.k = float(np.clip((stamp_ns - self.last_ns) * 1e-9 / self.frame_s, 0.25, 4.0))
        self.last_ns = stamp_ns if stamp_ns is not None else self.last_ns
        return self.k


class RunningBias:
    """A slowly varying bias learnt as a running mean of what a filter sees (degrees, a float or an array): shrunk
    towards zero by ``prior`` pseudo-frames, an exponential mean of ``tau`` frames once that many are in; the frames are
    of ``frame_s`` (each :meth:`fold` counts its ``k``, :class:`FrameClock`); ``tau`` 0: off (:attr:`value` stays 0).
    The image fit's own bias, and in ``fused`` the fit's roll and the IMU's pitch against each other."""

    def __init__(self, prior: float, tau: float, value=0.0):
        self.prior, self.tau, self.n, self.value = float(prior), float(tau), 0.0, value

    def fold(self, x, k: float = 1.0):
        """Fold one reading ``x`` from a frame ``k`` frames long in; the bias now."""
        if self.tau > 0:
            self.n += k
            self.value = self.value + (x - self.value) * k / min(self.n + self.prior, self.tau)
        return self.value
