"""``cone-perception imu-rest``: the IMU's rest attitude (``imu_rest_deg``) from a bag of the car standing still.

  cone-perception imu-rest rest.bag                      # the first 2 s of /imu
  cone-perception imu-rest rest.bag --start 5 --seconds 10 --out calib/imu_rest.params.yaml

Park the car on the level ground where the camera was calibrated, record the IMU for a few seconds
(``ros2 bag record /imu``), and run this: it averages the IMU's pitch and roll over the window and
prints the value of the nodes' ``imu_rest_deg`` parameter and of ``replay --imu-rest``; ``--out`` writes
it as a ROS 2 parameter file for every node (``--params-file`` it after the camera's). It refuses,
naming why, when the window holds too few usable samples (NaN and non-unit quaternions are dropped and
counted) or when the car moved (angular rate, acceleration or the readings scatter more than a still
IMU's noise).
"""

from __future__ import annotations

import argparse
import textwrap
from pathlib import Path

from ..attitude import IMU_REST_MAX_ACCEL_SD, IMU_REST_MAX_ANGLE_SD_DEG, IMU_REST_MAX_RATE_SD_DPS, IMU_REST_MIN_SAMPLES
from ..calibrate.imu_rest import run_imu_rest


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = __doc__.split(": ", 1)[1].strip()
    p.epilog = textwrap.fill(f"Refused: fewer than {IMU_REST_MIN_SAMPLES} usable samples, or a 1-sigma scatter over the window above "
                f"{IMU_REST_MAX_RATE_SD_DPS} deg/s angular rate, {IMU_REST_MAX_ACCEL_SD} m/s^2 acceleration or "
                f"{IMU_REST_MAX_ANGLE_SD_DEG} deg pitch / roll (any axis). The IMU's axes must be those of rear_axle "
                "(docs/attitude.md).", 100)
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument("bag", type=Path, help="rosbag2 folder (or .mcap / .db3) with the IMU of the car standing still")
    p.add_argument("--imu-topic", default="/imu", help="the sensor_msgs/Imu topic (default %(default)s)")
    p.add_argument("--start", type=float, default=0.0, metavar="S",
                   help="seconds after the first IMU message where the window starts (default %(default)s)")
    p.add_argument("--seconds", type=float, default=2.0, metavar="S", help="window length (default %(default)s)")
    p.add_argument("--out", type=Path, metavar="FILE.yaml",
                   help="also write imu_rest_deg as a ROS 2 parameter file for every node (/**)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object instead")


def run(args: argparse.Namespace) -> int:
    return run_imu_rest(args)
