"""CPU renderer (numpy / OpenCV) of a Formula Student scene with exact ground truth.

Per frame: sky gradient, ground as one ``cv2.warpPerspective`` of a tiled
asphalt texture through the frame's ground homography, a 360-degree background
band (grass, trees, buildings, fences, tyre walls) at the horizon, cone
shadows, cones as faceted 3D frusta drawn far to near (painter's order) with
sun shading, an optional car nose, then photometric randomisation (exposure,
white balance, gamma, saturation, optics and motion blur, sensor noise, JPEG)
and optional lens distortion.

Ground truth comes from a per-pixel cone id buffer drawn with the same
polygons: each cone's box is the tight box of its visible pixels (full-image
px, ``[u1, v1, u2, v2]`` with pixel ``c`` covering ``[c, c + 1)``), its visible
fraction = visible pixels / pixels of its whole silhouette (inside or outside
the image).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np

from ..classes import BLUE, CLASS_NAMES, LARGE_ORANGE, ORANGE, UNKNOWN, YELLOW
from ..geometry.camera import PinholeCamera
from .scene import CarPose, SceneCamera
from .track import Track

NOSE_ID = 65535  # id-buffer value of the car nose (occluder)
NEAR_GROUND_M = 15.0  # ground nearer than this comes from the fine texture mosaic


@dataclass(frozen=True)
class ConeModel:
    """FS cone geometry (m). ``bands``: (z0, z1, paint) of the body, z measured from the ground."""

    base_m: float  # square base plate side
    plate_h_m: float
    r_bottom_m: float
    r_top_m: float
    height_m: float
    bands: tuple[tuple[float, float, str], ...]


def _bands(h: float, plate: float, stripes: tuple[tuple[float, float], ...], body: str, stripe: str):
    """Body bands between plate top and tip, ``stripes`` as fractions of the body height."""
    edges, paints = [plate], []
    z = plate
    for f0, f1 in stripes:
        z0, z1 = plate + f0 * (h - plate), plate + f1 * (h - plate)
        edges += [z0, z1]
        paints += [body, stripe]
        z = z1
    edges.append(h)
    paints.append(body)
    del z
    return tuple((edges[i], edges[i + 1], paints[i]) for i in range(len(paints)))


SMALL_H, LARGE_H = 0.325, 0.505
CONE_MODELS: dict[int, ConeModel] = {
    BLUE: ConeModel(0.228, 0.025, 0.095, 0.022, SMALL_H, _bands(SMALL_H, 0.025, ((0.36, 0.62),), "body", "white")),
    YELLOW: ConeModel(0.228, 0.025, 0.095, 0.022, SMALL_H, _bands(SMALL_H, 0.025, ((0.36, 0.62),), "body", "black")),
    ORANGE: ConeModel(0.228, 0.025, 0.095, 0.022, SMALL_H, _bands(SMALL_H, 0.025, ((0.36, 0.62),), "body", "white")),
    LARGE_ORANGE: ConeModel(
        0.285, 0.03, 0.125, 0.028, LARGE_H, _bands(LARGE_H, 0.03, ((0.30, 0.42), (0.56, 0.68)), "body", "white")
    ),
}
CONE_MODELS[UNKNOWN] = CONE_MODELS[ORANGE]

# Base paint colours, BGR 0..255, jittered per look.
_PAINT = {BLUE: (205, 110, 20), YELLOW: (25, 200, 240), ORANGE: (20, 105, 245), LARGE_ORANGE: (25, 95, 240), UNKNOWN: (120, 120, 120)}


@dataclass
class RenderOptions:
    """Switches of the renderer."""

    nose_prob: float = 0.5  # chance a look has the car nose at the bottom of the frame
    photometric: bool = True  # exposure, white balance, noise, blur, JPEG
    jpeg_prob: float = 0.5
    speed_mps: float = 0.0  # for motion blur; 0 = random per frame in dataset mode
    fps: float = 20.0
    steady_photometric: bool = False  # camera settings fixed per look (videos / bags) instead of per frame


@dataclass
class ConeTruth:
    """Ground truth of one visible cone."""

    track_index: int
    class_id: int
    x_m: float  # rear_axle
    y_m: float
    distance_m: float  # from the rear-axle origin
    box: tuple[float, float, float, float]  # full-image px, tight box of visible pixels
    visible_fraction: float
    foot_px: tuple[float, float]  # projection of the ground contact point (cone centre on the ground)

    def to_dict(self) -> dict:
        return {
            "class_id": self.class_id,
            "class": CLASS_NAMES[self.class_id],
            "x_m": round(self.x_m, 4),
            "y_m": round(self.y_m, 4),
            "distance_m": round(self.distance_m, 4),
            "box": [round(float(b), 2) for b in self.box],
            "visible_fraction": round(self.visible_fraction, 4),
            "foot_px": [round(float(f), 4) for f in self.foot_px],
        }


# ---------------------------------------------------------------- look (per track)


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
    if rng.random() < 0.7:  # painted lines (parking lot markings), white or yellow, worn
        line_col = (235, 235, 235) if rng.random() < 0.8 else (60, 200, 230)
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


# ---------------------------------------------------------------- cone meshes

N_SEG = 12
_THETA = np.arange(N_SEG) * 2 * np.pi / N_SEG


def _mesh(model: ConeModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cone-local vertices (V, 3): 8 plate corners, then one ring of N_SEG per band edge; ring heights; ring radii."""
    a = model.base_m / 2
    plate = np.array([[sx * a, sy * a, z] for z in (0.0, model.plate_h_m) for (sx, sy) in ((1, 1), (-1, 1), (-1, -1), (1, -1))])
    zs = np.array([model.bands[0][0]] + [b[1] for b in model.bands])
    r = model.r_bottom_m + (model.r_top_m - model.r_bottom_m) * (zs - zs[0]) / (model.height_m - zs[0])
    rings = np.concatenate([np.column_stack([ri * np.cos(_THETA), ri * np.sin(_THETA), np.full(N_SEG, z)]) for z, ri in zip(zs, r)])
    return np.concatenate([plate, rings]), zs, r


_MESHES = {c: _mesh(m) for c, m in CONE_MODELS.items()}
_PLATE_FACES = [(4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]  # top, 4 sides


def cone_vertices_W(track: Track, i: int) -> np.ndarray:
    """(V, 3) track-frame vertices (m) of cone ``i``: 8 base-plate corners, then the body rings.

    A knocked-over cone lies on its side (plate edge and body flank on the ground, tip pointing
    in a fixed random direction) around its track position.
    """
    verts, _, _ = _MESHES[int(track.cone_class[i])]
    yaw = (i * 0.6180339) % (np.pi / 2)  # fixed plate yaw per cone
    if track.fallen(i):
        model = CONE_MODELS[int(track.cone_class[i])]
        tilt = np.pi / 2 - np.arctan((model.r_bottom_m - model.r_top_m) / (model.height_m - model.plate_h_m))
        Rx = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
        verts = verts @ Rx.T
        verts = verts - np.array([0.0, verts[:, 1].mean(), verts[:, 2].min()])  # rest on the ground, centred
        yaw = (i * 2.3999632) % (2 * np.pi)
    c, s = np.cos(yaw), np.sin(yaw)
    return verts @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]) + np.array([track.cones_xy_m[i, 0], track.cones_xy_m[i, 1], 0.0])


# ---------------------------------------------------------------- renderer


class Renderer:
    """Renders frames of ``camera`` (nominal mount, K, size, optional distortion)."""

    def __init__(self, camera: PinholeCamera, options: RenderOptions | None = None):
        self.camera = camera
        self.options = options or RenderOptions()
        self.W, self.H = camera.width, camera.height
        self._noise_pos, self._noise_neg = self._make_sensor_noise()
        self._dist_map = None
        if camera.dist_coeffs.size and np.any(camera.dist_coeffs):
            uu, vv = np.meshgrid(np.arange(self.W, dtype=np.float32), np.arange(self.H, dtype=np.float32))
            # pixel (x, y) of OpenCV is the continuous point (x + 0.5, y + 0.5) of our pixel-corner convention
            pts = np.stack([uu.ravel(), vv.ravel()], 1).reshape(-1, 1, 2) + 0.5
            und = cv2.undistortPoints(pts, camera.K, camera.dist_coeffs, P=camera.K).reshape(self.H, self.W, 2) - 0.5
            self._dist_map = (und[:, :, 0].copy(), und[:, :, 1].copy())

    def _make_sensor_noise(self) -> tuple[np.ndarray, np.ndarray]:
        return _sensor_noise(self.H, self.W)

    def new_look(self, rng: np.random.Generator) -> Look:
        return make_look(self.camera, rng, self.options)

    # -- per frame
    def render(self, track: Track, pose: CarPose, look: Look, rng: np.random.Generator) -> tuple[np.ndarray, list[ConeTruth]]:
        """One frame: ((H, W, 3) uint8 BGR, ground truth of every cone with visible pixels)."""
        W, H = self.W, self.H
        sc = SceneCamera(self.camera, pose)
        H_B_W = sc.H_B_W()
        # horizon row at the image centre (band placement) and lowest horizon row (ground start)
        H_W_B = np.linalg.inv(H_B_W)  # the horizon is where the third row of H_W_B vanishes
        hz = lambda u: -(H_W_B[2, 0] * u + H_W_B[2, 2]) / H_W_B[2, 1]  # noqa: E731
        v_hc = hz(W / 2.0)
        v_ground = int(np.clip(np.ceil(max(hz(0.0), hz(W - 1.0))) + 1, 0, H))

        img = self._sky(look, v_hc)
        if v_ground < H:
            img[v_ground:] = self._ground(look, H_W_B, v_ground, sc)
        self._band(img, look, pose, v_hc, sc)

        idbuf = np.zeros((H, W), np.uint16)
        cones = self._visible_cones(track, sc, look)
        ground_rows = img[v_ground:] if v_ground < H else None
        if ground_rows is not None:
            self._shadows(img, cones, track, sc, look, v_ground)
        polys = self._draw_cones(img, idbuf, cones, track, sc, look)
        if look.nose is not None:
            t = look.nose_top
            np.copyto(img[t:], look.nose[t:], where=look.nose_mask[t:, :, None])
            idbuf[t:][look.nose_mask[t:]] = NOSE_ID
        if self._dist_map is not None:
            img = cv2.remap(img, *self._dist_map, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            idbuf = cv2.remap(idbuf, *self._dist_map, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        truths = self._truth(idbuf, cones, polys, track, sc)
        if self.options.photometric:
            img = self._photometric(img, rng, v_hc, look)
        return img, truths

    def _sky(self, look: Look, v_hc: float) -> np.ndarray:
        off = int(np.clip(round(self.H - v_hc), 0, look.sky.shape[0] - self.H))
        return look.sky[off : off + self.H].copy()

    def _ground(self, look: Look, H_W_B: np.ndarray, v0: int, sc: SceneCamera) -> np.ndarray:
        """Rows ``v0..H`` of the ground: near rows from the fine mosaic, far rows from the coarse one.

        The tile is seamless, so shifting the texture by whole tiles changes nothing: each mosaic is
        placed with the camera in its middle tile and warped with a constant border (several times
        faster than ``BORDER_WRAP``).
        """
        W, H = self.W, self.H
        cam = sc.position_W()
        rows = np.arange(v0, H, dtype=np.float64) + 0.5
        p = np.column_stack([np.full_like(rows, W / 2), rows, np.ones_like(rows)]) @ H_W_B.T
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = p[:, :2] / p[:, 2:3]
        d = np.where(p[:, 2] > 0, np.hypot(xy[:, 0] - cam[0], xy[:, 1] - cam[1]), np.inf)
        n_far = int(np.count_nonzero(d > NEAR_GROUND_M))  # rows are ordered far (top) to near (bottom)
        g = np.empty((H - v0, W, 3), np.uint8)
        for mosaic, res, r0, r1 in ((look.far_mosaic, look.far_res_m, 0, n_far), (look.near_mosaic, look.tex_res_m, n_far, H - v0)):
            if r1 <= r0:
                continue
            tile_px = look.tile_m / res
            k = np.floor(cam[:2] / look.tile_m) - (mosaic.shape[0] // tile_px - 1) // 2  # first tile of the mosaic
            T_tex_W = np.array([[1 / res, 0, -k[0] * tile_px], [0, 1 / res, -k[1] * tile_px], [0, 0, 1.0]])
            M = T_tex_W @ H_W_B @ np.array([[1, 0, 0.5], [0, 1, v0 + r0 + 0.5], [0, 0, 1.0]])
            cv2.warpPerspective(
                mosaic, M, (W, r1 - r0), dst=g[r0:r1], flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                borderMode=cv2.BORDER_CONSTANT, borderValue=tuple(float(c) for c in look.haze_bgr),
            )
        # haze: blend the far rows towards the mean ground colour (hides texture aliasing)
        rows = np.arange(v0, H, dtype=np.float64) + 0.5
        p = np.column_stack([np.full_like(rows, W / 2), rows, np.ones_like(rows)]) @ H_W_B.T
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = p[:, :2] / p[:, 2:3]
        alpha = np.clip((d - 12.0) / 40.0, 0.0, 0.85)
        n = int(np.count_nonzero(alpha > 0.01))
        if n:
            a = alpha[:n, None, None].astype(np.float32)
            g[:n] = (g[:n] * (1 - a) + look.haze_bgr.astype(np.float32) * a).astype(np.uint8)
        return g

    def _band(self, img: np.ndarray, look: Look, pose: CarPose, v_hc: float, sc: SceneCamera) -> None:
        W, H = self.W, self.H
        K = self.camera.K
        yaw_cam = pose.yaw_rad + np.radians(self.camera.pose.yaw_deg)
        az = yaw_cam + np.arctan((K[0, 2] - (np.arange(W) + 0.5)) / K[0, 0])
        wp = look.pano.shape[1]
        cols = np.mod(np.round(az * K[0, 0]).astype(np.int64), wp)
        hp = look.pano.shape[0]
        top = int(round(v_hc)) - (hp - look.pano_below_px)
        r0, r1 = max(top, 0), min(top + hp, H)
        if r1 <= r0:
            return
        band = look.pano[r0 - top : r1 - top][:, cols].astype(np.float32)
        a = look.pano_alpha[r0 - top : r1 - top][:, cols][:, :, None]
        img[r0:r1] = (img[r0:r1] * (1 - a) + band * a).astype(np.uint8)

    def _visible_cones(self, track: Track, sc: SceneCamera, look: Look) -> list[tuple[int, np.ndarray, np.ndarray, float]]:
        """Cones in front of the camera within the band distance, far to near: (index, verts_W, uv, depth)."""
        cam = sc.position_W()
        xy = track.cones_xy_m
        d = np.hypot(xy[:, 0] - cam[0], xy[:, 1] - cam[1])
        cand = np.flatnonzero(d < look.far_m)
        if not len(cand):
            return []
        c3 = np.column_stack([xy[cand], np.zeros(len(cand))])
        uv, depth = sc.project(c3, distort=False)
        m = 0.6 * self.W
        keep = (depth > 0.4) & (uv[:, 0] > -m) & (uv[:, 0] < self.W + m) & (uv[:, 1] < self.H + m)
        out = []
        for i in cand[keep]:
            V = cone_vertices_W(track, int(i))
            uvv, dep = sc.project(V, distort=False)
            if np.any(~(dep > 0.1)):
                continue
            out.append((int(i), V, uvv, float(np.hypot(*(xy[i] - cam[:2])))))
        out.sort(key=lambda t: -t[3])
        return out

    def _shadows(self, img, cones, track: Track, sc: SceneCamera, look: Look, v_ground: int) -> None:
        L = look.sun_W
        k = float(0.35 + 0.4 * look.ambient)
        for i, V, _, _ in cones:
            G = V - (V[:, 2:3] / L[2]) * L  # every vertex along the sun onto the ground
            G[:, 2] = 0.0
            uv, dep = sc.project(G, distort=False)
            if np.any(~(dep > 0.1)):
                continue
            hull = cv2.convexHull(_px4(uv))
            x, y, w, h = cv2.boundingRect(hull)
            x0, y0, x1, y1 = max(x // 4, 0), max(y // 4, v_ground), min((x + w) // 4 + 2, self.W), min((y + h) // 4 + 2, self.H)
            if x1 <= x0 or y1 <= y0:
                continue
            mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
            cv2.fillConvexPoly(mask, hull - np.array([x0 * 4, y0 * 4]), 1, cv2.LINE_8, 2)
            roi = img[y0:y1, x0:x1]
            np.copyto(roi, (roi * k).astype(np.uint8), where=mask[:, :, None].astype(bool))

    def _draw_cones(self, img, idbuf, cones, track: Track, sc: SceneCamera, look: Look) -> dict[int, list[np.ndarray]]:
        """Draw cones far to near into ``img`` and ``idbuf`` (value = index + 1). Returns silhouette hulls (px*4).

        Facet normals come from the posed vertices, so upright, rotated and knocked-over cones shade
        and cull alike; visible facets of one convex piece never overlap, so their order is free.
        """
        cam = sc.position_W()
        L = look.sun_W
        amb = look.ambient
        polys: dict[int, list[np.ndarray]] = {}
        for n_id, (i, V, uv, _) in enumerate(cones):
            cls = int(track.cone_class[i])
            model = CONE_MODELS[cls]
            P = _px4(uv)
            body = look.body_paint[cls]
            size_px = float(max(np.ptp(uv[:, 1]), np.ptp(uv[:, 0])))
            # base plate: 5 faces (top and sides; the bottom is never seen from above)
            faces = np.array(_PLATE_FACES)
            nrm, fc = _quad_normals(V[faces], V[:8].mean(0))
            vis = np.einsum("ij,ij->i", nrm, cam - fc) > 0
            shade = amb + (1 - amb) * np.clip(nrm @ L, 0, None)
            for f, sh in zip(faces[vis], shade[vis]):
                cv2.fillConvexPoly(img, P[f], _col(body * 0.75 * sh), cv2.LINE_8, 2)
            # body bands
            j = np.arange(N_SEG)
            for b, (_, _, paint) in enumerate(model.bands):
                col = body if paint == "body" else look.paints[paint]
                r0 = 8 + b * N_SEG
                r1 = r0 + N_SEG
                if size_px < 18:  # small: one flat-shaded silhouette per band
                    hull = cv2.convexHull(P[r0 : r1 + N_SEG])
                    cv2.fillConvexPoly(img, hull, _col(col * (amb + (1 - amb) * 0.6)), cv2.LINE_8, 2)
                    continue
                quads = np.stack([r0 + j, r0 + (j + 1) % N_SEG, r1 + (j + 1) % N_SEG, r1 + j], axis=1)
                axis_mid = (V[r0:r1].mean(0) + V[r1 : r1 + N_SEG].mean(0)) / 2
                nrm, fc = _quad_normals(V[quads], axis_mid)
                vis = np.einsum("ij,ij->i", nrm, cam - fc) > 0
                lam = np.clip(nrm @ L, 0, None)
                shade = amb + (1 - amb) * lam + 0.08 * lam**8  # small highlight
                for q, sh in zip(quads[vis], shade[vis]):
                    cv2.fillConvexPoly(img, P[q], _col(col * sh), cv2.LINE_8, 2)
            hulls = [cv2.convexHull(P[:8]), cv2.convexHull(P[8:])]
            for h in hulls:
                cv2.fillConvexPoly(idbuf, h, n_id + 1, cv2.LINE_8, 2)
            polys[n_id] = hulls
        return polys

    def _truth(self, idbuf, cones, polys, track: Track, sc: SceneCamera) -> list[ConeTruth]:
        out = []
        for n_id, (i, V, uv, _) in enumerate(cones):
            if self._dist_map is not None:  # silhouette in distorted pixels
                uvd, _ = sc.project(V, distort=True)
                P = _px4(uvd)
                hulls = [cv2.convexHull(P[:8]), cv2.convexHull(P[8:])]
            else:
                hulls = polys[n_id]
            allp = np.concatenate([h.reshape(-1, 2) for h in hulls])
            x0, y0 = allp.min(0) // 4 - 1
            x1, y1 = allp.max(0) // 4 + 2
            full = np.zeros((y1 - y0, x1 - x0), np.uint8)
            for h in hulls:
                cv2.fillConvexPoly(full, h - np.array([x0 * 4, y0 * 4]), 1, cv2.LINE_8, 2)
            n_full = int(full.sum())
            cx0, cy0, cx1, cy1 = max(x0, 0), max(y0, 0), min(x1, self.W), min(y1, self.H)
            if n_full == 0 or cx1 <= cx0 or cy1 <= cy0:
                continue
            vis = idbuf[cy0:cy1, cx0:cx1] == n_id + 1
            n_vis = int(vis.sum())
            if n_vis == 0:
                continue
            rows, colsx = np.flatnonzero(vis.any(1)), np.flatnonzero(vis.any(0))
            box = (cx0 + colsx[0], cy0 + rows[0], cx0 + colsx[-1] + 1, cy0 + rows[-1] + 1)
            ground_W = np.array([[track.cones_xy_m[i, 0], track.cones_xy_m[i, 1], 0.0]])
            p_F = sc.world_to_F(ground_W)[0]
            foot, _ = sc.project(ground_W, distort=True)
            out.append(
                ConeTruth(
                    int(i), int(track.cone_class[i]), float(p_F[0]), float(p_F[1]), float(np.hypot(p_F[0], p_F[1])),
                    tuple(float(b) for b in box), min(n_vis / n_full, 1.0), (float(foot[0, 0]), float(foot[0, 1])),
                )
            )
        return out

    def _photometric(self, img: np.ndarray, rng: np.random.Generator, v_hc: float, look: Look) -> np.ndarray:
        """Camera effects. The settings (exposure, white balance, gamma, saturation, blur, noise level,
        exposure time) come from ``rng``, or with ``steady_photometric`` from the look (a video keeps
        its settings); the noise pattern and JPEG always vary per frame."""
        o = self.options
        H, W = self.H, self.W
        cam_rng = np.random.default_rng(look.photo_seed) if o.steady_photometric else rng
        # exposure, white balance, gamma in one LUT
        gain = float(np.exp(cam_rng.uniform(np.log(0.6), np.log(1.6))))
        temp, tint = cam_rng.uniform(-0.08, 0.08), cam_rng.uniform(-0.02, 0.02)
        wb = np.array([1.0 - temp, 1.0 + tint, 1.0 + temp])  # B G R: colour temperature, little green/magenta
        gamma = float(cam_rng.uniform(0.8, 1.25))
        x = np.arange(256, dtype=np.float64)[:, None] / 255.0
        lut = np.clip(255.0 * np.clip(x * gain * wb[None, :], 0, 1) ** gamma, 0, 255).astype(np.uint8)
        img = cv2.LUT(img, lut.reshape(256, 1, 3))
        sat = float(cam_rng.uniform(0.6, 1.15))
        if abs(sat - 1) > 0.03:
            g = cv2.cvtColor(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR)
            img = cv2.addWeighted(img, sat, g, 1 - sat, 0)
        # motion blur at speed (vertical, lower image part where the ground flows fastest)
        speed = o.speed_mps if o.speed_mps > 0 else cam_rng.uniform(0, 15)
        klen = int(np.clip(speed * cam_rng.uniform(1.0, 5.0) * 1e-3 * 0.3 * H, 1, 25))
        if klen >= 3:  # growing towards the bottom in 4 bands, so no visible step
            v_top = int(np.clip(v_hc + 0.2 * (H - v_hc), 0, H - 1))
            edges = np.linspace(v_top, H, 5).astype(int)
            for b in range(4):
                k = max(int(round(klen * (b + 1) / 4)), 1)
                if k >= 2:
                    r0, r1 = max(edges[b] - k, 0), edges[b + 1]
                    img[edges[b] : r1] = cv2.blur(img[r0:r1], (1, k))[edges[b] - r0 :]
        sigma = float(cam_rng.uniform(0.3, 1.2)) * H / 1080
        img = cv2.GaussianBlur(img, (0, 0), sigma)
        # sensor noise from a fixed noise field at a random offset and strength
        ns = float(cam_rng.uniform(0.1, 0.7))
        oy, ox = (int(v) for v in rng.integers(0, 32, 2))
        img = cv2.add(img, cv2.multiply(self._noise_pos[oy : oy + H, ox : ox + W], ns, dtype=cv2.CV_8U))
        img = cv2.subtract(img, cv2.multiply(self._noise_neg[oy : oy + H, ox : ox + W], ns, dtype=cv2.CV_8U))
        if rng.random() < o.jpeg_prob:
            ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(30, 90))])
            img = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        return img


def _px4(uv: np.ndarray) -> np.ndarray:
    """(N, 2) continuous px (pixel c covers [c, c + 1)) -> int32 OpenCV drawing points with shift = 2
    (OpenCV puts integer coordinates at pixel centres)."""
    return np.round((uv - 0.5) * 4).astype(np.int32)


@lru_cache(maxsize=2)
def _sensor_noise(H: int, W: int) -> tuple[np.ndarray, np.ndarray]:
    """Fixed Gaussian noise field (sigma 8) split in positive and negative parts, (H + 32, W + 32, 3) uint8 each."""
    rng = np.random.default_rng(12345)
    n = rng.normal(0, 8.0, (H + 32, W + 32, 3)).astype(np.float32)
    return np.clip(n, 0, 255).astype(np.uint8), np.clip(-n, 0, 255).astype(np.uint8)


def _quad_normals(Q: np.ndarray, inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F, 4, 3) quads -> ((F, 3) unit normals pointing away from ``inside`` (3,), (F, 3) face centres)."""
    n = np.cross(Q[:, 2] - Q[:, 0], Q[:, 3] - Q[:, 1])
    fc = Q.mean(1)
    n *= np.where(np.einsum("ij,ij->i", n, fc - inside) < 0, -1.0, 1.0)[:, None]
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12), fc



def _col(c: np.ndarray) -> tuple[float, float, float]:
    return tuple(float(x) for x in np.clip(c, 0, 255))
