"""The band's rows and ONNX Runtime's spinning against the far strip's cost (issue 26, helper 26h).

    .venv/bin/python docs/experiments/band_rows.py --rounds 2 --frames 200 --designs "1:crop:none;1:crop:auto;..."
    .venv/bin/python docs/experiments/band_rows.py --design 2:auto:auto:spin [--frames 200] [--calib C.yaml]

Each design runs `bench pipeline`'s timing (cone_perception.bench.run's loaders and
cone_perception.bench.pipeline.bench_pipeline: rendered 1920x1080 YUYV frames, the example calibration, the
default model, ONNX Runtime, the shipped thread rule of detector/parallel.py) in a fresh process; `--rounds`
interleaves all designs that many times and prints one line per run: frames/s (median end to end), its
ratio to the round's first design of the same thread count, the load average before the run, and the
process's CPU time per frame in the pipeline (``cpu_ms``, median; all threads: on one thread the frame's
work, which other processes' load barely changes, unlike its wall time).

A design is ``THREADS:BAND:FAR[:FLAG...]``:

* ``BAND``: as ``--band-rows`` (detector/farband.py ``band_rows_for``): ``crop`` = the calibration's hand-set
  crop, ``auto`` = placed from the calibration, ``V0,V1`` = those rows;
* ``FAR``: ``none``, ``auto`` (the calibration's strip) or ``V0,V1`` (fixed strip rows), as ``--far-rows``;
* flags: ``spin`` = every ONNX Runtime session spins (its default, the rule before this issue; without it
  the shipped rule, backends.ort_spinning: pools do not spin); ``seq`` = the band's and the strip's forwards
  one after the other, each network on all THREADS (``bench pipeline --sequential``); ``alt`` = the strip
  runs on every other frame only (its cut and the thread hand-off still every frame: an upper bound); ``split`` =
  the band split from the calibration (``--band-split auto``: its near rows at a quarter of full resolution).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

from cone_perception.bench.frames import rendered_frames
from cone_perception.bench.pipeline import bench_pipeline, load_for_crop
from cone_perception.bench.run import forward_plan
from cone_perception.detector import backends
from cone_perception.detector import default_model_path
from cone_perception.detector.farband import FarBand, SplitDetector, band_rows_for, band_split_for, far_rows_for
from cone_perception.geometry.calib import load_calibration
from cone_perception.pipeline import Pipeline
from cone_perception.records import BOX_DTYPE


FLAGS = ("spin", "seq", "alt", "split")


def parse(design: str) -> tuple[int, str, str, set[str]]:
    parts = design.split(":")
    if len(parts) < 3 or not set(parts[3:]) <= set(FLAGS):
        raise SystemExit(f"design {design!r}: expected THREADS:BAND:FAR[:FLAG...], flags {', '.join(FLAGS)}")
    return int(parts[0]), parts[1], parts[2], set(parts[3:])


class AlternateFrames:
    """A far band whose detect runs on every other frame (no boxes on the others)."""

    def __init__(self, far):
        self._far, self._n = far, 0

    def __getattr__(self, name):
        return getattr(self._far, name)

    def detect(self, strip_bgr, crop=None):
        self._n += 1
        if self._n % 2:
            return self._far.detect(strip_bgr, crop)
        return np.zeros(0, dtype=BOX_DTYPE)


def run_design(design: str, frames: int, calib_name: str = "example_mainhoop") -> dict:
    threads, band, far_rows, flags = parse(design)
    if "spin" in flags:
        backends.ort_spinning = lambda t: True
    calib = load_calibration(calib_name)
    calib = band_rows_for(band, calib, far_rows, "--band-rows").apply(calib)
    fr = far_rows_for(far_rows, calib, "--far-rows")
    plan = forward_plan(threads, fr.crop is not None, "seq" in flags)
    split = band_split_for("auto" if "split" in flags else "none", calib, "--band-split")
    if split.upper is None:
        det = load_for_crop(None, "auto", calib.crop, plan.network_threads)
    else:
        det = SplitDetector.load(default_model_path(), split, threads=plan.network_threads)
    far = FarBand.for_calibration(det.source, far_rows, calib, "--far-rows", threads=plan.network_threads)
    if far is not None and "alt" in flags:
        far = AlternateFrames(far)
    cpu_ms = []
    process_raw = Pipeline.process_raw

    def timed(self, *a, **kw):  # the process's CPU time (all its threads) in the frame: the load barely moves it
        c0 = time.process_time()
        out = process_raw(self, *a, **kw)
        cpu_ms.append((time.process_time() - c0) * 1e3)
        return out

    Pipeline.process_raw = timed
    r = bench_pipeline(calib, det, rendered_frames(calib, 16), frames, 20, far, plan.concurrent)
    st = r["stages"]
    med = {k: round(st[k]["median_ms"], 2) for k in ("forward", "far_forward", "far_wait", "end_to_end") if k in st}
    cpu = float(np.median(cpu_ms[20:]))
    return {"design": design, "band": f"{calib.crop.v0},{calib.crop.v1}", "input": r["model_input"],
            "strip": f"{far.crop.v0},{far.crop.v1}" if far else "", "fps": round(r["fps"], 1), **med,
            "cpu_ms": round(cpu, 2), "cpu_mean_ms": round(float(np.mean(cpu_ms[20:])), 2)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--design", help="run this one design in this process, print its JSON line")
    ap.add_argument("--designs", default="1:crop:none;1:crop:auto;2:crop:none;2:crop:auto",
                    help="designs separated by ;")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--calib", default="example_mainhoop", help="the calibration (default %(default)s)")
    ap.add_argument("--frames", type=int, default=200)
    args = ap.parse_args()
    if args.design:
        print(json.dumps(run_design(args.design, args.frames, args.calib)))
        return
    designs = [d.strip() for d in args.designs.split(";") if d.strip()]
    for r in range(1, args.rounds + 1):
        ref: dict[int, float] = {}
        for d in designs:
            load = os.getloadavg()[0]
            out = subprocess.run([sys.executable, __file__, "--design", d, "--frames", str(args.frames), "--calib", args.calib],
                                 capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1]
            res = json.loads(out)
            t = parse(d)[0]
            ref.setdefault(t, res["fps"])
            res.update(round=r, load=round(load, 2), ratio=round(res["fps"] / ref[t], 3))
            print(json.dumps(res), flush=True)


if __name__ == "__main__":
    main()
