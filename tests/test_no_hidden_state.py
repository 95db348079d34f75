"""Issue 28: no hidden state. The pipeline's frame stamp is an argument of each call (it was an attribute
set before it: forgotten, the IMU was read at the previous frame's time); the tracker's tuning lives in
TrackerConfig (the gap and failed-registration inflation were literals)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cone_perception.attitude import ImuAttitude
from cone_perception.geometry.calib import load_calibration
from cone_perception.pipeline import Pipeline
from cone_perception.records import BOX_DTYPE, CONE_DTYPE
from cone_perception.tracking import ConeTracker, Motion2D, TrackerConfig

CALIB = load_calibration("example_mainhoop")


class NoBoxes:
    """A detector that finds nothing (the attitude in mode imu comes from the IMU alone)."""

    timing: dict = {}

    def detect(self, band, crop):
        return np.zeros(0, BOX_DTYPE)


def _imu() -> ImuAttitude:
    imu = ImuAttitude((0.0, 0.0))
    for k in range(11):  # 0 .. 1 s, the car pitching by 0.2 degrees every 0.1 s
        a = math.radians(0.2 * k) / 2
        assert imu.add(k * 100_000_000, (0.0, math.sin(a), 0.0, math.cos(a)))
    return imu


def test_pipeline_reads_the_imu_at_the_stamp_it_is_given():
    imu = _imu()
    pipe = Pipeline(CALIB, NoBoxes(), "imu", imu)
    w, h = CALIB.image_width, CALIB.image_height
    frame = bytes(2 * w * h)
    early = pipe.process_raw("yuv422_yuy2", w, h, 2 * w, frame, stamp_ns=0).attitude
    late = pipe.process_raw("yuv422_yuy2", w, h, 2 * w, frame, stamp_ns=1_000_000_000).attitude
    again = pipe.process_raw("yuv422_yuy2", w, h, 2 * w, frame, stamp_ns=0).attitude  # no memory of the last call
    assert early.source == late.source == "imu"
    assert (early.pitch_deg, early.roll_deg) == pytest.approx(tuple(imu.at(0)))
    assert (late.pitch_deg, late.roll_deg) == pytest.approx(tuple(imu.at(1_000_000_000)))
    assert abs(late.pitch_deg - early.pitch_deg) > 1.5 and again == early
    with pytest.raises(ValueError, match="stamp_ns"):  # with an IMU, a frame without its stamp is refused
        pipe.process_raw("yuv422_yuy2", w, h, 2 * w, frame)
    assert not hasattr(pipe, "frame_stamp_ns")


def test_the_gap_inflation_of_the_tracks_comes_from_tracker_config():
    """Over a gap (no cone seen, odometry standing still) each track's covariance grows by
    process_std_m^2 + (gap_std_m + gap_std_m_per_s * (dt - max_gap_s))^2 (plus the yaw term)."""

    def run(cfg: TrackerConfig) -> np.ndarray:
        trk = ConeTracker(cfg)
        cone = np.zeros(1, dtype=CONE_DTYPE)
        cone["x"], cone["score"], cone["cov_xx"], cone["cov_yy"] = 8.0, 0.9, 0.04, 0.04
        trk.update(0, cone, None)
        p0 = trk.P[0].copy()
        trk.update(2_000_000_000, cone[:0], Motion2D())  # 2 s later: a gap (max_gap_s 0.5)
        return trk.P[0] - p0

    keep = dict(delete_below=0.0)  # the track's certainty falls over the gap: keep it to look at
    default = TrackerConfig(**keep)
    assert (default.gap_std_m, default.gap_std_m_per_s) == (0.1, 0.5)  # the literals they replace
    grown = run(default)
    steeper = run(TrackerConfig(gap_std_m_per_s=1.0, **keep))
    extra = lambda c: c.gap_std_m + c.gap_std_m_per_s * (2.0 - c.max_gap_s)  # noqa: E731
    assert grown[0, 0] == pytest.approx(default.process_std_m**2 + extra(default) ** 2, rel=1e-6)  # x: no yaw term at y = 0
    assert (steeper - grown)[1, 1] == pytest.approx(extra(TrackerConfig(gap_std_m_per_s=1.0)) ** 2 - extra(default) ** 2)
