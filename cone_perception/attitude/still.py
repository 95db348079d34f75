"""The still test (``ImageAttitudeConfig`` ``still_*``): is the body still on level ground, by the scatter of what it
watches against what a still body would give? The image fit's (:meth:`~.image.ImageAttitude.motion_weight`) and, in
``fused``, the IMU's (:class:`~.fused.ImuStillTest`). ROS-free."""

from __future__ import annotations

import numpy as np


class StillTest:
    """The still test (``ImageAttitudeConfig`` ``still_*``) on what it watches (pitch, roll; degrees): the running means
    of the readings ``m1``, their squares ``m2`` and the variance ``mv`` they would scatter by on a still body, over
    ``still_frames`` frames of ``frame_s``; the image fit's (:meth:`ImageAttitude.motion_weight`) and the IMU's in
    ``fused`` (:class:`~.fused.ImuStillTest`)."""

    def __init__(self, cfg):  # an ImageAttitudeConfig (its still_* fields)
        self.cfg, self.n, self.m1, self.m2, self.mv = cfg, 0.0, np.zeros(2), np.zeros(2), np.zeros(2)

    def fold(self, z: np.ndarray, var: np.ndarray, k: float = 1.0) -> None:
        """One reading ``z`` and its variance, from a frame ``k`` frames of ``frame_s`` long."""
        self.n += k
        a = k / min(self.n, self.cfg.still_frames)
        self.m1 += a * (z - self.m1)
        self.m2 += a * (z * z - self.m2)
        self.mv += a * (var - self.mv)

    @property
    def judged(self) -> bool:
        """Enough readings in (``still_min_frames``) for :meth:`verdict`."""
        return self.n >= self.cfg.still_min_frames

    def verdict(self) -> float:
        """1 = moving or leaning (the readings' spread above ``still_ratio`` of what a still body gives, or their mean
        beyond ``still_max_mean_deg``), 0 = still, a ramp between."""
        c = self.cfg
        spread = np.sqrt(np.maximum(self.m2 - self.m1**2, 0.0) / np.maximum(self.mv, 1e-12))
        moving = (np.max(spread) - (c.still_ratio - c.still_ramp)) / c.still_ramp
        sloped = (np.max(np.abs(self.m1)) - c.still_max_mean_deg) / (0.5 * c.still_max_mean_deg)
        return float(np.clip(max(moving, sloped), 0.0, 1.0))
