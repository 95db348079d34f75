"""The ``--imu-rest`` a rest capture would give for a synthetic bag: the IMU's constant offset against the truth.

A car team measures the IMU's rest attitude once (``cone-perception imu-rest`` on a bag of the car
standing on the calibration ground). Synthetic drives have no standing phase, so this script takes the
same constant from the bag itself: the mean of (IMU pitch, roll) minus (``/attitude_gt`` pitch, roll)
over the drive (on flat-ground drives, where the IMU's attitude and the ground-relative truth differ only
by the bias and white noise). It prints ``PITCH,ROLL`` in degrees for ``replay --imu-rest``.

    .venv/bin/python docs/experiments/imu_rest_from_truth.py BAG [BAG ...]
"""

from __future__ import annotations

import math
import sys

import numpy as np

from cone_perception.data import bagio
from cone_perception.attitude import rpy_from_quaternion
from cone_perception.data.bags import read_imu


def rest_from_truth(bag: str) -> tuple[float, float, float, float]:
    """(pitch, roll) offset in degrees and the scatter (std) of each, over the frames with both."""
    imu = {s: rpy_from_quaternion(*q) for s, q in read_imu(bag)}
    rows = []
    for m in bagio.read_messages(bag, "/attitude_gt"):
        s = bagio.stamp_ns(m.msg.header)
        if s in imu:
            roll, pitch, _ = imu[s]
            rows.append((math.degrees(pitch) - math.degrees(m.msg.vector.y), math.degrees(roll) - math.degrees(m.msg.vector.x)))
    d = np.array(rows)
    return float(d[:, 0].mean()), float(d[:, 1].mean()), float(d[:, 0].std()), float(d[:, 1].std())


if __name__ == "__main__":
    for bag in sys.argv[1:]:
        p, r, sp, sr = rest_from_truth(bag)
        print(f"{bag}: --imu-rest={p:.4f},{r:.4f}   (scatter {sp:.3f} / {sr:.3f} deg: white noise only on flat ground)")
