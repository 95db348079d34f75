"""A camera's mount pose and the ground homography, both ways: :func:`from_pose` (pose + K ->
``H_F_B``), :func:`pose_from_homography` (``H_F_B`` + K -> pose), the body's attitude rotation and the
homography of a tilted body (:func:`pose_H_B_F`), and how far a pose disagrees with a calibrated
homography (:func:`mount_pose_disagreement`). The calibration, the attitude model and ``calibrate`` use
them. ROS-free.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .camera import MountPose, PinholeCamera
from .homography import apply_homography

#: A mount pose may disagree with the calibration's own H_F_B by at most this fraction of range at 10 m.
MOUNT_POSE_TOLERANCE = 0.01
MOUNT_POSE_CHECK_RANGE_M = 10.0


def from_pose(K: np.ndarray, width: int, height: int, pose: MountPose) -> np.ndarray:
    """``H_F_B`` (undistorted px -> rear_axle m) of a camera with known K and mount pose."""
    return PinholeCamera(np.asarray(K, dtype=np.float64), int(width), int(height), pose).H_F_B()


@dataclass(frozen=True)
class PoseEstimate:
    """Mount pose recovered from ``H_F_B`` and K, with how well K fits H.

    ``column_ratio`` = |r1| / |r2| of ``K^-1 H_B_F`` (1 for a consistent K),
    ``column_angle_deg`` their angle (90 for a consistent K).
    """

    pose: MountPose
    column_ratio: float
    column_angle_deg: float


def pose_from_homography(H_F_B: np.ndarray, K: np.ndarray) -> PoseEstimate:
    """Inverse of :func:`from_pose`: decompose ``K^-1 H_B_F = s [r1 r2 t]`` into the mount pose.

    r1, r2 are the first two columns of ``R_C_F`` (scale from their mean
    length, sign so the ground lies in front of the camera), r3 = r1 x r2, the
    rotation re-orthonormalised by SVD; camera position ``-R^T t``; yaw, pitch,
    roll in the convention of :class:`~cone_perception.geometry.camera.MountPose`.
    """
    M = np.linalg.inv(np.asarray(K, dtype=np.float64)) @ np.linalg.inv(np.asarray(H_F_B, dtype=np.float64))
    m1, m2, m3 = M[:, 0], M[:, 1], M[:, 2]
    n1, n2 = np.linalg.norm(m1), np.linalg.norm(m2)
    angle = math.degrees(math.acos(np.clip(m1 @ m2 / (n1 * n2), -1.0, 1.0)))
    s = 2.0 / (n1 + n2)  # the sign is fixed below: the camera must be above the ground
    r1, r2, t = s * m1, s * m2, s * m3
    R = np.column_stack([r1, r2, np.cross(r1, r2)])
    U, _, Vt = np.linalg.svd(R)
    R = U @ Vt
    if np.linalg.det(R) < 0:
        R = U @ np.diag([1, 1, -1]) @ Vt
    C = -R.T @ t
    if C[2] < 0:  # wrong overall sign: camera below the ground
        r1, r2, t = -r1, -r2, -t
        R = np.column_stack([r1, r2, np.cross(r1, r2)])
        U, _, Vt = np.linalg.svd(R)
        R = U @ Vt
        C = -R.T @ t
    pose = MountPose.from_R_F_C(R.T, C)
    return PoseEstimate(pose, float(n1 / n2), angle)


def attitude_rotation(pitch_deg: float, roll_deg: float) -> np.ndarray:
    """3x3 body rotation ``R_y(pitch) @ R_x(roll)`` (degrees; pitch + = nose down, roll + = right down)."""
    p, r = math.radians(pitch_deg), math.radians(roll_deg)
    cp, sp, cr, sr = math.cos(p), math.sin(p), math.cos(r), math.sin(r)
    return np.array([[cp, sp * sr, sp * cr], [0.0, cr, -sr], [-sp, cp * sr, cp * cr]])


def pose_H_B_F(K: np.ndarray, pose: MountPose, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
    """Homography ground (x, y of ``rear_axle``) -> undistorted px of a camera at ``pose`` on a body
    tilted by (pitch, roll) about the rear-axle origin."""
    R_att = attitude_rotation(pitch_deg, roll_deg)
    R_C_F = (R_att @ pose.R_F_C()).T
    t = -R_C_F @ (R_att @ pose.position_F())
    return np.asarray(K, dtype=np.float64) @ np.column_stack([R_C_F[:, 0], R_C_F[:, 1], t])


def mount_pose_disagreement(H_F_B: np.ndarray, K: np.ndarray, pose: MountPose, width: int, height: int,
                            range_m: float = MOUNT_POSE_CHECK_RANGE_M) -> float:
    """Largest position error, as a fraction of range, between ``pose`` (with K) and ``H_F_B`` for
    ground points ``range_m`` from the camera that the image sees (17 bearings across the view).

    Returns ``inf`` when the pose's camera sees no ground at that range inside the image.
    """
    cam = PinholeCamera(np.asarray(K, dtype=np.float64), width, height, pose)
    bearings = np.radians(np.linspace(-80.0, 80.0, 17)) + np.radians(pose.yaw_deg)
    g = np.column_stack([pose.x_m + range_m * np.cos(bearings), pose.y_m + range_m * np.sin(bearings)])
    uv, w = apply_homography(cam.H_B_F(), g)
    inside = (w > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= height - 1)
    if not np.any(inside):
        return float("inf")
    xy, w2 = apply_homography(H_F_B, uv[inside])
    if np.any(w2 <= 0):
        return float("inf")
    return float(np.max(np.hypot(*(xy - g[inside]).T)) / range_m)
