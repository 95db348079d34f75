"""The look of a track (one per track or video): ground textures, the 360-degree background band at the
horizon, the car nose, lighting; and the renderer's switches (:class:`RenderOptions`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..classes import BLUE, LARGE_ORANGE, ORANGE, UNKNOWN, YELLOW
from ..geometry.camera import PinholeCamera

# Base paint colours, BGR 0..255, jittered per look.
_PAINT = {BLUE: (205, 110, 20), YELLOW: (25, 200, 240), ORANGE: (20, 105, 245), LARGE_ORANGE: (25, 95, 240), UNKNOWN: (120, 120, 120)}


#: ``RenderOptions.paint_lines`` values: the ground's painted lines drawn at random, or in every look in this colour
#: (hard negatives for the detector: yellow paint is what rendered drives' boxes on no cone stand on)
PAINT_LINES: tuple[str, ...] = ("random", "yellow", "white")


@dataclass
class RenderOptions:
    """Switches of the renderer."""

    nose_prob: float = 0.5  # chance a look has the car nose at the bottom of the frame
    photometric: bool = True  # exposure, white balance, noise, blur, JPEG
    jpeg_prob: float = 0.5
    speed_mps: float = 0.0  # for motion blur; 0 = random per frame in dataset mode
    fps: float = 20.0
    steady_photometric: bool = False  # camera settings fixed per look (videos / bags) instead of per frame
    paint_lines: str = "random"  # PAINT_LINES: random (70 % of looks, a fifth of them yellow) or every look in one colour


def _noise(rng: np.random.Generator, h: int, w: int, scales: tuple[int, ...], weights: tuple[float, ...]) -> np.ndarray:
    """Multi-scale value noise (h, w) float32 around 0."""
    out = np.zeros((h, w), np.float32)
    for s, wt in zip(scales, weights):
        small = rng.standard_normal((max(h // s, 2), max(w // s, 2))).astype(np.float32)
        out += wt * cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    return out


def _seamless(tex: np.ndarray) -> np.ndarray:
    """Make a square tile wrap without seams: blend it with its half-shifted copy, whose seams sit where the
    original's weight is 1."""
    T = tex.shape[0]
    w1 = np.sin(np.pi * (np.arange(T) + 0.5) / T) ** 2
    w = np.outer(w1, w1).astype(np.float32)[:, :, None]
    shifted = np.roll(tex, (T // 2, T // 2), axis=(0, 1))
    return tex * w + shifted * (1 - w)


@dataclass
class Look:
    """Randomised appearance of one scene (track): ground, sky, background, sun, paints, nose."""

    near_mosaic: np.ndarray  # (3T, 3T, 3) uint8: 3 x 3 seamless ground tiles at tex_res_m
    tex_res_m: float  # m per near texture px
    far_mosaic: np.ndarray  # (9T/4, 9T/4, 3) uint8: 9 x 9 tiles at far_res_m
    far_res_m: float
    tile_m: float  # side of one tile in m
    haze_bgr: np.ndarray  # (3,) far-ground colour
    sky: np.ndarray  # (2H, W, 3) uint8 sky, horizon at row H
    pano: np.ndarray  # (hp, wp, 3) uint8 background band, px per rad = camera fx
    pano_alpha: np.ndarray  # (hp, wp) float32
    pano_below_px: int  # rows of the band below the horizon
    far_m: float  # distance where the background band starts (cones beyond are not drawn)
    sun_W: np.ndarray  # (3,) unit vector towards the sun
    ambient: float
    paints: dict[str, np.ndarray] = field(default_factory=dict)  # key -> (3,) float BGR
    body_paint: dict[int, np.ndarray] = field(default_factory=dict)
    nose: np.ndarray | None = None  # (H, W, 3) uint8
    nose_mask: np.ndarray | None = None  # (H, W) bool
    nose_top: int = 0
    photo_seed: int = 0  # camera settings of a steady (video) look


def make_look(camera: PinholeCamera, rng: np.random.Generator, options: RenderOptions) -> Look:
    W, H = camera.width, camera.height
    f = float(camera.K[0, 0])
    # ground tile: asphalt grey with multi-scale noise, patches, cracks, painted lines
    T, res = 1024, 0.02
    grey = rng.uniform(85, 150)
    tint = rng.uniform(-3, 3, 3)
    n = _noise(rng, T, T, (1, 3, 12, 48, 200), (5.0, 4.0, 5.0, 6.0, 7.0))
    tex = np.clip(grey + n, 0, 255).astype(np.float32)
    tex = np.repeat(tex[:, :, None], 3, axis=2) + tint
    for _ in range(int(rng.integers(2, 10))):  # repair patches (darker or lighter)
        c = tuple(int(x) for x in rng.integers(0, T, 2))
        ax = tuple(int(x) for x in rng.integers(20, 200, 2))
        col = float(rng.uniform(-30, 20))
        patch = np.zeros((T, T), np.float32)
        cv2.ellipse(patch, c, ax, float(rng.uniform(0, 180)), 0, 360, 1.0, -1)
        tex += cv2.GaussianBlur(patch, (0, 0), 6)[:, :, None] * col
    for _ in range(int(rng.integers(0, 12))):  # tar cracks
        pts = np.cumsum(rng.normal(0, 12, (8, 2)), axis=0) + rng.integers(0, T, 2)
        cv2.polylines(tex, [pts.astype(np.int32)], False, (grey * 0.7,) * 3, 1, cv2.LINE_AA)
    # painted lines (parking lot markings), white or yellow, worn (random: the draws of every earlier version)
    if (rng.random() < 0.7) or options.paint_lines != "random":
        white = rng.random() < 0.8
        line_col = (235, 235, 235) if (white if options.paint_lines == "random" else options.paint_lines == "white") \
            else (60, 200, 230)
        wear = np.clip(_noise(rng, T, T, (4, 30), (0.5, 0.6)) + 0.6, 0, 1)
        lines = np.zeros((T, T), np.float32)
        for _ in range(int(rng.integers(1, 4))):
            if rng.random() < 0.5:
                x = int(rng.integers(0, T))
                cv2.line(lines, (x, 0), (x, T), 1.0, 6)
            else:
                y = int(rng.integers(0, T))
                cv2.line(lines, (0, y), (T, y), 1.0, 6)
        a = (cv2.GaussianBlur(lines, (0, 0), 1.0) * wear * rng.uniform(0.4, 0.9))[:, :, None]
        tex = tex * (1 - a) + np.array(line_col, np.float32) * a
    tex = np.clip(_seamless(tex), 0, 255).astype(np.uint8)
    haze = tex.reshape(-1, 3).mean(0) * rng.uniform(0.95, 1.1)

    # sky: zenith -> horizon gradient, optional clouds
    kind = rng.choice(["clear", "overcast", "bright"], p=[0.5, 0.3, 0.2])
    if kind == "clear":
        top, hor = np.array([200, 140, 80]) + rng.uniform(-20, 20, 3), np.array([240, 225, 210]) + rng.uniform(-15, 10, 3)
    elif kind == "overcast":
        g = rng.uniform(170, 220)
        top, hor = np.array([g, g, g - 5]), np.array([g + 20, g + 20, g + 18])
    else:
        top, hor = np.array([245, 240, 235]), np.array([252, 252, 252])
    t = np.linspace(0, 1, 2 * H)[:, None] ** 0.7
    col = (top[None, :] * (1 - t) + hor[None, :] * t)
    col[H:] = hor
    sky = np.repeat(col[:, None, :], W, axis=1).astype(np.float32)
    if kind != "bright" and rng.random() < 0.5:  # soft clouds
        cl = cv2.GaussianBlur(_noise(rng, 2 * H, W, (60, 240), (0.4, 1.0)), (0, 0), 0.02 * W)
        cl = np.clip(cl * rng.uniform(0.8, 2.0) - 0.3, 0, 0.7)[:, :, None]
        sky = sky * (1 - cl) + np.float32(rng.uniform(225, 250)) * cl
    sky = np.clip(sky, 0, 255).astype(np.uint8)

    pano, alpha, below, far_m = _make_pano(rng, f, camera.pose.height_m)
    elev = np.radians(rng.uniform(15, 65))
    az = rng.uniform(0, 2 * np.pi)
    sun = np.array([np.cos(elev) * np.cos(az), np.cos(elev) * np.sin(az), np.sin(elev)])
    paints = {
        "white": np.array([235, 235, 232], float) * rng.uniform(0.9, 1.0),
        "black": np.array([28, 28, 30], float) + rng.uniform(0, 15),
    }
    body_paint = {c: np.clip(np.array(v, float) + rng.normal(0, 10, 3), 0, 255) for c, v in _PAINT.items()}
    far_tile = cv2.resize(tex, (T // 4, T // 4), interpolation=cv2.INTER_AREA)
    look = Look(np.tile(tex, (3, 3, 1)), res, np.tile(far_tile, (9, 9, 1)), res * 4, T * res, haze, sky, pano, alpha, below, far_m, sun, float(rng.uniform(0.35, 0.6)), paints, body_paint)
    look.photo_seed = int(rng.integers(0, 2**31))
    if rng.random() < options.nose_prob:
        look.nose, look.nose_mask, look.nose_top = _make_nose(rng, W, H)
    return look


def _make_pano(rng: np.random.Generator, f: float, cam_h_m: float) -> tuple[np.ndarray, np.ndarray, int, float]:
    """360-degree background band at ``f`` px/rad: trees, buildings, fences, tyre walls, poles, far grass."""
    wp = int(np.ceil(2 * np.pi * f))
    above = int(0.32 * f)  # ~18 degrees above the horizon
    dv_deg = rng.uniform(0.9, 1.7)
    below = int(np.ceil(np.radians(dv_deg) * f)) + 2
    far_m = float(cam_h_m / np.tan(np.radians(dv_deg)))
    hp = above + below
    img = np.zeros((hp, wp, 3), np.float32)
    a = np.zeros((hp, wp), np.float32)
    hz = above  # horizon row in the band
    # far ground (grass or far asphalt) below and slightly above the horizon
    ground_col = np.array([60, 120, 90], float) if rng.random() < 0.6 else np.array([120, 125, 125], float)
    ground_col = ground_col + rng.uniform(-20, 20, 3)
    img[hz - 2 :] = ground_col + _noise(rng, below + 2, wp, (2, 9), (8, 8))[:, :, None]
    a[hz - 2 :] = 1.0
    x = 0
    while x < wp:
        kind = rng.choice(["trees", "building", "fence", "tyres", "pole", "gap"], p=[0.35, 0.2, 0.15, 0.1, 0.05, 0.15])
        wdt = int(rng.uniform(0.05, 0.35) * f) if kind != "pole" else int(0.01 * f) + 2
        x1 = min(x + wdt, wp)
        if kind == "trees":
            h = rng.uniform(0.03, 0.3) * f
            xs = (np.arange(x1 - x) + 0.5) / (x1 - x)
            crowns = np.clip(_noise(rng, 1, x1 - x, (16, 48), (0.25, 0.5))[0] + 0.75, 0.3, 1.2)
            prof = h * crowns * np.sin(np.pi * xs) ** 0.4  # rounded ends
            col = np.array([40, 90, 60], float) * rng.uniform(0.6, 1.3) + rng.uniform(-10, 10, 3)
            for i, ph in enumerate(prof):
                y0 = max(int(hz - ph), 0)
                img[y0:hz, x + i] = col
                a[y0:hz, x + i] = 1.0
            img[:hz, x:x1] += _noise(rng, hz, x1 - x, (2, 6), (10, 10))[:, :, None] * a[:hz, x:x1, None]
        elif kind == "building":
            h = int(rng.uniform(0.03, 0.25) * f)
            col = rng.choice([[200, 200, 200], [170, 190, 210], [120, 120, 130], [230, 230, 225]]) + rng.uniform(-20, 20, 3)
            y0 = max(hz - h, 0)
            img[y0:hz, x:x1] = col
            a[y0:hz, x:x1] = 1.0
            step = max(int(0.012 * f), 3)
            win = col * 0.45
            for yy in range(y0 + step // 2, hz - step, step):
                for xx in range(x + step // 2, x1 - step, step):
                    img[yy : yy + step // 2, xx : xx + step // 2] = win
        elif kind == "fence":
            h = int(rng.uniform(0.015, 0.03) * f)
            col = np.array([150, 150, 150], float) * rng.uniform(0.5, 1.2)
            for xx in range(x, x1, max(int(0.02 * f), 3)):
                img[hz - h : hz, xx] = col
                a[hz - h : hz, xx] = 1.0
            for yy in (hz - h, hz - h // 2):
                img[yy, x:x1] = col
                a[yy, x:x1] = 1.0
            mesh = (np.add.outer(np.arange(h), np.arange(x1 - x)) % 4 == 0).astype(np.float32) * 0.35
            a[hz - h : hz, x:x1] = np.maximum(a[hz - h : hz, x:x1], mesh)
            img[hz - h : hz, x:x1] = np.where(mesh[:, :, None] > 0, col, img[hz - h : hz, x:x1])
        elif kind == "tyres":
            h = max(int(0.008 * f), 3)
            img[hz - h : hz, x:x1] = 25 + _noise(rng, h, x1 - x, (1,), (6,))[:, :, None]
            a[hz - h : hz, x:x1] = 1.0
        elif kind == "pole":
            h = int(rng.uniform(0.05, 0.16) * f)
            img[hz - h : hz, x:x1] = 140
            a[hz - h : hz, x:x1] = 1.0
        x = x1
    return np.clip(img, 0, 255).astype(np.uint8), a, below, far_m


def _make_nose(rng: np.random.Generator, W: int, H: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Car nose, cockpit rim, front wheels and wishbones in image space (fixed to the car)."""
    img = np.zeros((H, W, 3), np.uint8)
    mask = np.zeros((H, W), np.uint8)

    def fill(poly_or_fn, colour):
        poly_or_fn(img, tuple(int(c) for c in colour))
        poly_or_fn(mask, 1)

    top = int(H * rng.uniform(0.5, 0.9))
    half_b, half_t = W * rng.uniform(0.18, 0.35), W * rng.uniform(0.05, 0.14)
    cx = W / 2 + rng.uniform(-0.02, 0.02) * W
    body = np.array([[cx - half_b, H], [cx - half_t, top], [cx + half_t, top], [cx + half_b, H]], np.int32)
    dark = [[40, 25, 20], [25, 25, 25], [50, 30, 25], [35, 35, 40]]  # carbon, navy, black: most cars
    bright = [[90, 40, 20], [30, 30, 140], [200, 200, 200], [20, 70, 20]]
    col = np.array(dark[int(rng.integers(len(dark)))] if rng.random() < 0.75 else bright[int(rng.integers(len(bright)))], float)
    col += rng.integers(-10, 10, 3)
    fill(lambda im, c: cv2.fillConvexPoly(im, body, c), col)
    # shading across the nose (lighter towards the sky-facing middle), stickers, centre seam
    xs = np.arange(W, dtype=np.float32)
    shade = 0.75 + 0.35 * np.exp(-(((xs - cx) / max(half_t * 1.5, 1.0)) ** 2))
    img[top:] = np.clip(img[top:] * shade[None, :, None], 0, 255).astype(np.uint8)
    for _ in range(int(rng.integers(0, 4))):
        y0 = int(rng.uniform(top, H))
        h = int(H * rng.uniform(0.01, 0.04))
        f0 = (y0 - top) / max(H - top, 1)
        hw = half_t + (half_b - half_t) * f0
        sticker = np.array([[cx - hw * 0.9, y0], [cx + hw * 0.9, y0], [cx + hw * 0.9, y0 + h], [cx - hw * 0.9, y0 + h]], np.int32)
        cv2.fillConvexPoly(img, sticker, tuple(int(c) for c in rng.integers(0, 255, 3)))
        img[mask == 0] = 0
    cv2.line(img, (int(cx), H), (int(cx), top), tuple(int(c * 0.6 + 60) for c in col), max(W // 200, 2))
    if rng.random() < 0.5:  # cockpit rim / steering wheel at the very bottom
        axes = (int(half_b * 0.7), int(H * rng.uniform(0.08, 0.15)))
        fill(lambda im, c: cv2.ellipse(im, (int(cx), H), axes, 0, 180, 360, c, -1), (18, 18, 18))
    if rng.random() < 0.8:  # front wheels and wishbones
        wr = int(H * rng.uniform(0.12, 0.25))
        for s in (-1, 1):
            wc = (int(cx + s * W * rng.uniform(0.3, 0.42)), int(H - wr * rng.uniform(0.0, 0.6)))
            fill(lambda im, c: cv2.ellipse(im, wc, (int(wr * 0.55), wr), 0, 0, 360, c, -1), (22, 22, 22))
            for dy in (0, int(H * 0.04)):
                p0 = (int(cx + s * half_t * 1.5), top + dy + int(H * 0.03))
                fill(lambda im, c: cv2.line(im, p0, wc, c, max(W // 300, 2)), (50, 50, 50))
    return img, mask.astype(bool), int(np.flatnonzero(mask.any(1))[0])
