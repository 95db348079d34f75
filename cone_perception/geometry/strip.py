"""The far strip: the image rows where cones ``near_m``..``far_m`` ahead stand, placed from the
calibration's camera model and moved with the attitude. ROS-free.

The halved band sees cones to about 15 m; farther ones are a few px tall there, and the detector
finds them only at full resolution. The strip (run at full resolution by
:class:`~cone_perception.detector.farband.FarBand`) covers, across the whole image width, the rows
from the top of the tallest cone (large orange, 0.505 m) ``far_m`` ahead down to the foot of a cone
``near_m`` ahead. "Ahead" is the distance along the camera's heading: a cone 15 m ahead at the
view's edge is farther away but as large in the image as one 15 m straight ahead (its depth is the
same), and the halved band sees it as well.

The strip's height is fixed (the detector is built for one input size): the rows needed at the
calibration's attitude plus a margin for what the attitude the strip follows may be off by
(``pitch_margin_deg``: the frame-to-frame change and the estimate's error; ``roll_margin_deg``: a roll
tilts the rows, which a horizontal strip cannot follow), rounded up to :data:`ROW_MULTIPLE`. Each
frame its centre follows the rows needed at that frame's attitude (:meth:`StripPlan.top_for`); where
that would leave the image the strip is clamped to it (the caller counts it).

The calibration's optional ``far_strip`` field sets :class:`FarStripSpec` (``off`` disables it);
:func:`plan_strip` refuses a strip that leaves the image or lies above the horizon, naming the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..classes import CONE_SIZE_M, LARGE_ORANGE
from ..errors import ConfigError
from .camera import MountPose, PinholeCamera
from .pose import attitude_rotation

#: The strip's height is a multiple of this (the detector's stride: no padding of its input).
ROW_MULTIPLE = 32
#: The tallest cone (large orange, m): the strip reaches its top at ``far_m``.
TALLEST_CONE_M = CONE_SIZE_M[LARGE_ORANGE][0]
#: Ground points sampled across the view on each of the strip's two lines (far tops, near feet).
_SAMPLES = 41


@dataclass(frozen=True)
class FarStripSpec:
    """The calibration's ``far_strip``: the range ahead the strip covers and its attitude margins."""

    near_m: float = 15.0
    far_m: float = 40.0
    pitch_margin_deg: float = 0.5
    roll_margin_deg: float = 0.5

    def to_dict(self) -> dict[str, float]:
        return {k: float(getattr(self, k)) for k in ("near_m", "far_m", "pitch_margin_deg", "roll_margin_deg")}


DEFAULT_STRIP = FarStripSpec()


def strip_spec_from_yaml(value, err) -> FarStripSpec | None:
    """The YAML's ``far_strip`` value -> a spec (absent: the defaults), or None for ``off`` / ``false``.
    ``err(field, message)`` builds the ConfigError naming the file and field."""
    if value is None:
        return DEFAULT_STRIP
    if value is False or (isinstance(value, str) and value.strip().lower() == "off"):
        return None
    if not isinstance(value, dict):
        raise err("far_strip", f"must be off or a mapping with {', '.join(DEFAULT_STRIP.to_dict())}, got {value!r}")
    known = DEFAULT_STRIP.to_dict()
    v = dict(known)
    for k, x in value.items():
        if k not in known:
            raise err(f"far_strip.{k}", f"unknown key; known: {', '.join(known)}")
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            raise err(f"far_strip.{k}", f"must be a finite number, got {x!r}")
        v[k] = float(x)
    if not 0.0 < v["near_m"] < v["far_m"] <= 200.0:
        raise err("far_strip", f"needs 0 < near_m < far_m <= 200 m, got near_m {v['near_m']:g}, far_m {v['far_m']:g}")
    for k in ("pitch_margin_deg", "roll_margin_deg"):
        if not 0.0 <= v[k] <= 10.0:
            raise err(f"far_strip.{k}", f"must be within 0..10 degrees, got {v[k]:g}")
    return FarStripSpec(**v)


def tilted(pose: MountPose, pitch_deg: float, roll_deg: float) -> MountPose:
    """The mount pose of a body tilted by (pitch, roll) about the rear-axle origin (the attitude model's
    convention, :mod:`cone_perception.attitude.model`)."""
    if pitch_deg == 0.0 and roll_deg == 0.0:
        return pose
    R = attitude_rotation(pitch_deg, roll_deg)
    return MountPose.from_R_F_C(R @ pose.R_F_C(), R @ pose.position_F())


def needed_rows(camera: PinholeCamera, near_m: float, far_m: float, pitch_deg: float = 0.0,
                roll_deg: float = 0.0) -> tuple[float, float, float]:
    """(top, bottom, horizon) image rows, for the body tilted by (pitch, roll): the highest top of a tallest
    cone ``far_m`` ahead and the lowest foot of a cone ``near_m`` ahead, over the columns of the image that
    see them; the horizon's row at the image centre. NaN top / bottom where no such point is in view."""
    cam = PinholeCamera(camera.K, camera.width, camera.height, tilted(camera.pose, pitch_deg, roll_deg),
                        camera.dist_coeffs)
    pose = camera.pose  # "ahead": along the heading of the car's mount (the rest pose), from the camera
    yaw = math.radians(pose.yaw_deg)
    fwd, left = np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])
    rows = []
    for d, z, pick in ((far_m, TALLEST_CONE_M, np.min), (near_m, 0.0, np.max)):
        s = np.linspace(-4.0 * d, 4.0 * d, _SAMPLES * 4)  # lateral offsets well past any lens's view
        xy = np.array([pose.x_m, pose.y_m]) + d * fwd + s[:, None] * left
        uv, depth = cam.project(np.column_stack([xy, np.full(len(s), z)]))
        ok = (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= camera.width - 1)
        rows.append(float(pick(uv[ok, 1])) if np.any(ok) else float("nan"))
    return rows[0], rows[1], cam.horizon_v()


@dataclass(frozen=True)
class StripPlan:
    """A camera's far strip: ``height`` rows (a multiple of :data:`ROW_MULTIPLE`), its top row ``top0`` at
    the calibration's attitude, and how it moves: :meth:`top_for`."""

    height: int
    top0: int
    camera: PinholeCamera
    spec: FarStripSpec

    @property
    def rows(self) -> tuple[int, int]:
        """(V0, V1) at the calibration's attitude."""
        return self.top0, self.top0 + self.height

    def centre(self, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> float:
        top, bottom, _ = needed_rows(self.camera, self.spec.near_m, self.spec.far_m, pitch_deg, roll_deg)
        return 0.5 * (top + bottom)

    def top_for(self, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> tuple[int, bool]:
        """(top row, clamped): the strip centred on the rows needed at this attitude offset (degrees), kept
        inside the image; ``clamped`` when it had to be moved to stay inside (or the rows are not in view)."""
        if pitch_deg == 0.0 and roll_deg == 0.0:
            return self.top0, False
        c = self.centre(pitch_deg, roll_deg)
        top = int(round(c - self.height / 2.0)) if math.isfinite(c) else self.top0
        inside = min(max(top, 0), self.camera.height - self.height)
        return inside, inside != top or not math.isfinite(c)


def _span(camera: PinholeCamera, spec: FarStripSpec, multiple: int) -> tuple[float, int]:
    """(centre row at the calibration's attitude, height): the rows :func:`needed_rows` gives for ``spec``'s
    range at every attitude within its margins, centred, the height rounded up to ``multiple``."""
    top, bottom, _ = needed_rows(camera, spec.near_m, spec.far_m)
    c0 = 0.5 * (top + bottom)
    half = 0.0
    mp, mr = spec.pitch_margin_deg, spec.roll_margin_deg
    for p in (-mp, 0.0, mp):  # the attitude the rows follow may be off by up to the margins
        for r in (-mr, 0.0, mr):
            t, b, _ = needed_rows(camera, spec.near_m, spec.far_m, p, r)
            if math.isfinite(t) and math.isfinite(b):
                half = max(half, c0 - t, b - c0)
    return c0, int(math.ceil(2.0 * half / multiple)) * multiple


def plan_strip(camera: PinholeCamera, spec: FarStripSpec = DEFAULT_STRIP, source: str = "<calibration>",
               field: str = "far_strip") -> StripPlan:
    """The strip of ``camera`` (K, size, rest mount pose, lens) for ``spec``. ConfigError naming ``source``
    and ``field`` when the rows it needs (margins included) leave the image, or lie above the horizon."""
    near, far = spec.near_m, spec.far_m
    top, bottom, horizon = needed_rows(camera, near, far)
    if not (math.isfinite(top) and math.isfinite(bottom)):
        raise ConfigError(source, field, f"the camera sees no cone {near:g}-{far:g} m ahead (mount_pose, "
                                         "camera_matrix): set far_strip: off, or near_m / far_m it sees")
    if not bottom > horizon:
        raise ConfigError(source, field, f"the feet of cones {near:g} m ahead are at row {bottom:.0f}, on or above "
                                         f"the horizon (row {horizon:.0f}): the mount pose cannot be right")
    c0, height = _span(camera, spec, ROW_MULTIPLE)
    top0 = int(round(c0 - height / 2.0))
    if top0 < 0 or top0 + height > camera.height:
        raise ConfigError(source, field, f"the strip for cones {near:g}-{far:g} m ahead needs rows {top0}-{top0 + height} "
                                         f"(its margins included), outside the {camera.width}x{camera.height} image: "
                                         "check mount_pose / camera_matrix, or set far_strip near_m / far_m / margins, "
                                         "or far_strip: off")
    return StripPlan(height, top0, camera, spec)


def foot_distance(camera: PinholeCamera, row: float) -> float:
    """The distance ahead (m, along the mount's heading) whose cone feet reach down to image ``row`` (the
    lowest foot over the columns, as :func:`needed_rows`); ``row`` at or below the image's bottom: the image's
    bottom row; NaN when no foot ahead reaches the row (above the horizon)."""
    row = min(float(row), camera.height - 1.0)

    def foot(d: float) -> float:
        return needed_rows(camera, d, d + 1.0)[1]

    lo, hi = 0.05, 1000.0  # nearer: lower in the image (larger row)
    if not math.isfinite(foot(hi)) or foot(hi) > row:
        return float("nan")
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        f = foot(mid)
        if math.isfinite(f) and f <= row:
            hi = mid
        else:
            lo = mid
    return hi


def plan_band(camera: PinholeCamera, bottom_row: int, top_m: float, downscale: int, spec: FarStripSpec = DEFAULT_STRIP,
              source: str = "<calibration>", field: str = "band_rows") -> StripPlan:
    """The band placed from the calibration (``band_rows: auto``): from the top of the tallest cone ``top_m``
    ahead down to the feet of the cones at ``bottom_row`` (the hand-set crop's bottom: how near the car must see),
    with ``spec``'s attitude margins (``near_m`` / ``far_m`` are replaced), the height a multiple of
    :data:`ROW_MULTIPLE` rows at the band's scale (``downscale``); kept inside the image (a band whose margins
    reach past the image's bottom ends there: no rows exist below it). ConfigError naming ``source`` and
    ``field`` when the camera sees no cone feet at ``bottom_row`` or the band would need more rows than the image."""
    near = foot_distance(camera, bottom_row)
    if not math.isfinite(near) or not near < top_m:
        raise ConfigError(source, field, f"no cone feet ahead at row {bottom_row} nearer than {top_m:g} m (mount_pose, "
                                         "camera_matrix, crop.v1): set the band's rows by hand")
    band = FarStripSpec(near, float(top_m), spec.pitch_margin_deg, spec.roll_margin_deg)
    top, _, _ = needed_rows(camera, near, top_m)
    if not math.isfinite(top):
        raise ConfigError(source, field, f"the camera sees no cone {top_m:g} m ahead: set the band's rows by hand")
    c0, height = _span(camera, band, ROW_MULTIPLE * int(downscale))
    if height > camera.height:
        raise ConfigError(source, field, f"the band for cones {near:.1f}-{top_m:g} m ahead needs {height} rows "
                                         f"(margins included), more than the image's {camera.height}")
    top0 = min(max(int(round(c0 - height / 2.0)), 0), camera.height - height)
    return StripPlan(height, top0, camera, band)


#: The smallest cone (px tall at the detector's input) a coarser band may leave to the detector: a small cone at
#: the near band's top must be at least this tall there (boxes >= 12 px are where the detector is sure: issue 26's
#: no-loss class; docs/detector.md "Row-scaled band").
SPLIT_MIN_PX = 12.0
#: The near band's downscale (a quarter of full resolution: twice the band's 2).
SPLIT_DOWNSCALE = 4
SMALLEST_CONE_M = min(h for h, _, _ in CONE_SIZE_M.values())


@dataclass(frozen=True)
class SplitPlan:
    """The band in two: its upper rows ``upper`` (V0, V1) at the band's own downscale and its lower rows ``near``
    (V0, V1) at ``near_downscale``; the two overlap by at least a large cone's height at the split, so every cone
    is whole in one of them (:func:`plan_split`). ``split_m``: the distance ahead whose small cones are
    ``min_px`` tall in the near band (nearer ones are larger)."""

    upper: tuple[int, int]
    near: tuple[int, int]
    near_downscale: int
    split_m: float
    min_px: float


def cone_height_px(camera: PinholeCamera, d_m: float, height_m: float) -> float:
    """Image height (px) of a cone ``height_m`` tall ``d_m`` ahead at the image's centre column (pinhole, the rest
    attitude): its foot's row minus its top's."""
    pose = camera.pose
    yaw = math.radians(pose.yaw_deg)
    xy = np.array([pose.x_m + d_m * math.cos(yaw), pose.y_m + d_m * math.sin(yaw)])
    uv, depth = camera.project(np.array([[*xy, 0.0], [*xy, height_m]]))
    return float(uv[0, 1] - uv[1, 1]) if np.all(depth > 0) else float("nan")


def plan_split(camera: PinholeCamera, band_rows: tuple[int, int], downscale: int, spec: FarStripSpec = DEFAULT_STRIP,
               near_downscale: int = SPLIT_DOWNSCALE, min_px: float = SPLIT_MIN_PX, edge_px: float = 2.0,
               source: str = "<calibration>", field: str = "band_split") -> SplitPlan:
    """The band ``band_rows`` (its rows at ``downscale``) split in two from the calibration (``band_split: auto``):
    the near rows, where every cone is large, at ``near_downscale``. The split distance is where a small cone is
    ``min_px`` tall at ``near_downscale``; the upper band (the band's top, ``downscale``) reaches down to the lowest
    foot of such a cone within ``spec``'s attitude margins (plus ``edge_px``: a box touching an inner edge is a cut
    cone and dropped), the near band (down to the band's bottom) up to the top of a large cone standing at the upper
    band's bottom; heights are multiples of 32 rows at each band's scale, inside the band. ConfigError naming
    ``source`` and ``field`` when no cone is that large in the band's rows (nothing to split) or the two bands would
    not overlap by a cone."""
    v0, v1 = int(band_rows[0]), int(band_rows[1])
    if near_downscale <= downscale:
        raise ConfigError(source, field, f"the near band's downscale {near_downscale} must be coarser than the band's {downscale}")
    need = min_px * near_downscale  # full-resolution px a small cone needs in the near band
    # the distance ahead where a small cone is `need` px tall (nearer: taller), searched from the nearest feet in
    # view (nearer points leave the image, where a lens model's projection no longer holds)
    lo, hi = foot_distance(camera, camera.height - 1.0), 1000.0
    if not (math.isfinite(lo) and cone_height_px(camera, lo, SMALLEST_CONE_M) >= need):
        raise ConfigError(source, field, f"no cone ahead is {need:g} px tall (mount_pose, camera_matrix): nothing to "
                                         "run at the coarser scale")
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        h = cone_height_px(camera, mid, SMALLEST_CONE_M)
        lo, hi = (mid, hi) if math.isfinite(h) and h >= need else (lo, mid)
    split_m = lo
    feet = [needed_rows(camera, split_m, split_m + 1.0, p, r)[1]
            for p in (-spec.pitch_margin_deg, 0.0, spec.pitch_margin_deg)
            for r in (-spec.roll_margin_deg, 0.0, spec.roll_margin_deg)]
    feet = [f for f in feet if math.isfinite(f)]
    step_up, step_near = ROW_MULTIPLE * int(downscale), ROW_MULTIPLE * int(near_downscale)
    if not feet or max(feet) + edge_px >= v1 - step_up:
        raise ConfigError(source, field, f"small cones {split_m:.1f} m ahead ({need:g} px tall) stand at or below row "
                                         f"{max(feet) if feet else float('nan'):.0f}, within {step_up} rows of the band's "
                                         f"bottom {v1}: too little to run at the coarser scale")
    bottom = max(feet) + edge_px  # the upper band reaches below every such foot
    u1 = min(v0 + int(math.ceil((bottom - v0) / step_up)) * step_up, v1)
    d_up = foot_distance(camera, u1)  # a large cone with its foot at the upper band's bottom: whole in the near band
    top = needed_rows(camera, d_up, d_up)[0] - edge_px if math.isfinite(d_up) else float("nan")
    if not math.isfinite(top):
        raise ConfigError(source, field, f"no cone feet ahead at row {u1}: the split needs cones below the horizon")
    n0 = max(v1 - int(math.ceil((v1 - top) / step_near)) * step_near, v0)
    while (v1 - n0) % near_downscale:  # inside the band, divisible by its downscale
        n0 += 1
    if not n0 < u1 - edge_px:
        raise ConfigError(source, field, f"the near band {n0}-{v1} and the upper band {v0}-{u1} do not overlap")
    return SplitPlan((v0, u1), (n0, v1), int(near_downscale), split_m, float(min_px))


__all__ = ["DEFAULT_STRIP", "FarStripSpec", "ROW_MULTIPLE", "StripPlan", "TALLEST_CONE_M", "foot_distance",
           "needed_rows", "plan_band", "plan_split", "plan_strip", "SplitPlan", "SPLIT_DOWNSCALE",
           "SPLIT_MIN_PX", "cone_height_px", "strip_spec_from_yaml", "tilted"]
