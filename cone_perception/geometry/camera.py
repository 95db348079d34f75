"""Pinhole camera on the car: mount pose, projection, and the ground homography
that follows from them.

Frames: vehicle frame F = ``rear_axle`` (x forward, y left, z up, origin on the
ground under the middle of the rear axle, REP 103). Optical camera frame C:
x right, y down, z along the optical axis (REP 103 ``_optical`` convention).

Mount angles (degrees), applied to a camera that first looks straight along +x:
``yaw`` about +z (positive turns the camera to the left), then ``pitch`` about
the camera's +y (positive looks DOWN), then ``roll`` about its +x (positive
lowers the camera's right side).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from .homography import fix_homography_sign

# Optical axes expressed in a vehicle-aligned frame: z_opt = x_veh, x_opt = -y_veh, y_opt = -z_veh.
_R_OPT_FROM_BODY = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


def _rot_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=np.float64)


def _rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=np.float64)


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=np.float64)


@dataclass(frozen=True)
class MountPose:
    """Camera position (m, in ``rear_axle``) and orientation (degrees)."""

    x_m: float = 0.5
    y_m: float = 0.0
    height_m: float = 1.2
    pitch_deg: float = 10.0
    roll_deg: float = 0.0
    yaw_deg: float = 0.0

    def R_F_C(self) -> np.ndarray:
        """Rotation taking optical-frame vectors to the vehicle frame (3x3)."""
        R_F_body = (
            _rot_z(np.radians(self.yaw_deg)) @ _rot_y(np.radians(self.pitch_deg)) @ _rot_x(np.radians(self.roll_deg))
        )
        return R_F_body @ _R_OPT_FROM_BODY.T

    def R_C_F(self) -> np.ndarray:
        """Rotation taking vehicle-frame vectors to the optical frame (3x3)."""
        return self.R_F_C().T

    def position_F(self) -> np.ndarray:
        return np.array([self.x_m, self.y_m, self.height_m], dtype=np.float64)

    @classmethod
    def from_R_F_C(cls, R_F_C: np.ndarray, position_F: np.ndarray) -> "MountPose":
        """Inverse of :meth:`R_F_C` / :meth:`position_F`: a rotation (3x3) and a position (m) -> pose."""
        R = np.asarray(R_F_C, dtype=np.float64) @ _R_OPT_FROM_BODY  # = Rz(yaw) Ry(pitch) Rx(roll)
        yaw = np.degrees(np.arctan2(R[1, 0], R[0, 0]))
        pitch = np.degrees(np.arcsin(np.clip(-R[2, 0], -1.0, 1.0)))
        roll = np.degrees(np.arctan2(R[2, 1], R[2, 2]))
        x, y, z = (float(v) for v in np.asarray(position_F, dtype=np.float64).ravel())
        return cls(x, y, z, float(pitch), float(roll), float(yaw))


def intrinsics(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """3x3 camera matrix K."""
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=np.float64)


def default_intrinsics(width: int = 1920, height: int = 1080, hfov_deg: float = 90.0) -> np.ndarray:
    """Square-pixel K with the principal point in the image centre."""
    f = (width / 2.0) / np.tan(np.radians(hfov_deg) / 2.0)
    return intrinsics(f, f, width / 2.0, height / 2.0)


@dataclass(frozen=True)
class PinholeCamera:
    """A calibrated camera mounted on the car.

    ``dist_coeffs`` follow OpenCV's model ``(k1, k2, p1, p2[, k3 ...])``; empty
    means an ideal pinhole.
    """

    K: np.ndarray
    width: int
    height: int
    pose: MountPose = field(default_factory=MountPose)
    dist_coeffs: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def to_camera(self, points_F: np.ndarray) -> np.ndarray:
        """(N, 3) vehicle-frame points (m) -> (N, 3) optical-frame points (m)."""
        P = np.asarray(points_F, dtype=np.float64).reshape(-1, 3)
        return (P - self.pose.position_F()) @ self.pose.R_C_F().T

    def project(self, points_F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) vehicle-frame points -> ((N, 2) full-image px, (N,) depth in m).

        Points behind the camera (depth <= 0) get NaN pixels.
        """
        Pc = self.to_camera(points_F)
        z = Pc[:, 2]
        uv = np.full((Pc.shape[0], 2), np.nan)
        ok = z > 1e-6
        if np.any(ok):
            if self.dist_coeffs.size:
                pts, _ = cv2.projectPoints(
                    Pc[ok].reshape(-1, 1, 3), np.zeros(3), np.zeros(3), self.K, self.dist_coeffs.astype(np.float64)
                )
                uv[ok] = pts.reshape(-1, 2)
            else:
                p = Pc[ok] @ self.K.T
                uv[ok] = p[:, :2] / p[:, 2:3]
        return uv, z

    def H_B_F(self) -> np.ndarray:
        """Homography ground plane (x, y, z=0 of ``rear_axle``) -> undistorted pixels."""
        R = self.pose.R_C_F()
        t = -R @ self.pose.position_F()
        return self.K @ np.column_stack([R[:, 0], R[:, 1], t])

    def H_F_B(self) -> np.ndarray:
        """Homography undistorted pixels -> ground (m), |h33| = 1 and w > 0 on the ground, by the package's
        one sign rule (:func:`~cone_perception.geometry.fix_homography_sign`) at the pixel of a ground point
        10 m ahead of the camera (along its heading)."""
        H_B_F = self.H_B_F()
        yaw = np.radians(self.pose.yaw_deg)
        ahead = H_B_F @ np.array([self.pose.x_m + 10.0 * np.cos(yaw), self.pose.y_m + 10.0 * np.sin(yaw), 1.0])
        if ahead[2] <= 0:  # its depth: the camera looks away from the ground ahead
            raise ValueError(f"camera mount {self.pose} does not see the ground ahead of it")
        return fix_homography_sign(np.linalg.inv(H_B_F), ahead[:2] / ahead[2])

    def horizon_v(self, u: float | None = None) -> float:
        """Row of the horizon (vanishing line of the ground) at column ``u`` (default centre)."""
        u = self.width / 2.0 if u is None else u
        h = self.H_F_B()[2]  # w(u, v) = h0 u + h1 v + h2 = 0 on the horizon
        return float(-(h[0] * u + h[2]) / h[1])
