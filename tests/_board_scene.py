"""Test helper: a chessboard (or any texture) lying on the ground, rendered through a known camera.

The ideal (pinhole) image is ``cv2.warpPerspective`` of the board texture with
the exact ground -> image homography ``PinholeCamera.H_B_F() @ T_F_board @ A``;
with lens distortion the ideal image is resampled at the undistorted position
of every raw pixel (``geometry.undistort_pixels``), so the corners sit where the
lens model puts them.
"""

from __future__ import annotations

import cv2
import numpy as np

from cone_perception.calibrate import planar_transform
from cone_perception.geometry import undistort_pixels
from cone_perception.geometry.camera import PinholeCamera


def board_texture(cols: int, rows: int, px_per_square: int, margin_squares: int = 1) -> np.ndarray:
    """Grey-level chessboard with ``cols`` x ``rows`` inner corners and a white margin."""
    s = px_per_square
    n_u, n_v = cols + 1 + 2 * margin_squares, rows + 1 + 2 * margin_squares
    tex = np.full((n_v * s, n_u * s), 245, np.uint8)
    for i in range(rows + 1):
        for j in range(cols + 1):
            if (i + j) % 2 == 0:
                v0, u0 = (i + margin_squares) * s, (j + margin_squares) * s
                tex[v0 : v0 + s, u0 : u0 + s] = 15
    return tex


def texture_to_local(tex_shape: tuple[int, int], m_per_px: float) -> np.ndarray:
    """3x3: texture px (pixel centres at integers) -> board-local metres, origin at the texture centre."""
    th, tw = tex_shape
    return np.array([[m_per_px, 0, (0.5 - tw / 2) * m_per_px], [0, m_per_px, (0.5 - th / 2) * m_per_px], [0, 0, 1.0]])


def distortion_maps(cam: PinholeCamera) -> tuple[np.ndarray, np.ndarray] | None:
    """remap() maps: for each raw pixel, where it lies in the ideal image (None without distortion)."""
    if not cam.dist_coeffs.size:
        return None
    u, v = np.meshgrid(np.arange(cam.width, dtype=np.float64), np.arange(cam.height, dtype=np.float64))
    und = undistort_pixels(np.column_stack([u.ravel(), v.ravel()]), cam.K, cam.dist_coeffs)
    return (
        und[:, 0].reshape(cam.height, cam.width).astype(np.float32),
        und[:, 1].reshape(cam.height, cam.width).astype(np.float32),
    )


def render_on_ground(
    cam: PinholeCamera,
    texture: np.ndarray,
    m_per_px: float,
    board_x_m: float,
    board_y_m: float = 0.0,
    board_yaw_deg: float = 0.0,
    background: int = 100,
    maps: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """(H, W, 3) uint8 BGR raw camera image of ``texture`` lying centred at (x, y, yaw) in rear_axle."""
    T_F_local = planar_transform(board_x_m, board_y_m, board_yaw_deg)
    Hw = cam.H_B_F() @ T_F_local @ texture_to_local(texture.shape, m_per_px)
    size = (cam.width, cam.height)
    img = cv2.warpPerspective(texture, Hw, size, flags=cv2.INTER_AREA, borderValue=background)
    if maps is None and cam.dist_coeffs.size:
        maps = distortion_maps(cam)
    if maps is not None:
        img = cv2.remap(img, maps[0], maps[1], cv2.INTER_LINEAR, borderValue=background)
    # horizon and sky: nothing of the ground plane above the horizon
    v_h = cam.horizon_v()
    if np.isfinite(v_h) and v_h > 0:
        img[: int(min(v_h, cam.height))] = 200
    return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)


def render_views(cam: PinholeCamera, cols: int, rows: int, square_m: float, seed: int = 3) -> list[np.ndarray]:
    """Six grey views of a chessboard held tilted at different places in front of ``cam`` (lens applied)."""
    maps = distortion_maps(cam)
    tex = board_texture(cols, rows, 30)
    A = texture_to_local(tex.shape, square_m / 30)
    rng = np.random.default_rng(seed)
    views = []
    for tx, ty, tz in [
        (0, 0, 0.9),
        (-0.25, -0.12, 1.0),
        (0.25, 0.12, 1.0),
        (0.22, -0.14, 0.8),
        (-0.22, 0.14, 0.8),
        (0.0, 0.15, 1.1),
    ]:
        R, _ = cv2.Rodrigues(rng.normal(0, 0.35, 3))
        Hv = cam.K @ np.column_stack([R[:, 0], R[:, 1], [tx, ty, tz]]) @ A
        img = cv2.warpPerspective(tex, Hv, (cam.width, cam.height), flags=cv2.INTER_LINEAR, borderValue=120)
        if maps is not None:
            img = cv2.remap(img, maps[0], maps[1], cv2.INTER_LINEAR, borderValue=120)
        views.append(img)
    return views


def write_example(out_dir: str) -> None:
    """The example inputs of docs/calibration.md: the synthetic main-hoop camera (1920x1080, 90 deg, 1.2 m, pitch 10 deg)
    seeing a 9x6 x 0.2 m board 4 m ahead of the rear axle, plus 8 cones at measured spots (exact pixels);
    the same with a wide-angle lens (``*_wide``) and its ``lens.yaml``."""
    from pathlib import Path

    import yaml

    from cone_perception.geometry.camera import MountPose, default_intrinsics

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cones = np.array([[x, y] for x in (7.0, 10.0, 13.0) for y in (-3.0, 3.0)] + [[5.0, -4.5], [5.0, 4.5]])
    dist = np.array([-0.25, 0.07, 0.0005, -0.0003, -0.01])
    for suffix, d in (("", np.zeros(0)), ("_wide", dist)):
        cam = PinholeCamera(default_intrinsics(1920, 1080, 90.0), 1920, 1080, MountPose(), d)
        cv2.imwrite(str(out / f"board{suffix}.png"), render_on_ground(cam, board_texture(9, 6, 40), 0.2 / 40, 4.0))
        uv, _ = cam.project(np.column_stack([cones, np.zeros(len(cones))]))
        rows = [f"{u:.2f},{v:.2f},{x - 4.0:.3f},{y:.3f}" for (u, v), (x, y) in zip(uv, cones)]
        (out / f"cones{suffix}.csv").write_text("u,v,x_s,y_s\n" + "\n".join(rows) + "\n")
    (out / "lens.yaml").write_text(yaml.safe_dump({"camera_matrix": cam.K.tolist(), "dist_coeffs": dist.tolist()}))


if __name__ == "__main__":
    import sys

    write_example(sys.argv[1] if len(sys.argv) > 1 else "calib_example")
