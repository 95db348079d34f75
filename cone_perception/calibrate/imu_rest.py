"""The ``cone-perception imu-rest`` run: the IMU's rest attitude (``imu_rest_deg``) from a bag of the car standing
still, printed and optionally written as a node parameter file.
"""

from __future__ import annotations

import argparse
import json
import sys

from ..attitude import imu_rest
from ..data.bags import read_imu_motion
from ..errors import ConfigError


def run_imu_rest(args: argparse.Namespace) -> int:
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
