"""Pictures that prove a calibration: points + residuals + metric grid on the image, bird's-eye warp.

All drawing is on the RAW camera image: grid lines and reprojections go
through ``H_B_F`` and then the lens model, so with a good calibration the
1 m grid bends exactly like painted lines on the ground do. ROS-free.
"""

from __future__ import annotations

import cv2
import numpy as np

from .fit import CalibrationResult

GRID_BGR = (255, 220, 0)
AXIS_BGR = (0, 200, 255)
BOARD_BGR = (60, 220, 60)
EXTRA_BGR = (255, 60, 255)
OUTLIER_BGR = (40, 40, 255)
ARROW_BGR = (0, 255, 255)


def _font_scale(width: int) -> float:
    return max(0.45, 0.6 * width / 1920.0)


def _text(img: np.ndarray, s: str, org: tuple[int, int], scale: float, color=(255, 255, 255), thick: int = 1) -> None:
    """Text with a dark outline, legible on any background."""
    org = (int(org[0]), int(org[1]))
    cv2.putText(img, s, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), thick + 3, cv2.LINE_AA)
    cv2.putText(img, s, org, cv2.FONT_HERSHEY_SIMPLEX, scale, color, thick, cv2.LINE_AA)


def _with_header(img: np.ndarray, lines: list[tuple[str, tuple[int, int, int]]], scale: float) -> np.ndarray:
    """A dark band with the legend lines on top of the picture (nothing of the picture is covered)."""
    h = int(round(30 * scale / 0.6))
    band = np.full((h * len(lines) + 10, img.shape[1], 3), 32, np.uint8)
    for k, (s, c) in enumerate(lines):
        _text(band, s, (10, h * (k + 1) - int(h * 0.2)), scale, c)
    return np.vstack([band, img])


def _polyline_raw(img: np.ndarray, res: CalibrationResult, xy_F: np.ndarray, color, thick: int) -> np.ndarray:
    """Draw a ground polyline (m in F) on the raw image; returns its (N, 2) raw px (NaN where not visible)."""
    H, W = img.shape[:2]
    px, front = res.ground_to_raw_px(xy_F)
    ok = front & np.all(np.isfinite(px), axis=1)
    ok &= (px[:, 0] > -W) & (px[:, 0] < 2 * W) & (px[:, 1] > -H) & (px[:, 1] < 2 * H)
    px[~ok] = np.nan
    start = None
    for k in range(len(px) + 1):
        good = k < len(px) and ok[k]
        if good and start is None:
            start = k
        if not good and start is not None:
            if k - start >= 2:
                pts = np.round(px[start:k] * 4).astype(np.int32)  # 2 fractional bits
                cv2.polylines(img, [pts.reshape(-1, 1, 2)], False, color, thick, cv2.LINE_AA, shift=2)
            start = None
    return px


def draw_grid(img: np.ndarray, res: CalibrationResult, max_x_m: float = 25.0, half_width_m: float = 10.0) -> None:
    """1 m grid of ``rear_axle`` (x forward, y left) through the inverse homography, labelled in metres.

    Lines closer than a few pixels near the horizon are thinned out to every
    5 m so the picture stays readable.
    """
    H, W = img.shape[:2]
    scale = _font_scale(W)
    thick = max(1, round(W / 1920))
    ys = np.linspace(-half_width_m, half_width_m, 400)
    # the visible x range: from the nearest ground row at the bottom of the image
    last_v = None
    x_lines = []
    for x in np.arange(0.0, max_x_m + 1e-9, 1.0):
        px, front = res.ground_to_raw_px(np.array([[x, 0.0]]))
        if not front[0] or not np.all(np.isfinite(px)) or px[0, 1] > 1.5 * H:
            continue
        v = float(px[0, 1])
        gap = np.inf if last_v is None else last_v - v
        major = abs(x % 5) < 1e-9
        if gap >= 8 or (major and gap >= 3):
            x_lines.append((x, v, gap))
            last_v = v
    for x, v, gap in x_lines:
        major = abs(x % 5) < 1e-9
        _polyline_raw(img, res, np.column_stack([np.full_like(ys, x), ys]), GRID_BGR, thick * (2 if major else 1))
        if 0 <= v < H - 30 * scale and (gap >= 22 * scale / 0.6 or (major and gap >= 8)):
            px, _ = res.ground_to_raw_px(np.array([[x, 0.0]]))
            _text(img, f"{x:g} m", (px[0, 0] + 6, px[0, 1] - 3), scale * 0.85, GRID_BGR)
    x_max_drawn = x_lines[-1][0] if x_lines else max_x_m
    x_min_drawn = x_lines[0][0] if x_lines else 0.0
    xs = np.linspace(x_min_drawn, x_max_drawn, 600)
    placed: list[tuple[float, float]] = []
    for y in np.arange(-half_width_m, half_width_m + 1e-9, 1.0):
        color = AXIS_BGR if abs(y) < 1e-9 else GRID_BGR
        px = _polyline_raw(
            img, res, np.column_stack([xs, np.full_like(xs, y)]), color, thick * (2 if abs(y) < 1e-9 else 1)
        )
        vis = np.flatnonzero(
            np.isfinite(px[:, 0]) & (px[:, 0] >= 0) & (px[:, 0] < W) & (px[:, 1] >= 0) & (px[:, 1] < H)
        )
        if vis.size:
            u, v = px[vis[np.argmax(px[vis, 1])]]  # lowest visible point of the line: label there
            if any(abs(u - a) < 60 * scale and abs(v - b) < 24 * scale for a, b in placed):
                continue  # would overlap a label already drawn
            placed.append((u, v))
            label = f"y {y:+g}" if abs(y) > 1e-9 else "y 0"
            tw = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, scale * 0.8, 1)[0][0]
            _text(img, label, (min(u + 4, W - tw - 6), min(v - 6, H - 8)), scale * 0.8, color)


def points_picture(
    image_bgr: np.ndarray,
    res: CalibrationResult,
    report: dict | None = None,
    arrow_scale: float = 20.0,
    max_x_m: float = 25.0,
) -> np.ndarray:
    """The calibration image with the 1 m grid, the points, and their residuals (arrows x ``arrow_scale``).

    Green circles: board corners; magenta: extra points; red crosses: rejected
    outliers; yellow arrows: from the measured pixel to where H puts the
    point's true ground position, magnified ``arrow_scale`` times.
    """
    img = image_bgr.copy() if image_bgr.ndim == 3 else cv2.cvtColor(image_bgr, cv2.COLOR_GRAY2BGR)
    H, W = img.shape[:2]
    scale = _font_scale(W)
    r = max(3, round(4 * W / 1920))
    draw_grid(img, res, max_x_m)
    if len(res.pairs):
        proj, front = res.ground_to_raw_px(res.xy_F())
        for k in range(len(res.pairs)):
            u, v = res.pairs.uv_px[k]
            p = (int(round(u)), int(round(v)))
            if not res.inliers[k]:
                cv2.drawMarker(img, p, OUTLIER_BGR, cv2.MARKER_TILTED_CROSS, 4 * r, 2, cv2.LINE_AA)
                _text(img, res.pairs.labels[k], (p[0] + 2 * r, p[1] - 2 * r), scale * 0.7, OUTLIER_BGR)
                continue
            color = BOARD_BGR if res.pairs.is_board[k] else EXTRA_BGR
            cv2.circle(
                img, p, r if res.pairs.is_board[k] else 2 * r, color, 1 if res.pairs.is_board[k] else 2, cv2.LINE_AA
            )
            if front[k] and np.all(np.isfinite(proj[k])):
                tip = res.pairs.uv_px[k] + arrow_scale * (proj[k] - res.pairs.uv_px[k])
                cv2.arrowedLine(
                    img, p, (int(round(tip[0])), int(round(tip[1]))), ARROW_BGR, 1, cv2.LINE_AA, tipLength=0.3
                )
            if not res.pairs.is_board[k]:
                _text(img, res.pairs.labels[k], (p[0] + 2 * r, p[1] - 2 * r), scale * 0.7, EXTRA_BGR)
    lines = [("cyan: 1 m grid of rear_axle (x forward, y left)", GRID_BGR), ("orange: y = 0", AXIS_BGR)]
    if len(res.pairs):
        kinds = [("green circles: board corners", BOARD_BGR, res.pairs.is_board),
                 ("magenta circles: extra points", EXTRA_BGR, ~res.pairs.is_board),
                 ("red x: outliers", OUTLIER_BGR, ~res.inliers)]
        lines += [(text, color) for text, color, mask in kinds if np.any(mask)]
        lines.append((f"yellow arrows: residual x{arrow_scale:g} (measured -> where H puts the true point)", ARROW_BGR))
    if report is not None and "rms_reproj_px" in report:
        lines.append(
            (
                f"RMS {report['rms_reproj_px']:.2f} px / {100 * report['rms_ground_m']:.1f} cm over "
                f"{report['n_inliers']} of {report['n_points']} points; {len(report['warnings'])} warning(s)",
                (255, 255, 255),
            )
        )
    return _with_header(img, lines, scale)


def birdseye_picture(
    image_bgr: np.ndarray,
    res: CalibrationResult,
    x_range_m: tuple[float, float] = (0.0, 25.0),
    half_width_m: float = 10.0,
    px_per_m: float = 30.0,
) -> np.ndarray:
    """Top view of the ground (x up, y left) resampled from the raw image, with a labelled 1 m grid.

    Every output pixel is a ground point in F, mapped through ``H_B_F`` and
    the lens model into the raw image (one resampling). Ground points behind
    the camera or outside the image stay black. The calibration points are
    drawn at their TRUE positions: on a good calibration they sit on the
    corners they were measured at.
    """
    x0, x1 = x_range_m
    ow, oh = int(round(2 * half_width_m * px_per_m)), int(round((x1 - x0) * px_per_m))
    c, r = np.meshgrid(np.arange(ow, dtype=np.float64), np.arange(oh, dtype=np.float64))
    xy = np.column_stack([(x1 - r.ravel() / px_per_m), (half_width_m - c.ravel() / px_per_m)])
    px, front = res.ground_to_raw_px(xy)
    px[~front] = -1e6
    mx = px[:, 0].reshape(oh, ow).astype(np.float32)
    my = px[:, 1].reshape(oh, ow).astype(np.float32)
    src = image_bgr if image_bgr.ndim == 3 else cv2.cvtColor(image_bgr, cv2.COLOR_GRAY2BGR)
    out = cv2.remap(src, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0))

    def to_out(x: float, y: float) -> tuple[int, int]:
        return int(round((half_width_m - y) * px_per_m)), int(round((x1 - x) * px_per_m))

    scale = 0.45
    for x in np.arange(np.ceil(x0), x1 + 1e-9, 1.0):
        major = abs(x % 5) < 1e-9
        cv2.line(out, to_out(x, half_width_m), to_out(x, -half_width_m), GRID_BGR, 2 if major else 1, cv2.LINE_AA)
        _text(out, f"{x:g}", (3, to_out(x, 0)[1] - 3), scale, GRID_BGR)
    for y in np.arange(-half_width_m, half_width_m + 1e-9, 1.0):
        color = AXIS_BGR if abs(y) < 1e-9 else GRID_BGR
        cv2.line(out, to_out(x1, y), to_out(x0, y), color, 2 if abs(y) < 1e-9 or abs(y % 5) < 1e-9 else 1, cv2.LINE_AA)
        if abs(y % 2) < 1e-9:
            _text(out, f"{y:+g}" if y else "0", (to_out(x0, y)[0] + 2, oh - 6), scale, color)
    if len(res.pairs):
        for k, (x, y) in enumerate(res.xy_F()):
            color = OUTLIER_BGR if not res.inliers[k] else (BOARD_BGR if res.pairs.is_board[k] else EXTRA_BGR)
            cv2.circle(out, to_out(x, y), 3 if res.pairs.is_board[k] else 5, color, 1, cv2.LINE_AA)
    lines = [
        (f"bird's-eye view of rear_axle, {x0:g}..{x1:g} m ahead", (255, 255, 255)),
        ("cyan: 1 m grid, x (m) at the left, y (m, + = left) at the bottom", GRID_BGR),
        ("orange: y = 0 (straight ahead of the rear axle)", AXIS_BGR),
    ]
    if len(res.pairs):
        lines.append(("circles: calibration points at their true positions:", (255, 255, 255)))
        kinds = [("green = board corners", BOARD_BGR, res.pairs.is_board & res.inliers),
                 ("magenta = extra points", EXTRA_BGR, ~res.pairs.is_board & res.inliers),
                 ("red = outliers", OUTLIER_BGR, ~res.inliers)]
        lines += [(f"  {text}", color) for text, color, mask in kinds if np.any(mask)]
    return _with_header(out, lines, scale)


def not_found_picture(
    image_bgr: np.ndarray, corners_px: np.ndarray | None, size: tuple[int, int], hint: str
) -> np.ndarray:
    """The image with whatever corners were found (red) and the reason the board was not accepted."""
    img = image_bgr.copy() if image_bgr.ndim == 3 else cv2.cvtColor(image_bgr, cv2.COLOR_GRAY2BGR)
    scale = _font_scale(img.shape[1])
    if corners_px is not None and len(corners_px):
        for u, v in corners_px:
            cv2.drawMarker(img, (int(round(u)), int(round(v))), OUTLIER_BGR, cv2.MARKER_CROSS, 10, 2)
    found = 0 if corners_px is None else len(corners_px)
    lines = [
        (f"NO {size[0]}x{size[1]} chessboard (inner corners) found", OUTLIER_BGR),
        (f"red crosses: {found} corner(s) a detector did find", (255, 255, 255)),
    ] + [(s.strip(), (255, 255, 255)) for s in hint.split(":", 1)]
    return _with_header(img, lines, scale)
