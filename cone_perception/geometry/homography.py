"""Image -> ground mapping: homography, foot points, horizon and range cuts,
position covariance.

``H_F_B`` maps full-image (undistorted) pixels ``B`` to the vehicle frame ``F``:
``[x, y, w]^T = H_F_B @ [u, v, 1]^T``, position ``(x / w, y / w)`` in metres.
After :func:`fix_homography_sign` every ground pixel has ``w > 0`` and pixels
with ``w <= 0`` lie on the sky side of the horizon.
"""

from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from ..classes import NUM_CLASSES

FOOT_RULES = ("bottom_left", "bottom_right", "bottom_center")
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)
_FOOT_U_WEIGHT = {"bottom_left": 0.0, "bottom_right": 1.0, "bottom_center": 0.5}


def fix_homography_sign(H: np.ndarray, ground_px: Sequence[float]) -> np.ndarray:
    """Return ``H`` scaled by +-1/|h33| so that ``w > 0`` at a known ground pixel.

    A homography is defined up to scale, sign included; ``cv2.findHomography``
    sets h33 = 1, which may leave every ground pixel with ``w < 0``.
    Raises ``ValueError`` if ``w`` is zero at that pixel.
    """
    H = np.asarray(H, dtype=np.float64)
    scale = abs(H[2, 2]) if abs(H[2, 2]) > 1e-12 else np.abs(H).max()
    H = H / scale
    w = H[2] @ np.array([ground_px[0], ground_px[1], 1.0])
    if abs(w) < 1e-12:
        raise ValueError(f"homography has w = 0 at the reference ground pixel {tuple(ground_px)}")
    return H if w > 0 else -H


def apply_homography(H: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) pixels -> ((N, 2) dehomogenised points, (N,) w). Points with w == 0 get inf."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    p = uv @ H[:, :2].T + H[:, 2]
    w = p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = p[:, :2] / w[:, None]
    return xy, w


def homography_jacobian(H: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Analytic Jacobian d(x, y)/d(u, v) of the homography at each pixel: (N, 2, 2)."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    p = uv @ H[:, :2].T + H[:, 2]
    w = p[:, 2]
    J = np.empty((uv.shape[0], 2, 2))
    for i in range(2):  # output x, y
        for j in range(2):  # input u, v
            J[:, i, j] = (H[i, j] * w - p[:, i] * H[2, j]) / (w * w)
    return J


def undistort_pixels(uv_px: np.ndarray, camera_matrix: np.ndarray, dist_coeffs: np.ndarray) -> np.ndarray:
    """(N, 2) raw pixels -> (N, 2) undistorted pixels of the same K (points only, never the image).

    Uses ``cv2.undistortPointsIter`` with 40 iterations: the default 5 of
    ``cv2.undistortPoints`` leave errors of several pixels in the corners of a
    wide-angle lens (k1 = -0.3: 12 px).
    """
    uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 2)
    if uv.shape[0] == 0:
        return uv
    K = np.asarray(camera_matrix, dtype=np.float64)
    d = np.asarray(dist_coeffs, dtype=np.float64)
    return cv2.undistortPointsIter(uv.reshape(-1, 1, 2), K, d, None, K, _UNDISTORT_CRITERIA).reshape(-1, 2)


def distort_pixels(uv_px: np.ndarray, camera_matrix: np.ndarray, dist_coeffs: np.ndarray) -> np.ndarray:
    """(N, 2) undistorted pixels -> (N, 2) raw pixels (inverse of :func:`undistort_pixels`)."""
    uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 2)
    if uv.shape[0] == 0:
        return uv
    K = np.asarray(camera_matrix, dtype=np.float64)
    rays = np.column_stack([(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1], np.ones(len(uv))])
    rays[:, 0] -= K[0, 1] / K[0, 0] * rays[:, 1]  # skew, usually 0
    pts, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, np.asarray(dist_coeffs, dtype=np.float64))
    return pts.reshape(-1, 2)


def foot_point_weights(rules: Sequence[str]) -> np.ndarray:
    """Per-class weight of u2 in the foot point ``u = (1 - a) u1 + a u2`` (0 left, 1 right, .5 centre)."""
    if len(rules) != NUM_CLASSES:
        raise ValueError(f"need a foot-point rule for each of {NUM_CLASSES} classes, got {len(rules)}")
    return np.array([_FOOT_U_WEIGHT[r] for r in rules], dtype=np.float64)


def foot_points(boxes_px: np.ndarray, class_ids: np.ndarray, u_weights: np.ndarray) -> np.ndarray:
    """(N, 4) boxes ``u1 v1 u2 v2`` + (N,) class ids -> (N, 2) foot pixels ``(u, v2)``."""
    b = np.asarray(boxes_px, dtype=np.float64).reshape(-1, 4)
    a = u_weights[np.asarray(class_ids, dtype=np.intp)]
    u = (1.0 - a) * b[:, 0] + a * b[:, 2]
    return np.column_stack([u, b[:, 3]])


class GroundMapper:
    """Maps full-image pixels to ``rear_axle`` ground positions with uncertainty.

    Parameters
    ----------
    H_F_B : 3x3, sign already fixed (w > 0 on the ground).
    max_range_m : points farther than this from the rear axle are dropped.
    pixel_sigma_px : (sigma_u, sigma_v), 1-sigma foot-point error in pixels.
    camera_matrix, dist_coeffs : optional lens model; when given, pixels are
        undistorted (``cv2.undistortPoints``, foot points only) before H.
    """

    def __init__(
        self,
        H_F_B: np.ndarray,
        max_range_m: float,
        pixel_sigma_px: tuple[float, float] = (1.0, 1.0),
        camera_matrix: np.ndarray | None = None,
        dist_coeffs: np.ndarray | None = None,
    ):
        self.H = np.asarray(H_F_B, dtype=np.float64)
        self.max_range_m = float(max_range_m)
        self.sigma = np.asarray(pixel_sigma_px, dtype=np.float64)
        self.K = None if camera_matrix is None else np.asarray(camera_matrix, dtype=np.float64)
        self.dist = None if dist_coeffs is None else np.asarray(dist_coeffs, dtype=np.float64).ravel()
        if self.dist is not None and not np.any(self.dist):
            self.dist = None

    def undistort(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) raw pixels -> (N, 2) undistorted pixels (identity without a lens model)."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        if self.dist is None or self.K is None:
            return uv
        return undistort_pixels(uv, self.K, self.dist)

    def map_pixels(self, uv_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) full-image px -> ((N, 2) x, y in m, (N,) bool valid).

        Invalid (sky side of the horizon or beyond ``max_range_m``) rows are NaN.
        """
        xy, w = apply_homography(self.H, self.undistort(uv_px))
        with np.errstate(invalid="ignore"):
            valid = (w > 0) & np.all(np.isfinite(xy), axis=1) & (np.hypot(xy[:, 0], xy[:, 1]) <= self.max_range_m)
        xy[~valid] = np.nan
        return xy, valid

    def ground_to_pixels(self, xy_m: np.ndarray) -> np.ndarray:
        """(N, 2) ground points (m, ``rear_axle``) -> (N, 2) raw full-image px (lens model applied;
        NaN behind the camera). The inverse of :meth:`map_pixels`."""
        uv, w = apply_homography(np.linalg.inv(self.H), np.asarray(xy_m, dtype=np.float64).reshape(-1, 2))
        uv[w <= 0] = np.nan
        if self.dist is not None and self.K is not None and uv.shape[0]:
            ok = np.all(np.isfinite(uv), axis=1)
            uv[ok] = distort_pixels(uv[ok], self.K, self.dist)
        return uv

    def jacobian(self, uv_px: np.ndarray) -> np.ndarray:
        """d(x, y)/d(u, v) at raw pixels, (N, 2, 2), including the lens model."""
        uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 2)
        J = homography_jacobian(self.H, self.undistort(uv))
        if self.dist is not None and uv.shape[0]:
            eps = 0.5  # px; undistortion is smooth on this scale
            Ju = np.empty((uv.shape[0], 2, 2))
            for j in range(2):
                d = np.zeros(2)
                d[j] = eps
                Ju[:, :, j] = (self.undistort(uv + d) - self.undistort(uv - d)) / (2 * eps)
            J = J @ Ju
        return J

    def covariance(self, uv_px: np.ndarray) -> np.ndarray:
        """(N, 2, 2) position covariance J diag(su^2, sv^2) J^T in m^2."""
        J = self.jacobian(uv_px)
        S = np.diag(self.sigma**2)
        return J @ S @ np.transpose(J, (0, 2, 1))


def covariance_ellipses(cones: np.ndarray, n_sigma: float = 2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ``n_sigma`` ellipse of each cone's position covariance (``CONE_DTYPE`` ``cov_xx cov_xy cov_yy``, m^2).

    Returns ((N,) major, (N,) minor full axis lengths in m (2 * n_sigma * sqrt(eigenvalue)),
    (N,) yaw of the major axis from +x towards +y, rad).
    """
    cov = np.empty((len(cones), 2, 2))
    cov[:, 0, 0] = cones["cov_xx"]
    cov[:, 0, 1] = cov[:, 1, 0] = cones["cov_xy"]
    cov[:, 1, 1] = cones["cov_yy"]
    vals, vecs = np.linalg.eigh(cov)  # ascending: [:, 1] is the major axis
    vals = np.clip(vals, 0.0, None)
    major, minor = 2 * n_sigma * np.sqrt(vals[:, 1]), 2 * n_sigma * np.sqrt(vals[:, 0])
    yaw = np.arctan2(vecs[:, 1, 1], vecs[:, 0, 1])
    return major, minor, yaw
