"""The car moving like a car: a speed profile with braking and acceleration, the body pitch and roll
that follow from it, bumps, grade changes of the road ahead, and the IMU that feels all of it.

Body attitude per frame (degrees, the convention of :class:`~cone_perception.synth.scene.CarPose`:
pitch + = nose down, roll + = right side down), the sum of

* the suspension jitter of :func:`~cone_perception.synth.scene.jitter_series` (unchanged, +-1 degree),
* longitudinal load transfer: ``pitch = -PITCH_PER_MPS2 * a_long`` (braking dips the nose), clipped to
  +-:data:`MAX_LOAD_PITCH_DEG`; the speed follows a smooth profile between 40 % and 160 % of the set
  speed (straights faster, braking before corners is what the car does: here a random smooth profile),
* lateral load transfer: ``roll = ROLL_PER_MPS2 * v^2 * curvature`` (a left turn rolls the body to
  the right: right side down),
* bumps: decaying 6-9 Hz oscillations of 0.2-0.5 degree, on average one every 2 s,
* grade changes: the road ahead tilts against the car's own plane by up to 2 % (1.15 degrees)
  lengthwise and 1 % across, drifting slowly; the ground the camera sees is then one plane tilted
  against the car, which for the camera is the same as the body tilting the other way by that
  angle about the rear axle (the renderer's body rotation).

The IMU (``sensor_msgs/Imu``, frame ``imu`` with the ``rear_axle`` axes) measures the body's
orientation against gravity (jitter, load transfer and bumps; yaw = heading; NOT the grade change,
which tilts the road ahead, not the car), its angular rate and its specific force (acceleration
minus gravity), with white noise and a small constant bias per bag. Ground truth per frame: the
total attitude of the camera against the ground the cones stand on (what the image fit estimates).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.camera import _rot_x, _rot_y, _rot_z
from .track import Track

PITCH_PER_MPS2 = 0.2  # degrees per m/s^2 of longitudinal acceleration (1 g braking: ~2 degrees)
MAX_LOAD_PITCH_DEG = 2.0
ROLL_PER_MPS2 = 0.12  # degrees per m/s^2 of lateral acceleration
MAX_GRADE = 0.02  # 2 % lengthwise
MAX_CROSS_GRADE = 0.01
G = 9.81
#: IMU noise (1-sigma per sample) and bias magnitude (one constant draw per bag)
IMU_ANGLE_NOISE_DEG = 0.03
IMU_RATE_NOISE_DPS = 0.2
IMU_ACCEL_NOISE = 0.05
IMU_ANGLE_BIAS_DEG = 0.05
IMU_RATE_BIAS_DPS = 0.1
IMU_ACCEL_BIAS = 0.05


@dataclass
class Drive:
    """Per-frame motion of one drive, arrays of length n (SI units unless named in degrees)."""

    s_m: np.ndarray  # arc length along the centre line
    speed_mps: np.ndarray
    accel_long: np.ndarray  # m/s^2, + = speeding up
    accel_lat: np.ndarray  # m/s^2, + = to the left (left turn)
    pitch_deg: np.ndarray  # total camera attitude against the ground ahead (jitter included)
    roll_deg: np.ndarray
    body_pitch_deg: np.ndarray  # the part the IMU feels (against gravity): all but the grade change
    body_roll_deg: np.ndarray


def constant_speed_drive(poses, speed_mps: float, fps: float) -> Drive:
    """The :class:`Drive` of poses at constant speed (the default scene: jitter only, no grade)."""
    n = len(poses)
    heading = np.unwrap([p.yaw_rad for p in poses])
    yaw_rate = np.gradient(heading, 1.0 / fps) if n > 1 else np.zeros(n)
    pitch = np.array([p.pitch_deg for p in poses])
    roll = np.array([p.roll_deg for p in poses])
    return Drive(np.zeros(n), np.full(n, speed_mps), np.zeros(n), speed_mps * yaw_rate, pitch, roll, pitch, roll)


def _smooth_noise(n: int, fps: float, rng: np.random.Generator, period_s: tuple[float, float], k: int = 3) -> np.ndarray:
    """(n,) sum of ``k`` sines with periods in ``period_s``, normalised to a peak of 1."""
    t = np.arange(n) / fps
    out = np.zeros(n)
    for _ in range(k):
        out += rng.uniform(0.5, 1.0) * np.sin(2 * np.pi * t / rng.uniform(*period_s) + rng.uniform(0, 2 * np.pi))
    return out / max(np.abs(out).max(), 1e-9)


def drive_motion(track: Track, n: int, fps: float, speed_mps: float, rng: np.random.Generator,
                 jitter: np.ndarray, start_m: float = 0.0) -> Drive:
    """The drive's motion; ``jitter`` (n, 2) is the suspension jitter (pitch, roll) in degrees."""
    dt = 1.0 / fps
    speed = speed_mps * (1.0 + 0.6 * _smooth_noise(n, fps, rng, (3.0, 8.0)))
    a_long = np.gradient(speed, dt) if n > 1 else np.zeros(n)
    s = start_m + np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * dt)])
    L = max(track.length_m - 1.0, 1.0)
    s = s % L
    heading = np.unwrap([track.pose_at(float(x))[2] for x in s])
    yaw_rate = np.gradient(heading, dt) if n > 1 else np.zeros(n)
    a_lat = speed * yaw_rate
    load_pitch = np.clip(-PITCH_PER_MPS2 * a_long, -MAX_LOAD_PITCH_DEG, MAX_LOAD_PITCH_DEG)
    load_roll = np.clip(ROLL_PER_MPS2 * a_lat, -1.5, 1.5)  # a left turn: right side down
    bumps = np.zeros(n)
    t = np.arange(n) * dt
    t_bump = 0.0
    while True:
        t_bump += rng.exponential(2.0)
        if t_bump >= t[-1] if n else True:
            break
        f, amp, tau = rng.uniform(6.0, 9.0), rng.uniform(0.2, 0.5) * rng.choice([-1, 1]), rng.uniform(0.1, 0.2)
        after = t >= t_bump
        x = t[after] - t_bump
        bumps[after] += amp * np.exp(-x / tau) * np.sin(2 * np.pi * f * x)
    grade = np.degrees(np.arctan(MAX_GRADE)) * _smooth_noise(n, fps, rng, (8.0, 20.0), 2)
    cross = np.degrees(np.arctan(MAX_CROSS_GRADE)) * _smooth_noise(n, fps, rng, (8.0, 20.0), 2)
    body_pitch = jitter[:, 0] + load_pitch + bumps
    body_roll = jitter[:, 1] + load_roll
    # a road rising ahead (grade > 0) looks to the camera like the nose dipping: pitch + grade
    return Drive(s, speed, a_long, a_lat, body_pitch + grade, body_roll + cross, body_pitch, body_roll)


@dataclass
class ImuSample:
    """One IMU message's content: orientation quaternion (x, y, z, w), angular rate (rad/s), specific force (m/s^2)."""

    quat_xyzw: np.ndarray
    rate: np.ndarray
    accel: np.ndarray


def imu_samples(drive: Drive, heading_rad: np.ndarray, fps: float, rng: np.random.Generator,
                stand: int = 0) -> tuple[list[ImuSample], list[ImuSample]]:
    """IMU readings (standing, driving): ``stand`` samples of the car standing still at the start pose on
    level ground (what ``cone-perception imu-rest`` averages), then one for each frame of ``drive``;
    noise and one constant bias drawn from ``rng`` (the drive's readings do not depend on ``stand``)."""
    n = len(drive.s_m)
    dt = 1.0 / fps
    bias_angle = np.radians(rng.normal(0.0, IMU_ANGLE_BIAS_DEG, 2))
    bias_rate = np.radians(rng.normal(0.0, IMU_RATE_BIAS_DPS, 3))
    bias_acc = rng.normal(0.0, IMU_ACCEL_BIAS, 3)
    # REP 103 angles of the body: roll about x (+ = right side down), pitch about y (+ = nose down), yaw about z
    roll = np.radians(drive.body_roll_deg)
    pitch = np.radians(drive.body_pitch_deg)
    yaw = np.asarray(heading_rad, dtype=np.float64)
    rates = np.column_stack([np.gradient(roll, dt), np.gradient(pitch, dt), np.gradient(yaw, dt)]) if n > 1 else np.zeros((n, 3))

    def reading(roll_i: float, pitch_i: float, yaw_i: float, rate_i, a_long: float, a_lat: float) -> ImuSample:
        r = roll_i + bias_angle[0] + rng.normal(0.0, np.radians(IMU_ANGLE_NOISE_DEG))
        p = pitch_i + bias_angle[1] + rng.normal(0.0, np.radians(IMU_ANGLE_NOISE_DEG))
        w = rate_i + bias_rate + rng.normal(0.0, np.radians(IMU_RATE_NOISE_DPS), 3)
        # specific force in the body frame: motion acceleration minus gravity (gravity -z in the world)
        R = rpy_matrix(roll_i, pitch_i, 0.0)
        f = R.T @ np.array([a_long, a_lat, G]) + bias_acc + rng.normal(0.0, IMU_ACCEL_NOISE, 3)
        return ImuSample(quat_from_rpy(r, p, yaw_i), w, f)

    out = [reading(roll[i], pitch[i], yaw[i], rates[i], drive.accel_long[i], drive.accel_lat[i]) for i in range(n)]
    still = [reading(0.0, 0.0, float(yaw[0]) if n else 0.0, np.zeros(3), 0.0, 0.0) for _ in range(stand)]
    return still, out


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rz(yaw) Ry(pitch) Rx(roll), radians."""
    return _rot_z(yaw) @ _rot_y(pitch) @ _rot_x(roll)


def quat_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """(x, y, z, w) of Rz(yaw) Ry(pitch) Rx(roll), radians."""
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return np.array([
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    ])
