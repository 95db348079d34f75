"""What the validation suite (``cone-perception validate``, :mod:`.suite`) holds: a fixed list of rendered drives
(:data:`DRIVES`) spanning what ``synth bag`` can vary, and the real labelled sets in the repository's reach
(:data:`REAL_SETS`).

**Judging seeds and tuning seeds.** The seeds of :data:`DRIVES` are the judging seeds: every one of them lies in
:data:`JUDGING_SEEDS` (410000-419999). Nothing is tuned on them: a threshold, a model or a default chosen while
looking at these drives is judged on drives it has seen. Tuning uses other seeds; :func:`tuning_drives`
(``validate --tuning``) gives the same drives with seeds in :data:`TUNING_SEEDS` (910000-919999), disjoint by
construction, with the same variety (camera, scene, motion; a low-sun drive's seed is searched for the same way).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import ConfigError
from ..geometry.camera import MountPose
from ..synth.config import SynthConfig
from ..synth.writers import bag_scene

#: Every drive's length and frame rate: few frames per drive keep the whole suite within 30 minutes on 2 cores.
SECONDS = 4.0
FPS = 10.0
#: The seeds the suite judges on (half-open range); tuning never uses one of them.
JUDGING_SEEDS = range(410_000, 420_000)
#: The tuning list's seeds: the judging seed plus :data:`TUNING_OFFSET`.
TUNING_OFFSET = 500_000
TUNING_SEEDS = range(JUDGING_SEEDS.start + TUNING_OFFSET, JUDGING_SEEDS.stop + TUNING_OFFSET)
#: A low-sun drive's sun stands at most this high (degrees; the generator draws 15-65).
LOW_SUN_DEG = 22.0
#: How many seeds from a low-sun drive's own a search for a low sun may go (each drive's seeds are 100 apart).
LOW_SUN_TRIES = 100


@dataclass(frozen=True)
class DriveSpec:
    """One rendered drive of the suite: ``synth bag`` options (sizes in px, angles in degrees, m, m/s).
    ``low_sun``: the drive's seed is the first from ``seed`` on whose scene has the sun at most
    :data:`LOW_SUN_DEG` high (:func:`drive_seed`)."""

    name: str
    seed: int
    note: str
    size: tuple[int, int] = (1920, 1080)
    hfov_deg: float = 90.0
    height_m: float = 1.2
    pitch_deg: float = 10.0
    k1: float = 0.0
    k2: float = 0.0
    jitter: bool = True
    car_motion: bool = False  # braking / acceleration pitch, cornering roll, bumps, grade changes (slopes)
    track: str = "autocross"
    speed_mps: float = 8.0
    paint_lines: str = "random"
    nose_prob: float = 0.5
    missing_frac: float = 0.0
    stray: int = 0
    compressed: bool = False  # JPEG CompressedImage instead of YUYV
    low_sun: bool = False

    def config(self, seed: int | None = None) -> SynthConfig:
        """The :class:`SynthConfig` of this drive (``seed``: instead of the drive's own)."""
        return SynthConfig(width=self.size[0], height=self.size[1], hfov_deg=self.hfov_deg,
                           mount=MountPose(height_m=self.height_m, pitch_deg=self.pitch_deg), k1=self.k1, k2=self.k2,
                           seed=self.seed if seed is None else seed, jitter=self.jitter, car_motion=self.car_motion,
                           nose_prob=self.nose_prob, track_kinds=(self.track,), missing_frac=self.missing_frac,
                           stray=self.stray, paint_lines=self.paint_lines)

    def describe(self) -> str:
        """One line: camera, then what the scene and the motion vary."""
        w, h = self.size
        cam = f"{w}x{h} hfov {self.hfov_deg:g} h {self.height_m:g} m pitch {self.pitch_deg:g}"
        if self.k1 or self.k2:
            cam += f" k1 {self.k1:g}" + (f" k2 {self.k2:g}" if self.k2 else "")
        scene = [self.track, f"{self.speed_mps:g} m/s"]
        scene += [t for t, on in (("car motion", self.car_motion), ("no jitter", not self.jitter),
                                  ("low sun", self.low_sun), ("JPEG", self.compressed)) if on]
        if self.paint_lines != "random":
            scene.append(f"{self.paint_lines} paint")
        if self.nose_prob in (0.0, 1.0):
            scene.append("nose" if self.nose_prob else "no nose")
        if self.missing_frac or self.stray:
            scene.append(f"missing {self.missing_frac:g}, stray {self.stray}")
        return f"{cam}; {', '.join(scene)}"


def _d(i: int, name: str, note: str, sun_search: int = 0, **kw) -> DriveSpec:
    """Drive ``i``'s seed: 100 apart from the next; a low-sun drive's is its search's result, ``sun_search`` on."""
    return DriveSpec(name, JUDGING_SEEDS.start + 100 * i + sun_search, note, **kw)


_HELD_OUT = dict(size=(2048, 1536), hfov_deg=59.0, height_m=1.03, pitch_deg=15.0, k1=-0.126)

#: The suite's drives (judging seeds). Names say the camera (rows, hfov) and what else varies.
DRIVES: tuple[DriveSpec, ...] = (
    _d(1, "base-a", "the generator's default camera, one scene look"),
    _d(2, "base-b", "the default camera, another look"),
    _d(3, "base-c", "the default camera, a third look"),
    _d(4, "heldout-cam", "like the held-out sharp camera (issue 41)", **_HELD_OUT),
    _d(5, "heldout-cam-motion", "the held-out-like camera, braking and slopes", car_motion=True, **_HELD_OUT),
    _d(6, "heldout-cam-lowsun", "the held-out-like camera, low sun", sun_search=1, low_sun=True, **_HELD_OUT),
    _d(7, "heldout-cam-yellow", "the held-out-like camera, yellow painted lines", paint_lines="yellow", **_HELD_OUT),
    _d(8, "720-hfov100", "small wide camera", size=(1280, 720), hfov_deg=100.0, height_m=1.0, pitch_deg=8.0),
    _d(9, "720-hfov70", "small narrow camera, level", size=(1280, 720), hfov_deg=70.0, height_m=1.1, pitch_deg=6.0),
    _d(10, "1536-hfov60-high", "large narrow camera, high mount", size=(2048, 1536), hfov_deg=60.0, height_m=1.5,
       pitch_deg=12.0),
    _d(11, "1536-hfov100-barrel", "large wide camera, barrel distortion", size=(2048, 1536), hfov_deg=100.0,
       k1=-0.15, k2=0.02),
    _d(12, "1200-hfov80-pitch14", "4:3 camera looking down", size=(1600, 1200), hfov_deg=80.0, pitch_deg=14.0),
    _d(13, "960-hfov75-low", "4:3 camera, low mount", size=(1280, 960), hfov_deg=75.0, height_m=0.9, pitch_deg=9.0),
    _d(14, "1080-pitch18-low", "steep pitch, low mount", hfov_deg=85.0, height_m=0.8, pitch_deg=18.0),
    _d(15, "1080-pitch4-high", "nearly level, high mount", hfov_deg=95.0, height_m=1.35, pitch_deg=4.0),
    _d(16, "1080-barrel", "barrel distortion", hfov_deg=95.0, k1=-0.2, k2=0.05),
    _d(17, "1080-pincushion", "pincushion distortion", hfov_deg=80.0, k1=0.08),
    _d(18, "1080-nojitter", "no body jitter", jitter=False),
    _d(19, "1080-braking-fast", "braking and slopes at 12 m/s", car_motion=True, speed_mps=12.0),
    _d(20, "1080-braking-slow", "braking and slopes at 5 m/s", car_motion=True, speed_mps=5.0),
    _d(21, "1080-yellow-paint", "yellow painted lines in the scene", paint_lines="yellow"),
    _d(22, "1080-white-paint", "white painted lines in the scene", paint_lines="white"),
    _d(23, "1080-lowsun", "low sun", sun_search=23, low_sun=True),
    _d(24, "720-lowsun-wide", "low sun, small wide camera", sun_search=1, low_sun=True, size=(1280, 720), hfov_deg=100.0),
    _d(25, "1080-skidpad", "the skidpad", track="skidpad", speed_mps=6.0),
    _d(26, "1080-accel", "the acceleration track, fast", track="acceleration", speed_mps=14.0),
    _d(27, "1080-nose", "the car's nose in view", nose_prob=1.0),
    _d(28, "1440-hfov65-k1", "narrow 4:3 camera near the held-out one", size=(1440, 1080), hfov_deg=65.0, height_m=1.05,
       pitch_deg=13.0, k1=-0.1),
    _d(29, "1080-missing-stray", "cones missing from the course, stray cones beside it", missing_frac=0.1, stray=3),
    _d(30, "1080-jpeg", "JPEG frames (CompressedImage)", compressed=True),
)
#: ``validate --quick``: a handful of the drives, across cameras and scenes.
QUICK: tuple[str, ...] = ("base-a", "heldout-cam", "720-hfov100", "1080-braking-fast", "1080-lowsun")


def tuning_drives(drives: tuple[DriveSpec, ...] = DRIVES) -> tuple[DriveSpec, ...]:
    """The drives with tuning seeds (:data:`TUNING_SEEDS`) instead of the judging ones, named ``tune-NAME``."""
    return tuple(replace(d, name=f"tune-{d.name}", seed=d.seed + TUNING_OFFSET) for d in drives)


def sun_elevation_deg(drive: DriveSpec, seed: int) -> float:
    """How high the sun of ``drive``'s scene with ``seed`` stands (degrees), drawn as ``synth bag`` draws it."""
    look = bag_scene(drive.config(seed), FPS, drive.speed_mps, drive.track)[3]
    return float(np.degrees(np.arcsin(np.clip(look.sun_W[2], -1.0, 1.0))))


def drive_seed(drive: DriveSpec) -> int:
    """The seed a drive renders with: its own, or for a low-sun drive the first from it on whose sun stands at
    most :data:`LOW_SUN_DEG` high (ConfigError naming the drive when none of :data:`LOW_SUN_TRIES` does)."""
    if not drive.low_sun:
        return drive.seed
    for seed in range(drive.seed, drive.seed + LOW_SUN_TRIES):
        if sun_elevation_deg(drive, seed) <= LOW_SUN_DEG:
            return seed
    raise ConfigError(drive.name, "low_sun", f"no seed in {drive.seed}-{drive.seed + LOW_SUN_TRIES - 1} has the sun "
                                             f"below {LOW_SUN_DEG:g} degrees")


@dataclass(frozen=True)
class RealSet:
    """A real labelled set scored as the car runs its camera: ``detect`` with the band (``crop`` rows at
    ``downscale``) and the far strip (``far_rows``), then ``eval`` in the band. ``path``: relative to the
    working directory (the repository's root); ``build``: how to make it when it is missing; ``band_split``: the
    set's split of its band (``N0,U1``) where the suite judges a split band (the clips have no calibration to place
    ``auto`` from)."""

    name: str
    path: str
    gt_names: str | None  # the labels' class names in order (None: from the set's data.yaml)
    crop: tuple[int, int]
    downscale: int
    far_rows: str
    build: str
    band_split: str = "416,544"


REAL_SETS: tuple[RealSet, ...] = (
    RealSet("real_val_1080", "data/real_val_1080", "blue_cone,large_orange_cone,orange_cone,yellow_cone", (96, 672), 2,
            "240,432", "cone-perception data restore-aspect ../shared/datasets/bgracing-real data/real_val_1080 --width "
                       "1920 --clips autox4,autox2,accel --names blue_cone,large_orange_cone,orange_cone,yellow_cone"),
)
