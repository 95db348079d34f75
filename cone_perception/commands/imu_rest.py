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
import json
import sys
import textwrap
from pathlib import Path

from ..attitude import (
    IMU_REST_MAX_ACCEL_SD, IMU_REST_MAX_ANGLE_SD_DEG, IMU_REST_MAX_RATE_SD_DPS, IMU_REST_MIN_SAMPLES, imu_rest,
)
from ..errors import ConfigError


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
    from ..data.bags import read_imu_motion

    if args.seconds <= 0 or args.start < 0:
        raise ConfigError("--seconds/--start", None, f"need --seconds > 0 and --start >= 0, got {args.seconds}, {args.start}")
    stamps, quats, rates, accels = read_imu_motion(args.bag, args.imu_topic)
    src = f"{args.bag} {args.imu_topic}"
    if len(stamps) == 0:
        raise ConfigError(src, None, "no IMU messages")
    t0 = stamps[0] + int(args.start * 1e9)
    sel = (stamps >= t0) & (stamps < t0 + int(round(args.seconds * 1e9)))  # [start, start + seconds)
    r = imu_rest(stamps[sel], quats[sel], rates[sel], accels[sel], src)
    value = [round(r.pitch_deg, 4), round(r.roll_deg, 4)]
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(f"# IMU rest attitude (pitch, roll; degrees), cone-perception imu-rest {args.bag} "
                            f"--start {args.start:g} --seconds {args.seconds:g}: {r.n} samples, 1-sigma "
                            f"{r.sd_pitch_deg:.3f} / {r.sd_roll_deg:.3f} deg\n"
                            f"/**:\n  ros__parameters:\n    imu_rest_deg: [{value[0]}, {value[1]}]\n", encoding="utf-8")
    if args.json:
        print(json.dumps({"imu_rest_deg": value, **{k: v for k, v in r.__dict__.items()}, "out": str(args.out or "")}))
    else:
        print(f"IMU at rest ({r.n} samples over {r.seconds:.2f} s): pitch {r.pitch_deg:+.3f} deg, roll {r.roll_deg:+.3f} deg "
              f"(1-sigma {r.sd_pitch_deg:.3f} / {r.sd_roll_deg:.3f}; rate {r.rate_sd_dps:.2f} deg/s, accel {r.accel_sd:.3f} m/s^2)"
              + (f"; dropped: {', '.join(f'{k} {v}' for k, v in r.dropped.items())}" if r.dropped else ""))
        print(f"imu_rest_deg: [{value[0]}, {value[1]}]")
        print(f"replay: --imu-rest {value[0]},{value[1]}")
        if args.out is not None:
            print(f"wrote {args.out}", file=sys.stderr)
    return 0
