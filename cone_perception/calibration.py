"""Camera calibration to the rear axle: point pairs -> ``H_S_B`` -> ``H_F_B``, quality report,
mount pose <-> homography, lens intrinsics from chessboard views.

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

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np
import yaml

from .camera import MountPose, PinholeCamera
from .errors import ConfigError
from .geometry import GroundMapper, apply_homography, distort_pixels, fix_homography_sign, undistort_pixels

REPORT_DISTANCES_M = (5.0, 10.0, 15.0, 20.0)
DEFAULT_RANSAC_PX = 3.0
_SB_FLAGS = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY


def planar_transform(x_m: float = 0.0, y_m: float = 0.0, yaw_deg: float = 0.0) -> np.ndarray:
    """3x3 planar rigid transform: rotate by ``yaw_deg`` (counter-clockwise) then shift by (x_m, y_m)."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    return np.array([[c, -s, x_m], [s, c, y_m], [0.0, 0.0, 1.0]], dtype=np.float64) + 0.0  # no -0.0 in files


# -- point pairs ---------------------------------------------------------------------------------
@dataclass
class PointPairs:
    """Image/ground correspondences.

    ``uv_px``: (N, 2) float64 raw full-image px (as seen in the image);
    ``xy_S``: (N, 2) float64 m in frame S; ``labels``: N names (``board r0c3``,
    ``points.csv:7``); ``is_board``: (N,) bool.
    """

    uv_px: np.ndarray
    xy_S: np.ndarray
    labels: list[str]
    is_board: np.ndarray

    @classmethod
    def empty(cls) -> "PointPairs":
        return cls(np.zeros((0, 2)), np.zeros((0, 2)), [], np.zeros(0, dtype=bool))

    def __len__(self) -> int:
        return len(self.labels)

    def __add__(self, other: "PointPairs") -> "PointPairs":
        return PointPairs(
            np.vstack([self.uv_px, other.uv_px]),
            np.vstack([self.xy_S, other.xy_S]),
            self.labels + other.labels,
            np.concatenate([self.is_board, other.is_board]),
        )


def read_points_csv(path: str | Path) -> PointPairs:
    """Read extra pairs ``u,v,x_s,y_s`` (raw px, metres in S), one per line.

    Blank lines and lines starting with ``#`` are skipped, as is a first line
    of column names. Any other line that is not four finite numbers raises
    :class:`ConfigError` naming the file and the line.
    """
    path = Path(path)
    src = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise ConfigError(src, None, f"cannot read point file: {e.strerror}") from None
    uv, xy, labels = [], [], []
    for lineno, row in enumerate(csv.reader(text.splitlines()), start=1):
        cells = [c.strip() for c in row]
        if not cells or not any(cells) or cells[0].startswith("#"):
            continue
        if lineno == 1 and cells and not _is_number(cells[0]):
            continue  # header
        if len(cells) != 4:
            raise ConfigError(
                src, f"line {lineno}", f"needs 4 values u,v,x_s,y_s, got {len(cells)}: {','.join(cells)!r}"
            )
        try:
            vals = [float(c) for c in cells]
        except ValueError:
            raise ConfigError(
                src, f"line {lineno}", f"values must be numbers u,v,x_s,y_s, got {','.join(cells)!r}"
            ) from None
        if not all(math.isfinite(v) for v in vals):
            raise ConfigError(src, f"line {lineno}", f"values must be finite, got {','.join(cells)!r}")
        uv.append(vals[:2])
        xy.append(vals[2:])
        labels.append(f"{path.name}:{lineno}")
    if not labels:
        raise ConfigError(src, None, "point file has no point lines (u,v,x_s,y_s)")
    return PointPairs(
        np.array(uv, dtype=np.float64), np.array(xy, dtype=np.float64), labels, np.zeros(len(labels), bool)
    )


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


# -- chessboard ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Board:
    """A chessboard lying flat on the ground.

    ``cols`` x ``rows`` inner corners, squares of ``square_m``. Its pose in S:
    the centre of the inner-corner grid at (``x_m``, ``y_m``), its grid lines
    at ``yaw_deg`` to S's axes. Which way round the board lies is found from
    the image (see :func:`board_pairs`), so only ``yaw_deg`` modulo 90 matters.
    """

    cols: int
    rows: int
    square_m: float
    x_m: float = 0.0
    y_m: float = 0.0
    yaw_deg: float = 0.0

    @property
    def size(self) -> tuple[int, int]:
        return (self.cols, self.rows)


def _gray(image: np.ndarray) -> np.ndarray:
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def detect_board(image: np.ndarray, size: tuple[int, int]) -> np.ndarray | None:
    """Inner corners of a ``size = (cols, rows)`` chessboard, (rows*cols, 2) float64 raw px, or None.

    ``cv2.findChessboardCornersSB`` (sector-based, sub-pixel accurate by
    construction, with ``CALIB_CB_ACCURACY``). Order: row-major in the
    detector's own orientation.
    """
    ok, corners = cv2.findChessboardCornersSB(_gray(image), size, flags=_SB_FLAGS)
    if not ok or corners is None:
        return None
    return corners.reshape(-1, 2).astype(np.float64)


def board_not_found_hint(image: np.ndarray, size: tuple[int, int]) -> tuple[str, np.ndarray | None]:
    """Why no board of ``size`` was found: try neighbouring sizes; return (hint text, corners found or None)."""
    c, r = size
    tried = []
    for cc, rr in [(c - 1, r), (c, r - 1), (c + 1, r), (c, r + 1), (c - 1, r - 1), (c - 2, r), (c, r - 2)]:
        if cc < 3 or rr < 3 or (cc, rr) in tried:
            continue
        tried.append((cc, rr))
        ok, corners = cv2.findChessboardCornersSB(_gray(image), (cc, rr))
        if ok:
            return (
                f"a {cc}x{rr} board was found instead: check --board (count INNER corners, "
                f"where four squares meet) or whether part of the board is hidden or out of the image",
                corners.reshape(-1, 2).astype(np.float64),
            )
    ok, corners = cv2.findChessboardCorners(_gray(image), size)
    partial = None if corners is None else corners.reshape(-1, 2).astype(np.float64)
    return (
        "no chessboard of this or a neighbouring size is visible: is the whole board in the image, "
        "lit evenly, without glare, with a white margin around it?",
        partial,
    )


def _grid_candidates(board: Board) -> list[np.ndarray]:
    """The 8 ways to assign board-local metres (x, y) to the detector's row-major corners."""
    i, j = np.divmod(np.arange(board.rows * board.cols), board.cols)
    a = (j - (board.cols - 1) / 2.0) * board.square_m
    b = (i - (board.rows - 1) / 2.0) * board.square_m
    out = []
    for p, q in ((a, b), (b, a)):
        for sp in (1.0, -1.0):
            for sq in (1.0, -1.0):
                out.append(np.column_stack([sp * p, sq * q]))
    return out


def board_pairs(corners_px: np.ndarray, board: Board, T_F_S: np.ndarray) -> PointPairs:
    """Detected corners -> pairs with S coordinates, the board's orientation resolved from the image.

    Of the 8 ways the corner order can map onto the board, the one is chosen in
    which, in the vehicle frame F, x grows up the image (away from the car) and
    y grows to the left, as for any forward-looking camera. The board should be
    laid square to the car (within about 30 degrees).
    """
    uv = np.asarray(corners_px, dtype=np.float64).reshape(-1, 2)
    T_S_board = planar_transform(board.x_m, board.y_m, board.yaw_deg)
    T = T_F_S @ T_S_board
    best, best_score = None, -np.inf
    for local in _grid_candidates(board):
        xy_F = local @ T[:2, :2].T + T[:2, 2]
        score = _corr(xy_F[:, 0], -uv[:, 1]) + _corr(xy_F[:, 1], -uv[:, 0])
        if score > best_score:
            best, best_score = local, score
    xy_S = best @ T_S_board[:2, :2].T + T_S_board[:2, 2]
    i, j = np.divmod(np.arange(len(uv)), board.cols)
    labels = [f"board r{a}c{b}" for a, b in zip(i, j)]
    return PointPairs(uv, xy_S, labels, np.ones(len(uv), dtype=bool))


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    a = a - a.mean()
    b = b - b.mean()
    d = math.sqrt(float(a @ a) * float(b @ b))
    return float(a @ b) / d if d > 0 else 0.0


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
    roll in the convention of :class:`~cone_perception.camera.MountPose`.
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


# -- quality report ------------------------------------------------------------------------------
def quality_report(res: CalibrationResult, far_m: float = 10.0, max_range_m: float = 30.0) -> dict:
    """Numbers a person needs to accept a calibration (plain dict, JSON-able).

    Per point: raw pixel, true position in F, reprojection error (px, raw
    image) and ground error (m, in F), inlier flag. RMS over inliers. Coverage
    of the usable image (below the horizon, within ``max_range_m``) by the
    points' convex hull, and of the left / right edges and the far field
    (warnings when missing). Predicted ground error for a 1-px error at
    :data:`REPORT_DISTANCES_M` ahead. Pose from H when K is known.
    """
    W, Hh = res.width, res.height
    rep: dict = {"image_size": [W, Hh]}
    warnings = list(res.warnings)
    if len(res.pairs):
        _point_stats(res, rep, warnings, far_m, max_range_m)
    # predicted ground error for a one-pixel error, straight ahead
    K = None if res.intrinsics is None else res.intrinsics.K
    dist = None if res.intrinsics is None else res.intrinsics.dist
    gm = GroundMapper(res.H_F_B, 1e9, (1.0, 1.0), K, dist)
    pred = []
    for d in REPORT_DISTANCES_M:
        px, ok = res.ground_to_raw_px(np.array([[d, 0.0]]))
        row: dict = {"x_m": d, "u_px": None, "v_px": None, "m_per_px_v": None, "m_per_px_u": None, "in_image": False}
        if ok[0] and 0 <= px[0, 0] < W and 0 <= px[0, 1] < Hh:
            J = gm.jacobian(px)[0]
            row.update(
                u_px=float(px[0, 0]),
                v_px=float(px[0, 1]),
                m_per_px_v=float(np.linalg.norm(J[:, 1])),
                m_per_px_u=float(np.linalg.norm(J[:, 0])),
                in_image=True,
            )
        pred.append(row)
    rep["one_px_error"] = pred

    if K is not None:
        est = pose_from_homography(res.H_F_B, K)
        p = est.pose
        rep["pose_from_H"] = {
            "x_m": p.x_m,
            "y_m": p.y_m,
            "height_m": p.height_m,
            "pitch_deg": p.pitch_deg,
            "roll_deg": p.roll_deg,
            "yaw_deg": p.yaw_deg,
            "column_ratio": est.column_ratio,
            "column_angle_deg": est.column_angle_deg,
        }
        if abs(est.column_ratio - 1.0) > 0.05 or abs(est.column_angle_deg - 90.0) > 3.0:
            warnings.append(
                f"K does not fit H (|r1|/|r2| = {est.column_ratio:.3f}, angle {est.column_angle_deg:.1f} deg; want 1 and 90): "
                "wrong intrinsics, a bent board, or points off the ground plane; the pose estimate is unreliable"
            )
    if res.intrinsics is not None:
        rep["intrinsics"] = {
            "source": res.intrinsics.source,
            "camera_matrix": res.intrinsics.K.tolist(),
            "dist_coeffs": res.intrinsics.dist.tolist(),
            "calibrate_camera_rms_px": res.intrinsics.rms_px,
        }
    rep["warnings"] = warnings
    return rep


def _point_stats(res: CalibrationResult, rep: dict, warnings: list[str], far_m: float, max_range_m: float) -> None:
    """Per-point errors, RMS and coverage (+ warnings) of a calibration from point pairs."""
    W, Hh = res.width, res.height
    xy_F = res.xy_F()
    proj_px, front = res.ground_to_raw_px(xy_F)
    reproj = np.linalg.norm(proj_px - res.pairs.uv_px, axis=1)
    reproj[~front] = np.inf
    mapped, w = apply_homography(res.H_F_B, res.uv_und_px)
    ground = np.linalg.norm(mapped - xy_F, axis=1)
    ground[w <= 0] = np.inf
    inl = res.inliers
    points = [
        {
            "label": res.pairs.labels[k],
            "u_px": float(res.pairs.uv_px[k, 0]),
            "v_px": float(res.pairs.uv_px[k, 1]),
            "x_m": float(xy_F[k, 0]),
            "y_m": float(xy_F[k, 1]),
            "reproj_px": float(reproj[k]),
            "ground_err_m": float(ground[k]),
            "inlier": bool(inl[k]),
        }
        for k in range(len(res.pairs))
    ]
    rep.update(
        {
            "n_points": len(res.pairs),
            "n_board": int(res.pairs.is_board.sum()),
            "n_extra": int((~res.pairs.is_board).sum()),
            "n_inliers": int(inl.sum()),
            "outliers": [res.pairs.labels[k] for k in np.flatnonzero(~inl)],
            "rms_reproj_px": float(np.sqrt(np.mean(reproj[inl] ** 2))),
            "max_reproj_px": float(reproj[inl].max()),
            "rms_ground_m": float(np.sqrt(np.mean(ground[inl] ** 2))),
            "max_ground_m": float(ground[inl].max()),
            "points": points,
        }
    )

    # coverage of the usable image: grid of raw pixels below the horizon and within range
    gu, gv = np.meshgrid(np.linspace(0, W - 1, 96), np.linspace(0, Hh - 1, 54))
    grid = np.column_stack([gu.ravel(), gv.ravel()])
    gxy, gw = apply_homography(res.H_F_B, res.undistort(grid))
    with np.errstate(invalid="ignore"):
        usable = (gw > 0) & (np.hypot(gxy[:, 0], gxy[:, 1]) <= max_range_m)
    pts = res.pairs.uv_px[inl].astype(np.float32)
    hull = cv2.convexHull(pts)
    inside = np.array([cv2.pointPolygonTest(hull, (float(a), float(b)), False) >= 0 for a, b in grid[usable]])
    cover = float(inside.mean()) if inside.size else 0.0
    u_in = res.pairs.uv_px[inl, 0]
    rep["coverage"] = {
        "usable_image_fraction": float(usable.mean()),
        "hull_fraction_of_usable": cover,
        "u_span_px": [float(u_in.min()), float(u_in.max())],
        "v_span_px": [float(res.pairs.uv_px[inl, 1].min()), float(res.pairs.uv_px[inl, 1].max())],
        "max_distance_m": float(np.hypot(xy_F[inl, 0], xy_F[inl, 1]).max()),
        "max_x_m": float(xy_F[inl, 0].max()),
    }
    if cover < 0.3:
        warnings.append(
            f"points cover only {100 * cover:.0f} % of the usable image (below the horizon, within {max_range_m:g} m): "
            "H is extrapolated elsewhere; add reference points (cones at measured spots, --points)"
        )
    if not np.any(u_in < 0.2 * W):
        warnings.append("no point in the LEFT fifth of the image: errors grow towards the left edge (thesis ch. 4.4)")
    if not np.any(u_in > 0.8 * W):
        warnings.append("no point in the RIGHT fifth of the image: errors grow towards the right edge (thesis ch. 4.4)")
    if rep["coverage"]["max_x_m"] < far_m:
        warnings.append(
            f"far field not covered: the farthest point is {rep['coverage']['max_x_m']:.1f} m ahead (< {far_m:g} m); "
            "far cones rely on extrapolation: add points at 10-20 m"
        )
    uv = res.pairs.uv_px
    outside = (uv[:, 0] < 0) | (uv[:, 0] > W - 1) | (uv[:, 1] < 0) | (uv[:, 1] > Hh - 1)
    if np.any(outside):
        names = [res.pairs.labels[k] for k in np.flatnonzero(outside)]
        warnings.append(f"{len(names)} point(s) lie outside the {W}x{Hh} image: {', '.join(names[:8])}")
    if rep["n_inliers"] < len(res.pairs):
        warnings.append(f"{len(rep['outliers'])} point(s) rejected as outliers: {', '.join(rep['outliers'][:8])}")


def format_report(rep: dict, title: str = "calibration report", max_points: int | None = None) -> str:
    """The report as text for ``<name>.report.txt`` (all points) and the terminal (``max_points`` worst)."""
    L = [title, "=" * len(title)]
    if "n_points" not in rep:
        L.append(
            f"no point pairs (homography from the mount pose); image {rep['image_size'][0]}x{rep['image_size'][1]}"
        )
    else:
        _format_points_summary(L, rep)
    L.append("")
    L.append("ground error for a 1-px error, straight ahead:")
    for r in rep["one_px_error"]:
        if r["in_image"]:
            L.append(
                f"  {r['x_m']:4.0f} m (pixel {r['u_px']:.0f},{r['v_px']:.0f}): 1 px up/down -> {100 * r['m_per_px_v']:.1f} cm, "
                f"1 px left/right -> {100 * r['m_per_px_u']:.1f} cm"
            )
        else:
            L.append(f"  {r['x_m']:4.0f} m: not in the image")
    if "pose_from_H" in rep:
        p = rep["pose_from_H"]
        L.append("")
        L.append(
            f"camera pose from H and K (sanity check): x {p['x_m']:.3f} m, y {p['y_m']:.3f} m, "
            f"height {p['height_m']:.3f} m, pitch {p['pitch_deg']:.2f} deg, roll {p['roll_deg']:.2f} deg, "
            f"yaw {p['yaw_deg']:.2f} deg (K fit: |r1|/|r2| {p['column_ratio']:.3f}, angle {p['column_angle_deg']:.1f} deg)"
        )
    if "intrinsics" in rep:
        i = rep["intrinsics"]
        rms = f", calibrateCamera RMS {i['calibrate_camera_rms_px']:.3f} px" if i["calibrate_camera_rms_px"] else ""
        L.append(f"intrinsics: {i['source']}{rms}; dist_coeffs {np.round(i['dist_coeffs'], 5).tolist()}")
    if rep.get("points"):
        _format_points_table(L, rep, max_points)
    L.append("")
    if rep["warnings"]:
        L.extend(f"WARNING: {w}" for w in rep["warnings"])
    else:
        L.append("no warnings")
    return "\n".join(L) + "\n"


def _format_points_table(L: list[str], rep: dict, max_points: int | None) -> None:
    points = rep["points"]
    L.append("")
    if max_points is not None and len(points) > max_points:
        points = sorted(points, key=lambda p: (p["inlier"], -p["reproj_px"]))[:max_points]
        L.append(f"the {max_points} worst of {len(rep['points'])} points (all in the .report.txt file):")
    L.append(f"{'point':<22}{'u px':>8}{'v px':>8}{'x m':>8}{'y m':>8}{'reproj px':>11}{'ground cm':>11}  inlier")
    for p in points:
        L.append(
            f"{p['label']:<22}{p['u_px']:8.1f}{p['v_px']:8.1f}{p['x_m']:8.3f}{p['y_m']:8.3f}"
            f"{p['reproj_px']:11.2f}{100 * p['ground_err_m']:11.2f}  {'yes' if p['inlier'] else 'NO'}"
        )


def _format_points_summary(L: list[str], rep: dict) -> None:
    L.append(
        f"points: {rep['n_points']} ({rep['n_board']} board corners, {rep['n_extra']} extra), "
        f"inliers {rep['n_inliers']}"
    )
    L.append(
        f"reprojection error (inliers): RMS {rep['rms_reproj_px']:.2f} px, max {rep['max_reproj_px']:.2f} px; "
        f"ground error: RMS {100 * rep['rms_ground_m']:.1f} cm, max {100 * rep['max_ground_m']:.1f} cm"
    )
    c = rep["coverage"]
    L.append(
        f"coverage: points span u {c['u_span_px'][0]:.0f}..{c['u_span_px'][1]:.0f} px, "
        f"v {c['v_span_px'][0]:.0f}..{c['v_span_px'][1]:.0f} px of {rep['image_size'][0]}x{rep['image_size'][1]}; "
        f"their hull covers {100 * c['hull_fraction_of_usable']:.0f} % of the usable image; "
        f"farthest point {c['max_x_m']:.1f} m ahead"
    )


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
