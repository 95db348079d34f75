"""The camera's static transform ``rear_axle`` -> ``<camera>_optical_frame`` (for tf2 and rviz2),
from the calibration's mount pose. ROS-free; ``car.launch.py tf:=true`` starts tf2_ros's
``static_transform_publisher`` with :meth:`StaticTransform.args`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from ..errors import ConfigError
from .calib import Calibration
from .camera import MountPose
from .pose import pose_from_homography


def mount_pose_of(calib: Calibration) -> tuple[MountPose, str]:
    """The camera's mount pose in ``calib.frame_id`` and where it came from, in this order:
    ``mount_pose`` (measured), ``mount`` (written by ``calibrate --from-pose``), or decomposed from
    ``H_F_B`` and ``camera_matrix`` (:func:`~cone_perception.geometry.pose.pose_from_homography`).
    Without any of them: a :class:`ConfigError` naming the fields to add."""
    if calib.mount_pose is not None:
        return calib.mount_pose, "mount_pose"
    legacy = calib.extra.get("mount")
    if isinstance(legacy, dict) and all(k in legacy for k in ("x_m", "y_m", "height_m", "pitch_deg")):
        keys = ("x_m", "y_m", "height_m", "pitch_deg", "roll_deg", "yaw_deg")
        try:
            return MountPose(**{k: float(legacy.get(k, 0.0)) for k in keys}), "mount"
        except (TypeError, ValueError):
            raise ConfigError(calib.source, "mount", "must hold numbers") from None
    if calib.camera_matrix is not None:
        return pose_from_homography(calib.H_F_B, calib.camera_matrix).pose, "H_F_B + camera_matrix"
    raise ConfigError(calib.source, "mount_pose",
                      "missing: the camera's transform needs mount_pose {x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg} "
                      "or camera_matrix (the pose is then decomposed from the homography)")


def quaternion_xyzw(R: np.ndarray) -> np.ndarray:
    """(4,) float64 unit quaternion (x, y, z, w), w >= 0, of a 3x3 rotation matrix."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = [0.0, 0.0, 0.0, (R[k, j] - R[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
    q = np.asarray(q, dtype=np.float64)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


@dataclass(frozen=True)
class StaticTransform:
    """``child`` in ``parent``: translation (3,) m and rotation (x, y, z, w), as tf2 takes them."""

    parent: str
    child: str
    xyz_m: tuple[float, float, float]
    xyzw: tuple[float, float, float, float]
    source: str = ""

    def args(self) -> list[str]:
        """Arguments of ``ros2 run tf2_ros static_transform_publisher`` (Humble and newer)."""
        out = []
        for name, v in zip(("--x", "--y", "--z"), self.xyz_m):
            out += [name, f"{v:.9g}"]
        for name, v in zip(("--qx", "--qy", "--qz", "--qw"), self.xyzw):
            out += [name, f"{v:.9g}"]
        return out + ["--frame-id", self.parent, "--child-frame-id", self.child]


def optical_frame_name(calib: Calibration) -> str:
    """``<camera>_optical_frame`` (REP 103 optical axes: x right, y down, z forward)."""
    return f"{calib.camera}_optical_frame"


def optical_frame_transform(calib: Calibration, child_frame: str | None = None) -> StaticTransform:
    """``calib.frame_id`` (``rear_axle``) -> the camera's optical frame, from :func:`mount_pose_of`."""
    pose, source = mount_pose_of(calib)
    xyz = tuple(float(v) for v in pose.position_F())
    q = tuple(float(v) for v in quaternion_xyzw(pose.R_F_C()))
    return StaticTransform(calib.frame_id, child_frame or optical_frame_name(calib), xyz, q, source)  # type: ignore[arg-type]


def calibration_in_params_file(path: str | os.PathLike, node: str = "mapping") -> str | None:
    """The ``calibration`` parameter ``node`` gets from a ROS 2 parameter YAML (its own section
    first, then ``/**``), or ``None`` when the file sets none."""
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    except (OSError, yaml.YAMLError) as e:
        raise ConfigError(str(path), None, f"cannot read the parameter file: {e}") from None
    for section in (node, f"/{node}", "/**"):
        params = (data.get(section) or {}).get("ros__parameters") or {}
        if "calibration" in params:
            return str(params["calibration"])
    return None
