"""The car's odometry in a synthetic bag (``/odom``, ``nav_msgs/Odometry``): the body's true twist
with white noise and a small constant bias, at its own rate. ROS-free.

The true twist of the ``rear_axle`` frame (axes x forward, y left; ``vx``, ``vy`` in m/s, ``wz``
in rad/s) between two frames is the constant twist that moves the car from one frame's pose to the
next (:meth:`~cone_perception.geometry.motion.Motion2D.twist`); an odometry sample at time ``t`` takes
the twist linearly interpolated between the middles of the frame intervals around ``t``. Noise
per sample (1 sigma) and one bias per bag (1 sigma of the draw) are the constants below, about a
wheel-speed + gyro odometry of a small car. The pose (``pose.pose``, frame ``odom``) is the noisy
twist integrated from the first sample (dead reckoning, drifting as on a car). Noise comes from its
own generator, so the other topics of a seed's bag do not change.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..tracking import Motion2D, from_twist

ODOM_RATE_HZ = 50.0
ODOM_V_NOISE = 0.05  # m/s, forward speed, per sample
ODOM_VY_NOISE = 0.02  # m/s, lateral
ODOM_W_NOISE = np.radians(0.2)  # rad/s, yaw rate
ODOM_V_BIAS = 0.02  # m/s
ODOM_W_BIAS = np.radians(0.1)  # rad/s


@dataclass
class OdomSample:
    """One odometry message's content."""

    stamp_ns: int
    twist: tuple[float, float, float]  # vx m/s, vy m/s, wz rad/s (body axes, noisy)
    pose: tuple[float, float, float]  # x m, y m, yaw rad in ``odom`` (integrated noisy twist)


def frame_twists(poses_xy_yaw: np.ndarray, fps: float) -> np.ndarray:
    """(n, 3) poses (m, m, rad; track frame) of frames ``1 / fps`` apart -> (n - 1, 3) true body twists
    (m/s, m/s, rad/s) of the intervals. An interval longer than 3x its neighbours' median (the drive
    wrapping to the start of the course) repeats the twist before it."""
    p = np.asarray(poses_xy_yaw, dtype=np.float64).reshape(-1, 3)
    dt = 1.0 / fps
    out = np.zeros((max(len(p) - 1, 0), 3))
    for i in range(len(out)):
        x0, y0, a0 = p[i]
        x1, y1, a1 = p[i + 1]
        c, s = np.cos(a0), np.sin(a0)
        dx, dy = x1 - x0, y1 - y0
        m = Motion2D(c * dx + s * dy, -s * dx + c * dy, float((a1 - a0 + np.pi) % (2 * np.pi) - np.pi))
        out[i] = m.twist(dt)
    if len(out) > 2:
        speed = np.hypot(out[:, 0], out[:, 1])
        jump = speed > 3.0 * max(float(np.median(speed)), 0.1)
        for i in np.flatnonzero(jump):
            out[i] = out[i - 1] if i else out[min(i + 1, len(out) - 1)]
    return out


def odometry_samples(poses_xy_yaw: np.ndarray, fps: float, start_stamp_ns: int, rng: np.random.Generator,
                     rate_hz: float = ODOM_RATE_HZ) -> list[OdomSample]:
    """Odometry at ``rate_hz`` over the drive of ``poses_xy_yaw`` ((n, 3) m, m, rad, one per frame, the
    first at ``start_stamp_ns``), noise and bias drawn from ``rng``."""
    p = np.asarray(poses_xy_yaw, dtype=np.float64).reshape(-1, 3)
    if len(p) < 2:
        return []
    tw = frame_twists(p, fps)
    t_mid = (np.arange(len(tw)) + 0.5) / fps
    t_end = (len(p) - 1) / fps
    t = np.arange(0.0, t_end + 1e-9, 1.0 / rate_hz)
    true = np.column_stack([np.interp(t, t_mid, tw[:, k]) for k in range(3)])
    bias = np.array([rng.normal(0.0, ODOM_V_BIAS), 0.0, rng.normal(0.0, ODOM_W_BIAS)])
    noise = rng.normal(0.0, 1.0, (len(t), 3)) * (ODOM_V_NOISE, ODOM_VY_NOISE, ODOM_W_NOISE)
    meas = true + bias + noise
    out, pose = [], Motion2D()
    for k in range(len(t)):
        if k:
            pose = pose.compose(from_twist(*meas[k - 1], t[k] - t[k - 1]))
        out.append(OdomSample(start_stamp_ns + int(round(t[k] * 1e9)), tuple(float(v) for v in meas[k]),
                              (pose.dx, pose.dy, pose.dyaw)))
    return out
