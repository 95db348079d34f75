"""Camera attitude per frame: the calibration's ``H_F_B`` recomposed for a body pitch / roll offset
(:mod:`.model`), the offset fitted from the frame's cone boxes (:mod:`.image`, reading them through the
detector's box model, :mod:`.boxes`), read from an IMU
(:mod:`.imu`), or both fused through a ground gate (:mod:`.fused`). How good an attitude was is
:mod:`cone_perception.evaluation.attitude`. ROS-free; see docs/attitude.md.
"""

from __future__ import annotations

from .boxes import BOX_MODEL_BUCKETS_PX, DEFAULT_BOX_MODEL, BoxModel, box_top_extra_px
from .fused import FusedAttitude, GroundGate, attitude_estimator, attitude_for_boxes
from .image import ImageAttitude, ImageAttitudeConfig
from .imu import (
    IMU_MAX_AGE_NS, IMU_REST_MAX_ACCEL_SD, IMU_REST_MAX_ANGLE_SD_DEG, IMU_REST_MAX_RATE_SD_DPS, IMU_REST_MIN_SAMPLES,
    QUAT_NORM_TOL, ImuAttitude, ImuCounts, ImuRest, imu_rest, rpy_from_quaternion,
)
from .model import ATTITUDE_MODES, FIXED, MAX_ABS_DEG, Attitude, AttitudeCounts, AttitudeModel, attitude_vector, default_attitude_mode

__all__ = ["ATTITUDE_MODES", "Attitude", "AttitudeCounts", "AttitudeModel", "BOX_MODEL_BUCKETS_PX", "BoxModel",
    "DEFAULT_BOX_MODEL", "FIXED", "FusedAttitude", "GroundGate",
    "IMU_MAX_AGE_NS", "IMU_REST_MAX_ACCEL_SD", "IMU_REST_MAX_ANGLE_SD_DEG", "IMU_REST_MAX_RATE_SD_DPS",
    "IMU_REST_MIN_SAMPLES", "ImageAttitude", "ImageAttitudeConfig", "ImuAttitude", "ImuCounts", "ImuRest",
    "MAX_ABS_DEG", "QUAT_NORM_TOL", "attitude_estimator", "attitude_for_boxes", "attitude_vector",
    "box_top_extra_px", "default_attitude_mode", "imu_rest", "rpy_from_quaternion"]
