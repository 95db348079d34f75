"""The band's rows and ONNX Runtime's spinning against the far strip's cost (issue 26, helper 26h).

    .venv/bin/python docs/experiments/band_rows.py --rounds 2 --frames 200 --designs "1:crop:none;1:crop:auto;..."
    .venv/bin/python docs/experiments/band_rows.py --design 2:auto:auto:spin [--frames 200] [--calib C.yaml]

Each design runs `bench pipeline`'s timing (cone_perception.bench.run's loaders and
cone_perception.bench.pipeline.bench_pipeline: rendered 1920x1080 YUYV frames, the example calibration, the
default model (the strip: the default far model, since session 14; the band's own model before, a network of
the same size), ONNX Runtime, the shipped thread rule of detector/parallel.py) in a fresh process; `--rounds`
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
  the band split from the calibration (``--band-split auto``: its near rows at a quarter of full resolution);
  ``everyN`` = the strip on every N-th frame only (``--far-every N``: the band alone between, no strip cut);
  ``tilesW`` = with ``everyN``, the tiles between (``--far-tiles W``: the strip's windows around the last frame's
  far cones, one mosaic W columns wide). The rendered scenes cycle, so a frame's tiles look where the frame
  before (another scene) had its far cones: the mosaic's cost is the same, the fallbacks to the whole strip
  (``tiles_full``, printed) are what such a scene change gives. ``--bag B`` (with ``--calib`` its calibration):
  the first ``--bag-frames`` frames of the rendered drive B instead, in order (cycled), as YUYV: the tiles then
  look where the frame before had its far cones, as on the car.
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
from cone_perception.crop import CropSpec
from cone_perception.detector import backends
from cone_perception.detector import default_model_path
from cone_perception.detector.fartiles import FarTiles
from cone_perception.detector.farband import FarBand, SplitDetector, band_rows_for, band_split_for, far_rows_for
from cone_perception.geometry.calib import load_calibration
from cone_perception.pipeline import Pipeline
from cone_perception.resources import far_model_for
from cone_perception.records import BOX_DTYPE


FLAGS = ("spin", "seq", "alt", "split")  # and everyN, tilesW


def parse(design: str) -> tuple[int, str, str, set[str]]:
    parts = design.split(":")
    flags = {f for f in parts[3:] if not (f[:5] in ("every", "tiles") and f[5:].isdigit())}
    if len(parts) < 3 or not flags <= set(FLAGS):
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


def bag_frames(bag: str, n: int, calib) -> list[bytes]:
    """The first ``n`` frames of ``bag``'s camera topic as YUYV bytes (the bench's encoding)."""
    from cone_perception.adapter import DriverAdapter, bgr_to_yuyv
    from cone_perception.data.bags import iter_frames

    full = DriverAdapter(CropSpec(0, calib.image_height, 0, calib.image_width, 1), calib.image_width, calib.image_height)
    out = []
    for fr in iter_frames(bag, "/camera/image_raw"):
        m = fr.msg
        bgr = full.from_raw(m.encoding, int(m.width), int(m.height), int(m.step), m.data)
        out.append(bgr_to_yuyv(bgr).tobytes())
        if len(out) == n:
            break
    return out


def run_design(design: str, frames: int, calib_name: str = "example_mainhoop", bag: str | None = None,
               n_bag: int = 100) -> dict:
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
    far = FarBand.for_calibration(far_model_for(None, det.source), far_rows, calib, "--far-rows",
                                  threads=plan.network_threads)  # the default far model (the same network's size)
    every = next((int(f[5:]) for f in flags if f.startswith("every")), 1)
    width = next((int(f[5:]) for f in flags if f.startswith("tiles")), 0)
    tiles = FarTiles.for_setting(far.detector.source if far else None, width, far, every, threads=plan.network_threads)
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
    counts = {}
    pipeline_init = Pipeline.__init__

    def init(self, *a, **kw):  # the strip's counts of the timed pipeline
        pipeline_init(self, *a, **kw)
        counts["strip"] = self.strip_counts

    Pipeline.__init__ = init
    src = bag_frames(bag, n_bag, calib) if bag else rendered_frames(calib, 16)
    r = bench_pipeline(calib, det, src, frames, 20, far, plan.concurrent, every, tiles)
    st = r["stages"]
    med = {k: round(st[k]["median_ms"], 2) for k in ("forward", "far_forward", "far_wait", "end_to_end") if k in st}
    cpu = float(np.median(cpu_ms[20:]))
    return {"design": design, "band": f"{calib.crop.v0},{calib.crop.v1}", "input": r["model_input"],
            "strip": f"{far.crop.v0},{far.crop.v1}" if far else "", "fps": round(r["fps"], 1), **med,
            "cpu_ms": round(cpu, 2), "cpu_mean_ms": round(float(np.mean(cpu_ms[20:])), 2),
            "strip_counts": counts.get("strip")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--design", help="run this one design in this process, print its JSON line")
    ap.add_argument("--designs", default="1:crop:none;1:crop:auto;2:crop:none;2:crop:auto",
                    help="designs separated by ;")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--calib", default="example_mainhoop", help="the calibration (default %(default)s)")
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--bag", help="a rendered drive's frames instead of the rendered scenes (with --calib its calibration)")
    ap.add_argument("--bag-frames", type=int, default=100, help="how many of the bag's first frames (cycled)")
    args = ap.parse_args()
    if args.design:
        print(json.dumps(run_design(args.design, args.frames, args.calib, args.bag, args.bag_frames)))
        return
    designs = [d.strip() for d in args.designs.split(";") if d.strip()]
    for r in range(1, args.rounds + 1):
        ref: dict[int, float] = {}
        for d in designs:
            load = os.getloadavg()[0]
            bag = ["--bag", args.bag, "--bag-frames", str(args.bag_frames)] if args.bag else []
            out = subprocess.run([sys.executable, __file__, "--design", d, "--frames", str(args.frames), "--calib", args.calib, *bag],
                                 capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1]
            res = json.loads(out)
            t = parse(d)[0]
            ref.setdefault(t, res["fps"])
            res.update(round=r, load=round(load, 2), ratio=round(res["fps"] / ref[t], 3))
            print(json.dumps(res), flush=True)


if __name__ == "__main__":
    main()
