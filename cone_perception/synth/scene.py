"""The car on the track: its pose per frame, body jitter, and the frame's camera.

Frames: W = flat track frame (m); F = ``rear_axle`` (origin on the ground under
the rear axle, x forward, y left, z up), placed in W by the car pose
``(x_m, y_m, yaw_rad)``. The camera hangs on the sprung body, which pitches and
rolls about the rear-axle origin by ``pitch_deg`` / ``roll_deg`` (suspension
jitter). Ground truth is always given in F, so with jitter on the fixed
nominal ``H_F_B`` is (realistically) slightly wrong.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.camera import PinholeCamera, _rot_x, _rot_y
from .track import Track


@dataclass(frozen=True)
class CarPose:
    """Rear-axle pose in the track frame and body jitter of one frame."""

    x_m: float
    y_m: float
    yaw_rad: float
    pitch_deg: float = 0.0  # body pitch, positive = nose down
    roll_deg: float = 0.0  # body roll, positive = right side down

    def to_dict(self) -> dict:
        return {
            "x_m": round(self.x_m, 4),
            "y_m": round(self.y_m, 4),
            "yaw_deg": round(float(np.degrees(self.yaw_rad)), 4),
            "pitch_deg": round(self.pitch_deg, 4),
            "roll_deg": round(self.roll_deg, 4),
        }


class SceneCamera:
    """The mounted camera of one frame: world points -> pixels, world ground -> pixels.

    ``camera`` is the nominal mounted camera (its ``pose`` is the nominal
    mount); the body jitter of ``pose`` is applied on top.
    """

    def __init__(self, camera: PinholeCamera, pose: CarPose):
        self.camera = camera
        self.pose = pose
        c, s = np.cos(pose.yaw_rad), np.sin(pose.yaw_rad)
        self.R_W_F2 = np.array([[c, -s], [s, c]])
        self.t_W_F = np.array([pose.x_m, pose.y_m])
        # body rotation about the rear-axle origin (pitch about +y, then roll about +x)
        self.R_jit = _rot_y(np.radians(pose.pitch_deg)) @ _rot_x(np.radians(pose.roll_deg))

    def world_to_F(self, P_W: np.ndarray) -> np.ndarray:
        """(N, 3) or (N, 2) track-frame points (m) -> same shape in ``rear_axle`` (m)."""
        P = np.asarray(P_W, dtype=np.float64)
        out = P.copy()
        out[:, :2] = (P[:, :2] - self.t_W_F) @ self.R_W_F2
        return out

    def project(self, P_W: np.ndarray, distort: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) track-frame points -> ((N, 2) full-image px, (N,) depth m); NaN behind the camera.

        Jitter moves the camera by ``R_jit`` about the rear axle, which is the
        same as moving the points by ``R_jit^T`` in front of the nominal camera.
        ``distort=False`` gives ideal pinhole pixels (the renderer draws those
        and distorts the finished image).
        """
        P_J = self.world_to_F(P_W) @ self.R_jit  # row vectors: R_jit^T p
        cam = self.camera if distort or not self.camera.dist_coeffs.size else _pinhole(self.camera)
        return cam.project(P_J)

    def position_W(self) -> np.ndarray:
        """Camera centre in the track frame (3,)."""
        p_F = self.R_jit @ self.camera.pose.position_F()
        return np.array([*(self.R_W_F2 @ p_F[:2] + self.t_W_F), p_F[2]])

    def H_B_W(self) -> np.ndarray:
        """Homography track-frame ground (x, y, 1) -> ideal pinhole pixels."""
        R_C_F = self.camera.pose.R_C_F()
        A = np.zeros((3, 3))  # [xw, yw, 1] -> 3D point in F (z = 0)
        A[:2, :2] = self.R_W_F2.T
        A[:2, 2] = -self.R_W_F2.T @ self.t_W_F
        e3 = np.array([0.0, 0.0, 1.0])
        M = R_C_F @ self.R_jit.T @ A - np.outer(R_C_F @ self.camera.pose.position_F(), e3)
        return self.camera.K @ M


def _pinhole(cam: PinholeCamera) -> PinholeCamera:
    return PinholeCamera(K=cam.K, width=cam.width, height=cam.height, pose=cam.pose)


def ground_visible(camera: PinholeCamera, max_range_m: float = 60.0) -> bool:
    """True if some pixel of the image sees the ground within ``max_range_m`` of the camera."""
    H_F_B = camera.H_F_B()
    W, Hh = camera.width, camera.height
    uu, vv = np.meshgrid(np.linspace(0, W - 1, 9), np.linspace(0, Hh - 1, 9))
    p = np.column_stack([uu.ravel(), vv.ravel(), np.ones(uu.size)]) @ H_F_B.T
    ok = p[:, 2] > 1e-12
    if not np.any(ok):
        return False
    xy = p[ok, :2] / p[ok, 2:3]
    d = np.hypot(xy[:, 0] - camera.pose.x_m, xy[:, 1] - camera.pose.y_m)
    return bool(np.any(d <= max_range_m))


def jitter_series(n: int, fps: float, rng: np.random.Generator, amp_deg: float = 1.0) -> np.ndarray:
    """(n, 2) smooth body (pitch, roll) in degrees, |.| <= ``amp_deg``: two sines of 0.7-3 Hz each."""
    t = np.arange(n) / fps
    out = np.zeros((n, 2))
    for j in range(2):
        f = rng.uniform(0.7, 3.0, 2)
        ph = rng.uniform(0, 2 * np.pi, 2)
        a = rng.uniform(0.3, 0.5, 2) * amp_deg
        out[:, j] = a[0] * np.sin(2 * np.pi * f[0] * t + ph[0]) + a[1] * np.sin(2 * np.pi * f[1] * t + ph[1])
    return out


def drive_poses(
    track: Track, n: int, fps: float, speed_mps: float, rng: np.random.Generator, jitter: bool = True, start_m: float = 0.0
) -> list[CarPose]:
    """``n`` poses driving the centre line from ``start_m`` at ``speed_mps`` (wraps to the start at the end)."""
    jit = jitter_series(n, fps, rng) if jitter else np.zeros((n, 2))
    L = track.length_m
    out = []
    for i in range(n):
        s = (start_m + speed_mps * i / fps) % max(L - 1.0, 1.0)
        x, y, yaw = track.pose_at(s, interpolate=True)
        out.append(CarPose(x, y, yaw, float(jit[i, 0]), float(jit[i, 1])))
    return out


def random_pose(track: Track, rng: np.random.Generator, jitter: bool = True) -> CarPose:
    """A pose somewhere on the track: on the line +- a quarter width, heading +- ~4 degrees, random jitter."""
    s = rng.uniform(0.0, max(track.length_m - 5.0, 0.0))
    x, y, yaw = track.pose_at(s)
    off = rng.uniform(-0.25, 0.25) * track.width_m
    x, y = x - np.sin(yaw) * off, y + np.cos(yaw) * off
    yaw += np.radians(rng.normal(0.0, 4.0))
    p, r = (rng.uniform(-1.0, 1.0, 2) if jitter else (0.0, 0.0))
    return CarPose(float(x), float(y), float(yaw), float(p), float(r))
