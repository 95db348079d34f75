"""The far strip's cadence and tiles (issue 26, `far_every` / `far_tiles`) against the band alone, frame by frame.

    .venv/bin/python docs/experiments/far_cadence_cost.py --bag /tmp/s14-roi/jit2611 [--calib example_mainhoop]
        [--designs "none;1;2;2:1152;3:1152"] [--frames 200] [--bag-frames 100]

Every design is a Pipeline of its own in this one process, all sharing the same networks (the default model for
the band, the default far model for the strip, and the tiles' mosaics), and each frame of the rendered drive
``--bag`` (its first ``--bag-frames`` frames as YUYV, in order, cycled; the tiles look where the frame before had
its far cones, as on the car) runs through every design in turn, the order rotating frame by frame. The CPU time
of each design's frame (``time.process_time``, one thread) is summed per design, so a change of the machine's
load reaches all designs alike: the ratios are back to back at the scale of one frame, unlike separate processes
(docs/experiments/band_rows.py), whose CPU time moved by a tenth between rounds on the shared machine.

A design: ``none`` = the band alone, ``N`` = the strip every N-th frame (1: the default, every frame), ``N:W`` =
with the tiles between in mosaics up to W columns. Prints per design: CPU ms per frame (mean), its ratio to the
band alone's (the work rate relative to the band alone: the issue's target is 1), and the strip's counts.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from band_rows import bag_frames  # noqa: E402

from cone_perception.attitude import ImageAttitudeConfig  # noqa: E402
from cone_perception.attitude.box_files import box_model_for  # noqa: E402
from cone_perception.bench.pipeline import load_for_crop  # noqa: E402
from cone_perception.detector.farband import FarBand  # noqa: E402
from cone_perception.detector.fartiles import FarTiles  # noqa: E402
from cone_perception.geometry.calib import load_calibration  # noqa: E402
from cone_perception.pipeline import Pipeline  # noqa: E402
from cone_perception.resources import far_model_for  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bag", required=True)
    ap.add_argument("--calib", default="example_mainhoop")
    ap.add_argument("--designs", default="none;1;2;2:1152;3:1152")
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--warmup", type=int, default=20)
    ap.add_argument("--bag-frames", type=int, default=100)
    args = ap.parse_args()
    calib = load_calibration(args.calib)
    det = load_for_crop(None, "auto", calib.crop, 1)
    far = FarBand.for_calibration(far_model_for(None, det.source), "auto", calib, threads=1)
    bm, _ = box_model_for("auto", det.source, calib.camera == "synth")
    tiles: dict[int, FarTiles] = {}
    pipes = {}
    for d in args.designs.split(";"):
        if d == "none":
            pipes[d] = Pipeline(calib, det, attitude_config=ImageAttitudeConfig(box_model=bm))
            continue
        every, _, width = d.partition(":")
        t = None
        if width:
            t = tiles.setdefault(int(width), FarTiles.for_setting(far.detector.source, int(width), far, 2, threads=1))
            t = FarTiles(t.detectors)  # its own memory of the last frames (the networks shared)
        pipes[d] = Pipeline(calib, det, far=far, attitude_config=ImageAttitudeConfig(box_model=bm),
                            far_every=int(every), far_tiles=t)
    frames = bag_frames(args.bag, args.bag_frames, calib)
    w, h = calib.image_width, calib.image_height
    cpu = {d: [] for d in pipes}
    names = list(pipes)
    for i in range(args.warmup + args.frames):
        data = frames[i % len(frames)]
        for k in range(len(names)):
            d = names[(i + k) % len(names)]
            c0 = time.process_time()
            pipes[d].process_raw("yuv422_yuy2", w, h, 2 * w, data, stamp_ns=i)
            if i >= args.warmup:
                cpu[d].append((time.process_time() - c0) * 1e3)
    ref = float(np.mean(cpu[names[0]]))
    for d in names:
        m = float(np.mean(cpu[d]))
        print(json.dumps({"design": d, "calib": args.calib, "cpu_mean_ms": round(m, 2),
                          "cpu_median_ms": round(float(np.median(cpu[d])), 2),
                          "ratio_to_first": round(ref / m, 3), "strip_counts": pipes[d].strip_counts}))


if __name__ == "__main__":
    main()
