"""The attitude from an IMU's orientation relative to its rest attitude (:class:`ImuAttitude`), and
that rest attitude measured from a standing recording (:func:`imu_rest`). ROS-free.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError

QUAT_NORM_TOL = 0.01
#: An IMU sample older than this at a frame's stamp is not used for that frame.
IMU_MAX_AGE_NS = 100_000_000


def rpy_from_quaternion(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """(roll, pitch, yaw) radians of a unit quaternion, R = Rz(yaw) Ry(pitch) Rx(roll) (REP 103)."""
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


@dataclass
class ImuCounts:
    """IMU messages used and dropped by cause, and frames without a fresh IMU sample."""

    used: int = 0
    dropped_nan: int = 0
    dropped_quaternion_norm: int = 0
    dropped_out_of_order: int = 0
    stale_at_frame: int = 0

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


class ImuAttitude:
    """Body attitude from an IMU's orientation, relative to the rest attitude (the IMU's reading on
    the level ground of the calibration, ``rest_deg`` = (pitch, roll)), interpolated to frame stamps.

    The IMU frame's axes are the ``rear_axle`` axes (mount it so, or rotate before).
    """

    def __init__(self, rest_deg: tuple[float, float] = (0.0, 0.0), max_age_ns: int = IMU_MAX_AGE_NS,
                 sigma_deg: float = 0.1, keep: int = 200):
        self.rest = np.asarray(rest_deg, dtype=np.float64)
        self.max_age_ns = int(max_age_ns)
        self.sigma_deg = float(sigma_deg)
        self.keep = keep
        self.stamps: list[int] = []
        self.values: list[np.ndarray] = []  # (pitch, roll) degrees relative to rest
        self.counts = ImuCounts()

    def add(self, stamp_ns: int, quat_xyzw) -> bool:
        """Add one IMU orientation; returns False (and counts why) for a NaN, a quaternion far from unit
        length, or a stamp older than the last one."""
        q = np.asarray(quat_xyzw, dtype=np.float64)
        if q.shape != (4,) or not np.all(np.isfinite(q)):
            self.counts.dropped_nan += 1
            return False
        if abs(float(np.linalg.norm(q)) - 1.0) > QUAT_NORM_TOL:
            self.counts.dropped_quaternion_norm += 1
            return False
        if self.stamps and stamp_ns < self.stamps[-1]:
            self.counts.dropped_out_of_order += 1
            return False
        roll, pitch, _ = rpy_from_quaternion(*(q / np.linalg.norm(q)))
        self.stamps.append(int(stamp_ns))
        self.values.append(np.degrees([pitch, roll]) - self.rest)
        if len(self.stamps) > self.keep:
            del self.stamps[: -self.keep], self.values[: -self.keep]
        self.counts.used += 1
        return True

    def at(self, stamp_ns: int | None, count: bool = True) -> np.ndarray | None:
        """(pitch, roll) degrees at ``stamp_ns``: interpolated between the samples around it, else the
        newest one before it; None (counted in ``stale_at_frame`` unless ``count`` is False: a second read
        of the same frame) without a sample within ``max_age_ns``."""
        if stamp_ns is None or not self.stamps:
            self.counts.stale_at_frame += int(count)
            return None
        i = bisect.bisect_right(self.stamps, stamp_ns)  # first sample after the stamp
        if i == 0:  # every sample is newer than the frame
            if self.stamps[0] - stamp_ns <= self.max_age_ns:
                return self.values[0].copy()
            self.counts.stale_at_frame += int(count)
            return None
        t0, v0 = self.stamps[i - 1], self.values[i - 1]
        if i < len(self.stamps):
            t1, v1 = self.stamps[i], self.values[i]
            if t1 - t0 <= 2 * self.max_age_ns and t1 > t0:
                return v0 + (v1 - v0) * ((stamp_ns - t0) / (t1 - t0))
        if stamp_ns - t0 > self.max_age_ns:
            self.counts.stale_at_frame += int(count)
            return None
        return v0.copy()


#: Rest capture (``cone-perception imu-rest``): at least this many usable samples, and a car that stands
#: still: angular rate and acceleration (each axis) and the pitch / roll readings scatter at most this much
#: (1-sigma over the window; an IMU's noise is a few tenths of a degree/s and a few cm/s^2).
IMU_REST_MIN_SAMPLES = 20
IMU_REST_MAX_RATE_SD_DPS = 0.5
IMU_REST_MAX_ACCEL_SD = 0.2
IMU_REST_MAX_ANGLE_SD_DEG = 0.1


@dataclass
class ImuRest:
    """The IMU's pitch and roll (degrees) with the car at rest: the ``imu_rest_deg`` of the nodes."""

    pitch_deg: float
    roll_deg: float
    sd_pitch_deg: float
    sd_roll_deg: float
    n: int  # samples used
    seconds: float  # the window they span
    rate_sd_dps: float  # largest 1-sigma of the angular rate over the three axes (NaN without rates)
    accel_sd: float  # m/s^2, likewise
    dropped: dict  # IMU messages dropped by cause (NaN, quaternion norm, out of order)


def imu_rest(stamps_ns, quats_xyzw, rates_rad_s=None, accels=None, source: str = "imu") -> ImuRest:
    """The rest attitude from IMU samples of a car standing still: ``stamps_ns`` (N,), ``quats_xyzw``
    (N, 4), optional ``rates_rad_s`` (N, 3) and ``accels`` (N, 3) m/s^2. Samples with NaN or a quaternion
    off unit length are dropped (as :meth:`ImuAttitude.add`, counted).

    Raises :class:`ConfigError` (naming ``source``) with too few samples or when the car moved.
    """
    acc = ImuAttitude(keep=1 << 30)
    ok = np.array([acc.add(int(t), q) for t, q in zip(stamps_ns, quats_xyzw)], dtype=bool)
    dropped = {k.removeprefix("dropped_"): v for k, v in acc.counts.as_dict().items() if k.startswith("dropped_") and v}
    why = f" (dropped: {', '.join(f'{k} {v}' for k, v in dropped.items())})" if dropped else ""
    n = int(ok.sum())
    if n < IMU_REST_MIN_SAMPLES:
        raise ConfigError(source, None, f"only {n} usable IMU samples in the window, need >= {IMU_REST_MIN_SAMPLES}{why}")
    v = np.asarray(acc.values)
    sd = v.std(axis=0)

    def _sd(x, scale=1.0):
        if x is None:
            return float("nan")
        x = np.asarray(x, dtype=np.float64)[ok] * scale
        x = x[np.all(np.isfinite(x), axis=1)]
        return float(np.max(x.std(axis=0))) if len(x) > 1 else float("nan")

    rate_sd, accel_sd = _sd(rates_rad_s, 180.0 / math.pi), _sd(accels)
    moved = []
    if rate_sd > IMU_REST_MAX_RATE_SD_DPS:
        moved.append(f"angular rate scatters {rate_sd:.2f} deg/s (limit {IMU_REST_MAX_RATE_SD_DPS})")
    if accel_sd > IMU_REST_MAX_ACCEL_SD:
        moved.append(f"acceleration scatters {accel_sd:.3f} m/s^2 (limit {IMU_REST_MAX_ACCEL_SD})")
    if np.max(sd) > IMU_REST_MAX_ANGLE_SD_DEG:
        moved.append(f"pitch / roll scatter {sd[0]:.3f} / {sd[1]:.3f} deg (limit {IMU_REST_MAX_ANGLE_SD_DEG})")
    if moved:
        raise ConfigError(source, None, "the car moved in the window: " + "; ".join(moved)
                          + " (1-sigma over the window; choose a still part with --start / --seconds)")
    m = v.mean(axis=0)
    return ImuRest(float(m[0]), float(m[1]), float(sd[0]), float(sd[1]), n,
                   (acc.stamps[-1] - acc.stamps[0]) / 1e9, rate_sd, accel_sd, dropped)
