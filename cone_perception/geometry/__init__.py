"""Ground geometry of one camera: homographies, foot points and covariance (:mod:`.homography`), the
pinhole camera and its mount pose (:mod:`.camera`), pose <-> homography (:mod:`.pose`), the calibration
YAML (:mod:`.calib`), the camera's static transform (:mod:`.transforms`). ROS-free.
"""

from __future__ import annotations

from .homography import (
    FOOT_RULES, GroundMapper, apply_homography, covariance_ellipses, distort_pixels, fix_homography_sign,
    foot_point_weights, foot_points, homography_jacobian, undistort_pixels,
)

__all__ = ["FOOT_RULES", "GroundMapper", "apply_homography", "covariance_ellipses", "distort_pixels",
    "fix_homography_sign", "foot_point_weights", "foot_points", "homography_jacobian", "undistort_pixels"]
