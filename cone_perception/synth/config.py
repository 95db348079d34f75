"""The settings of ``cone-perception synth``: camera, mount and scene switches (:class:`SynthConfig`), and what
follows from them: the camera, its exact calibration, the renderer, the tracks."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..classes import CLASS_NAMES
from ..crop import CropSpec
from ..errors import ConfigError
from ..geometry.calib import (
    DEFAULT_MAX_RANGE_M, RECOMMENDED_FOOT_OFFSET_M, RECOMMENDED_FOOT_POINTS, Calibration, save_calibration,
)
from ..geometry.camera import MountPose, PinholeCamera, default_intrinsics
from .look import PAINT_LINES, RenderOptions
from .render import Renderer
from .scene import ground_visible
from .track import TRACK_KINDS, Track, make_track


@dataclass
class SynthConfig:
    """Camera, mount and scene switches shared by all outputs."""

    width: int = 1920
    height: int = 1080
    hfov_deg: float = 90.0
    mount: MountPose = field(default_factory=MountPose)
    k1: float = 0.0
    k2: float = 0.0
    seed: int = 0
    jitter: bool = True
    nose_prob: float = 0.5
    photometric: bool = True
    track_kinds: tuple[str, ...] = TRACK_KINDS
    missing_frac: float = 0.0
    stray: int = 0
    knocked_frac: float = 0.0
    car_motion: bool = False  # bags: speed profile, braking pitch, cornering roll, bumps, grade changes (synth/motion.py)
    vary_mount: bool = False  # datasets: new hfov / pitch / height per track (calib.yaml is then the nominal only)
    paint_lines: str = "random"  # the ground's painted lines: random, or yellow / white in every look (look.PAINT_LINES)

    def validate(self) -> None:
        """Raise :class:`ConfigError` for impossible parameters, before any work."""
        if self.width <= 0 or self.height <= 0:
            raise ConfigError("--size", None, f"width and height must be > 0, got {self.width}x{self.height}")
        if self.width < 64 or self.height < 64 or self.width % 4 or self.height % 4:
            raise ConfigError("--size", None, f"must be at least 64x64 and divisible by 4, got {self.width}x{self.height}")
        if not 10.0 <= self.hfov_deg <= 150.0:
            raise ConfigError("--hfov", None, f"must be within 10..150 degrees, got {self.hfov_deg}")
        if not self.mount.height_m > 0:
            raise ConfigError("--height", None, f"camera height must be > 0 m, got {self.mount.height_m}")
        if not 0.0 <= self.nose_prob <= 1.0:
            raise ConfigError("--nose-prob", None, f"must be within 0..1, got {self.nose_prob}")
        if self.paint_lines not in PAINT_LINES:
            raise ConfigError("--paint-lines", None, f"unknown value {self.paint_lines!r}; known: {', '.join(PAINT_LINES)}")
        for k in self.track_kinds:
            if k not in TRACK_KINDS:
                raise ConfigError("--tracks", None, f"unknown track kind {k!r}; known: {', '.join(TRACK_KINDS)}")
        for name, v in (("--missing", self.missing_frac), ("--knocked", self.knocked_frac)):
            if not 0.0 <= v <= 1.0:
                raise ConfigError(name, None, f"must be a fraction within 0..1, got {v}")
        if self.stray < 0:
            raise ConfigError("--stray", None, f"must be >= 0, got {self.stray}")
        if not self.track_kinds:
            raise ConfigError("--tracks", None, "need at least one track kind")
        if not ground_visible(self.camera(), 60.0):
            raise ConfigError(
                "--pitch",
                None,
                f"the camera (pitch {self.mount.pitch_deg} deg, height {self.mount.height_m} m, hfov {self.hfov_deg} deg) "
                "sees no ground within 60 m: it looks at the sky",
            )

    def camera(self) -> PinholeCamera:
        dist = np.array([self.k1, self.k2, 0.0, 0.0, 0.0]) if (self.k1 or self.k2) else np.zeros(0)
        return PinholeCamera(default_intrinsics(self.width, self.height, self.hfov_deg), self.width, self.height, self.mount, dist)

    def calibration(self) -> Calibration:
        """The exact calibration of the nominal mount: ``H_S_B = H_F_B`` of the camera, ``T_F_S`` = identity."""
        cam = self.camera()
        W, H = self.width, self.height
        v0 = int(np.clip(np.floor(cam.horizon_v() / 4) * 4, 0, H - 8))
        crop = CropSpec(v0, H, 0, W, 2)  # the road band: horizon row (rounded down to 4) to the bottom
        m = self.mount
        return Calibration(
            camera="synth",
            image_width=W,
            image_height=H,
            H_S_B=cam.H_F_B(),
            T_F_S=np.eye(3),
            crop=crop,
            foot_points=tuple(RECOMMENDED_FOOT_POINTS[n] for n in CLASS_NAMES),
            foot_offset_m=tuple(RECOMMENDED_FOOT_OFFSET_M[n] for n in CLASS_NAMES),
            max_range_m=DEFAULT_MAX_RANGE_M,
            pixel_sigma_u=1.5,
            pixel_sigma_v=1.5,
            camera_matrix=cam.K,
            dist_coeffs=cam.dist_coeffs if cam.dist_coeffs.size else None,
            mount_pose=m,
            extra={
                "mount": {
                    "x_m": m.x_m, "y_m": m.y_m, "height_m": m.height_m, "pitch_deg": m.pitch_deg,
                    "roll_deg": m.roll_deg, "yaw_deg": m.yaw_deg, "hfov_deg": self.hfov_deg,
                },
            },
        )

    def save_calibration(self, path: Path) -> Path:
        return save_calibration(self.calibration(), path, header="Synthetic camera (cone-perception synth): exact H_F_B of the nominal mount")

    def renderer(self, **opts) -> Renderer:
        return Renderer(self.camera(), RenderOptions(nose_prob=self.nose_prob, photometric=self.photometric,
                                                       paint_lines=self.paint_lines, **opts))

    def varied(self, rng: np.random.Generator) -> "SynthConfig":
        """A copy with a random viewpoint: hfov 70..120 deg, pitch -4..+16 deg around this one, height +-0.3 m.

        Real on-board cameras look further down than the nominal mount (horizon 15-25 % below the
        top of the frame), hence the asymmetric pitch range.
        """
        m = self.mount
        for _ in range(20):
            cfg = replace(
                self,
                hfov_deg=float(rng.uniform(70.0, 120.0)),
                mount=replace(
                    m,
                    pitch_deg=float(m.pitch_deg + rng.uniform(-4.0, 16.0)),
                    height_m=float(max(m.height_m + rng.uniform(-0.3, 0.3), 0.5)),
                ),
            )
            if ground_visible(cfg.camera(), 60.0):
                return cfg
        return self

    def camera_record(self) -> dict:
        """Camera of a frame for gt.jsonl: K and mount."""
        m = self.mount
        return {
            "K": [[round(float(x), 6) for x in row] for row in self.camera().K],
            "dist_coeffs": [self.k1, self.k2, 0.0, 0.0, 0.0],
            "mount": {"x_m": m.x_m, "y_m": m.y_m, "height_m": m.height_m, "pitch_deg": m.pitch_deg, "roll_deg": m.roll_deg, "yaw_deg": m.yaw_deg},
        }

    def track(self, index: int, rng: np.random.Generator) -> Track:
        kind = self.track_kinds[0] if len(self.track_kinds) == 1 else rng.choice(
            self.track_kinds, p=_kind_weights(self.track_kinds)
        )
        return make_track(str(kind), int(rng.integers(0, 2**31)), self.missing_frac, self.stray, self.knocked_frac)


def _kind_weights(kinds: tuple[str, ...]) -> np.ndarray:
    w = np.array([{"autocross": 0.7, "skidpad": 0.15, "acceleration": 0.15}[k] for k in kinds])
    return w / w.sum()
