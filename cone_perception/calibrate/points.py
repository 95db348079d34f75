"""Calibration inputs: point pairs (ground metres <-> image pixels) from a CSV file or a chessboard
on the ground, and the planar transform of the set-up's ground frame S to ``rear_axle``. ROS-free."""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import ConfigError

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
