"""Where the camera can see a cone (:class:`FieldOfView`): the tracker lowers a track's certainty only where its cone
should have been seen. ROS-free."""

from __future__ import annotations

import numpy as np

from ..classes import CONE_SIZE_M
from ..mapping import ConeMapper


class FieldOfView:
    """Where the camera can see a cone: ground points whose foot pixel lies inside the band (with a
    margin) and within ``max_range_m``.

    ``ground_to_pixels`` maps (N, 2) rear_axle m to (N, 2) full-image px (NaN behind the camera),
    e.g. :meth:`cone_perception.mapping.ConeMapper.ground_to_pixels`. ``cone_height_frac``: a cone's height over the
    camera's (the tallest cone's); given, a cone is cut off by the band's top where its tip (its foot row less its
    height in px, which is this fraction of the foot's rows below the horizon) lies above the band's top margin, so a
    far cone 10 px tall is in view to the band's top; None: its foot must lie three margins below the top.
    """

    def __init__(self, ground_to_pixels, band_px: tuple[float, float, float, float], max_range_m: float,
                 margin_frac: float = 0.03, min_range_m: float = 0.0, cone_height_frac: float | None = None):
        self.ground_to_pixels = ground_to_pixels
        u0, v0, u1, v1 = (float(x) for x in band_px)
        mu, mv = margin_frac * (u1 - u0), margin_frac * (v1 - v0)
        self.cone_height_frac = cone_height_frac
        # without the cone's height: a cone whose foot is near the top of the band is cut off by it
        self.u0, self.u1, self.v0, self.v1 = u0 + mu, u1 - mu, v0 + (mv if cone_height_frac else 3 * mv), v1 - mv
        self.max_range_m = float(max_range_m)
        self.min_range_m = float(min_range_m)

    @classmethod
    def from_calibration(cls, calib, margin_frac: float = 0.03) -> "FieldOfView":
        c = calib.crop
        pose = calib.mount_pose
        frac = max(h for h, _, _ in CONE_SIZE_M.values()) / pose.height_m if pose is not None else None
        return cls(ConeMapper(calib).ground.ground_to_pixels, (c.u0, c.v0, c.u1, c.v1), calib.max_range_m, margin_frac,
                   cone_height_frac=frac)

    def visible(self, xy_m: np.ndarray) -> np.ndarray:
        """(N, 2) rear_axle m -> (N,) bool."""
        return self.view(xy_m)[0]

    def view(self, xy_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) rear_axle m -> ((N,) in view, (N,) within the view's sides and above its bottom: in view, or beyond
        its far end (the tip above the band's top, or beyond ``max_range_m``), where it may come into view)."""
        xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        if len(xy) == 0:
            return np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)
        uv = self.ground_to_pixels(xy)
        r = np.hypot(xy[:, 0], xy[:, 1])
        top = uv[:, 1]
        if self.cone_height_frac:  # the tip's row: the foot's less the cone's height (horizon: the same ray far off)
            top = top - (top - self.ground_to_pixels(xy * (1e4 / np.maximum(r, 1e-6))[:, None])[:, 1]) * self.cone_height_frac
        with np.errstate(invalid="ignore"):
            sides = (uv[:, 0] >= self.u0) & (uv[:, 0] < self.u1) & (uv[:, 1] < self.v1) & (r >= self.min_range_m)
            return sides & (top >= self.v0) & (r <= self.max_range_m), sides
