"""Calibration fit: point pairs -> ``H_S_B`` -> ``H_F_B`` (:func:`fit_calibration`), mount pose <-> homography
(:func:`from_pose`, :func:`pose_from_homography`), lens intrinsics from chessboard views or a file.

Frames (thesis ch. 4, see ``calib/README.md``):

* ``B``: pixels of the full camera image (u right, v down). With a lens model
  (``camera_matrix`` + ``dist_coeffs``) every homography here works on
  UNDISTORTED pixels of the same K; raw pixels are undistorted first.
* ``S``: the ground frame of the calibration set-up, metres, x forward (away
  from the car), y left. By default its origin is the centre of the
  chessboard's inner-corner grid.
* ``F``: ``rear_axle`` (x forward, y left, origin under the middle of the rear
  axle). ``T_F_S`` is the planar rigid transform S -> F.

``H_S_B`` maps undistorted pixels to S; ``H_F_B = T_F_S @ H_S_B`` to F. H is
estimated as the ground -> image map (so that RANSAC thresholds and the
least-squares refinement are in pixels, where the detection noise lives) and
then inverted.

Bad input raises :class:`~cone_perception.errors.ConfigError` naming the
source (image, point file) and what is wrong. ROS-free.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np
import yaml

from ..crop import CropSpec
from ..errors import ConfigError
from ..geometry import apply_homography, distort_pixels, fix_homography_sign, undistort_pixels
from ..geometry.camera import MountPose
from ..geometry.pose import from_pose
from .points import PointPairs, detect_board

DEFAULT_RANSAC_PX = 3.0


# -- homography ----------------------------------------------------------------------------------
def _check_spread(xy: np.ndarray, uv: np.ndarray, source: str) -> None:
    for pts, what in ((xy, "ground (x_s, y_s)"), (uv, "image (u, v)")):
        c = pts - pts.mean(axis=0)
        s = np.linalg.svd(c, compute_uv=False)
        if s[0] <= 0 or s[1] / s[0] < 1e-3:
            raise ConfigError(
                source,
                "points",
                f"the {len(pts)} points are collinear in the {what} (spread ratio {s[1] / max(s[0], 1e-300):.1e}): "
                "a homography needs points spread in two directions; add points off that line",
            )


def estimate_homography(
    uv_px: np.ndarray, xy_S: np.ndarray, ransac_px: float = DEFAULT_RANSAC_PX, source: str = "calibration"
) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) undistorted px + (N, 2) m in S -> (``H_S_B`` 3x3, (N,) bool inliers).

    Robust fit of the ground -> image map with ``cv2.RANSAC`` (threshold
    ``ransac_px`` in pixels; ``cv2.USAC_MAGSAC`` was tried and fails on the
    exact grid of a chessboard), then Levenberg-Marquardt refinement on the
    inliers (``cv2.findHomography`` method 0), inliers re-selected with the
    refined map. Raises :class:`ConfigError` for fewer than 4 points, collinear
    points, or fewer than 4 inliers.
    """
    uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 2)
    xy = np.asarray(xy_S, dtype=np.float64).reshape(-1, 2)
    if len(uv) < 4:
        raise ConfigError(source, "points", f"need at least 4 usable point pairs for a homography, got {len(uv)}")
    _check_spread(xy, uv, source)
    if len(uv) >= 5:
        H_B_S, mask = cv2.findHomography(xy, uv, cv2.RANSAC, ransac_px, maxIters=5000, confidence=0.9999)
        if H_B_S is None:
            raise ConfigError(source, "points", "no homography fits the points (RANSAC failed): check the point pairs")
        inl = mask.ravel().astype(bool)
    else:
        inl = np.ones(len(uv), dtype=bool)
    for _ in range(3):
        if inl.sum() < 4:
            raise ConfigError(
                source,
                "points",
                f"only {int(inl.sum())} of {len(uv)} points agree with one homography (need 4): check the point pairs",
            )
        _check_spread(xy[inl], uv[inl], source)
        H_B_S, _ = cv2.findHomography(xy[inl], uv[inl], 0)
        if H_B_S is None:
            raise ConfigError(source, "points", "homography refinement failed: check the point pairs")
        proj, w = apply_homography(H_B_S, xy)
        err = np.linalg.norm(proj - uv, axis=1)
        new = (w != 0) & (err <= ransac_px)
        if len(uv) < 5 or np.array_equal(new, inl):
            break
        inl = new
    return np.linalg.inv(H_B_S), inl


# -- result + report -----------------------------------------------------------------------------
@dataclass
class Intrinsics:
    """Lens model: ``K`` 3x3, ``dist`` OpenCV coefficients (may be empty), and where it came from."""

    K: np.ndarray
    dist: np.ndarray
    source: str
    rms_px: float | None = None  # of cv2.calibrateCamera, when estimated here
    image_size: tuple[int, int] | None = None  # (width, height) the model was made for, when known

    @property
    def has_distortion(self) -> bool:
        return self.dist.size > 0 and bool(np.any(self.dist != 0))


@dataclass
class CalibrationResult:
    """Everything one calibration produced. Pixels in ``pairs`` are raw; ``uv_und_px`` undistorted."""

    H_S_B: np.ndarray
    T_F_S: np.ndarray
    H_F_B: np.ndarray
    width: int
    height: int
    pairs: PointPairs
    inliers: np.ndarray
    uv_und_px: np.ndarray
    intrinsics: Intrinsics | None = None
    warnings: list[str] = field(default_factory=list)

    def H_B_F(self) -> np.ndarray:
        return np.linalg.inv(self.H_F_B)

    def undistort(self, uv_px: np.ndarray) -> np.ndarray:
        if self.intrinsics is None or not self.intrinsics.has_distortion:
            return np.asarray(uv_px, dtype=np.float64).reshape(-1, 2)
        return undistort_pixels(uv_px, self.intrinsics.K, self.intrinsics.dist)

    def distort(self, uv_und_px: np.ndarray) -> np.ndarray:
        if self.intrinsics is None or not self.intrinsics.has_distortion:
            return np.asarray(uv_und_px, dtype=np.float64).reshape(-1, 2)
        return distort_pixels(uv_und_px, self.intrinsics.K, self.intrinsics.dist)

    def ground_to_raw_px(self, xy_F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) m in F -> ((N, 2) raw px, (N,) bool valid).

        Valid: in front of the camera and, with a lens model, where the model
        is one-to-one (undistorting the raw pixel gives the pixel back within
        0.5 px; outside the field of view the polynomial folds back).
        """
        uv, w = apply_homography(self.H_B_F(), xy_F)
        # w of H_B_F has the sign of the depth because H_F_B has w > 0 on the ground (fixed sign)
        valid = w > 0
        out = np.full_like(uv, np.nan)
        if np.any(valid):
            out[valid] = self.distort(uv[valid])
            if self.intrinsics is not None and self.intrinsics.has_distortion:
                back = np.full_like(uv, np.nan)
                back[valid] = self.undistort(out[valid])
                with np.errstate(invalid="ignore"):
                    valid &= np.linalg.norm(back - uv, axis=1) < 0.5
                out[~valid] = np.nan
        return out, valid

    def xy_F(self) -> np.ndarray:
        """(N, 2) true positions of the pairs in F (m)."""
        return self.pairs.xy_S @ self.T_F_S[:2, :2].T + self.T_F_S[:2, 2]


def fit_calibration(
    pairs: PointPairs,
    width: int,
    height: int,
    T_F_S: np.ndarray,
    intrinsics: Intrinsics | None = None,
    ransac_px: float = DEFAULT_RANSAC_PX,
    source: str = "calibration",
) -> CalibrationResult:
    """Point pairs -> :class:`CalibrationResult` (H_S_B, H_F_B with fixed sign, inliers).

    Raises :class:`ConfigError` for too few / collinear points and for an H
    that puts the calibration points on the sky side of the horizon (w <= 0
    once the sign is fixed at the image's bottom centre, as the mapping does)
    or that is mirrored (S not right-handed, e.g. y_s pointing right).
    """
    res = CalibrationResult(
        np.eye(3), T_F_S, np.eye(3), width, height, pairs, np.zeros(len(pairs), bool), np.zeros((0, 2)), intrinsics
    )
    uv_und = res.undistort(pairs.uv_px)
    H_S_B, inl = estimate_homography(uv_und, pairs.xy_S, ransac_px, source)
    ref = (width / 2.0, height - 1.0)
    try:
        H_S_B = fix_homography_sign(H_S_B, ref)
    except ValueError as e:
        raise ConfigError(
            source, "H", f"the horizon of the fitted H runs through the bottom of the image ({e})"
        ) from None
    H_F_B = fix_homography_sign(T_F_S @ H_S_B, ref)
    _, w = apply_homography(H_F_B, uv_und[inl])
    if np.any(w <= 0):
        bad = [pairs.labels[i] for i in np.flatnonzero(inl)[w <= 0]][:5]
        raise ConfigError(
            source,
            "H",
            f"the fitted H puts {int((w <= 0).sum())} of the calibration points above the horizon (w <= 0), e.g. "
            f"{', '.join(bad)}: the pairs are inconsistent (x_s/y_s swapped or wrong, or points off the ground)",
        )
    if np.linalg.det(H_F_B) > 0:
        raise ConfigError(
            source,
            "H",
            "the fitted H is mirrored (ground frame left-handed): y must point to the LEFT of x; "
            "check the sign of y_s in the point file or --board-pose",
        )
    res.H_S_B, res.H_F_B, res.inliers, res.uv_und_px = H_S_B, H_F_B, inl, uv_und
    return res


# -- intrinsics ----------------------------------------------------------------------------------
def calibrate_intrinsics(
    views: Sequence[tuple[str, np.ndarray]], size: tuple[int, int], square_m: float
) -> tuple[Intrinsics, list[str]]:
    """Lens model from several chessboard views (``cv2.calibrateCamera``, 5 coefficients).

    ``views``: (name, image) pairs, all the same size. Returns the intrinsics
    and the names of views in which no board was found (reported, not used).
    Raises :class:`ConfigError` with fewer than 3 usable views or mixed sizes.
    """
    cols, rows = size
    i, j = np.divmod(np.arange(rows * cols), cols)
    objp = np.column_stack([j * square_m, i * square_m, np.zeros(rows * cols)]).astype(np.float32)
    obj, img, missed, shape = [], [], [], None
    for name, image in views:
        hw = image.shape[:2]
        if shape is None:
            shape = hw
        elif hw != shape:
            raise ConfigError(
                name, None, f"view size {hw[1]}x{hw[0]} differs from the first view's {shape[1]}x{shape[0]}"
            )
        corners = detect_board(image, size)
        if corners is None:
            missed.append(name)
            continue
        obj.append(objp)
        img.append(corners.astype(np.float32).reshape(-1, 1, 2))
    if len(obj) < 3:
        raise ConfigError(
            "--views",
            None,
            f"the {cols}x{rows} board was found in only {len(obj)} of {len(views)} views; need at least 3 "
            f"(tilted, at different places in the image){'; not found in: ' + ', '.join(missed) if missed else ''}",
        )
    assert shape is not None
    rms, K, dist, _, _ = cv2.calibrateCamera(obj, img, (shape[1], shape[0]), None, None)
    src = f"{len(obj)} chessboard views (cv2.calibrateCamera)"
    return Intrinsics(K, dist.ravel(), src, float(rms), (int(shape[1]), int(shape[0]))), missed


def read_intrinsics_file(path: Path) -> Intrinsics:
    """camera_matrix + dist_coeffs from our calibration YAML or a ROS camera_calibration ``ost.yaml``."""
    src = str(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise ConfigError(src, None, f"cannot read: {e.strerror}") from None
    except yaml.YAMLError as e:
        raise ConfigError(src, None, f"not valid YAML: {e}") from None
    if not isinstance(data, dict):
        raise ConfigError(src, None, "must be a YAML mapping with camera_matrix and dist_coeffs")

    def values(key_names: tuple[str, ...], n: int | None) -> np.ndarray | None:
        for k in key_names:
            if k in data and data[k] is not None:
                v = data[k]
                v = v.get("data") if isinstance(v, dict) else v
                try:
                    a = np.asarray(v, dtype=np.float64).ravel()
                except (TypeError, ValueError):
                    raise ConfigError(src, k, "must be numbers (a list, rows, or a mapping with data:)") from None
                if (n is not None and a.size != n) or not np.all(np.isfinite(a)):
                    raise ConfigError(src, k, f"must be {n or 'some'} finite numbers, got {a.size}")
                return a
        return None

    K = values(("camera_matrix",), 9)
    if K is None:
        raise ConfigError(src, "camera_matrix", "missing")
    d = values(("dist_coeffs", "distortion_coefficients"), None)
    d = np.zeros(0) if d is None else d
    if d.size not in (0, 4, 5, 8, 12, 14):
        raise ConfigError(src, "dist_coeffs", f"must be 4, 5, 8, 12 or 14 numbers (OpenCV model), got {d.size}")
    size = None
    w, h = data.get("image_width"), data.get("image_height")
    if isinstance(w, int) and isinstance(h, int):
        size = (w, h)
    return Intrinsics(K.reshape(3, 3), d, src, image_size=size)


def result_from_pose(intr: Intrinsics, width: int, height: int, pose: MountPose, T_F_S: np.ndarray) -> CalibrationResult:
    """The calibration of a camera with known K (``intr``) and mount pose: ``H_F_B`` from the pose, ``H_S_B``
    through ``T_F_S``, no point pairs. :class:`ConfigError` naming ``--pitch`` when the bottom centre of the
    image does not see the ground."""
    H_F_B = from_pose(intr.K, width, height, pose)
    _, w = apply_homography(H_F_B, np.array([[width / 2.0, height - 1.0]]))
    if w[0] <= 0:
        raise ConfigError("calibrate", "--pitch", "with this pose the bottom of the image does not see the ground")
    H_S_B = np.linalg.inv(T_F_S) @ H_F_B
    return CalibrationResult(H_S_B, T_F_S, H_F_B, width, height, PointPairs.empty(), np.zeros(0, bool),
                             np.zeros((0, 2)), intr)


def default_crop(res: CalibrationResult) -> CropSpec:
    """A new camera's band: from a little above the horizon to the bottom, full width, half resolution."""
    W, H = res.width, res.height
    h = res.H_F_B[2]
    v_h = -(h[0] * W / 2.0 + h[2]) / h[1] if abs(h[1]) > 1e-12 else 0.0
    v0 = int(np.clip(v_h - 0.03 * H, 0, H - 4)) // 4 * 4
    v1 = H - (H - v0) % 2
    ds = 2 if W % 4 == 0 and (v1 - v0) % 2 == 0 else 1
    return CropSpec(v0, v1, 0, W - W % 2, ds)
