"""Band and far strip on two CPU threads (issue 26, item 1): the designs `bench pipeline` has no flag for.

    .venv/bin/python docs/experiments/concurrent_forwards.py [--rounds 3] [--frames 200] [--far-rows 384,480]
    .venv/bin/python docs/experiments/concurrent_forwards.py --design NAME [--frames 200] [--far-rows V0,V1]

Each design runs `bench pipeline`'s timing (cone_perception.bench.pipeline.bench_pipeline: rendered 1920x1080
YUYV frames, the example calibration, the default model, ONNX Runtime) in a fresh process; `--rounds`
interleaves all designs that many times and prints one line per run (frames/s, and its ratio to the band
alone on two threads, `band 2`, of the same round). Designs (threads: band's network + strip's network):

* ``band 1``, ``band 2``: no strip, one / two intra-op threads;
* ``seq 2+2``: the strip after the band, each network on two intra-op threads (``--threads 2 --sequential``);
* ``conc 1+1``: at once, one each: the shipped rule for ``threads: 2`` (detector/parallel.py);
* ``conc 2+1``: balancing: at once, the band (the larger network) on two intra-op threads, the strip on one
  (three threads on two cores);
* ``band 2 nospin``, ``seq 2+2 nospin``, ``conc 2+1 nospin``: the same with ONNX Runtime's intra-op threads not spinning after
  their work (``session.intra_op.allow_spinning = 0``), so an idle network's pool gives its core back.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys

from cone_perception.bench.frames import rendered_frames
from cone_perception.bench.pipeline import bench_pipeline
from cone_perception.detector import Detector, default_model_path
from cone_perception.detector import detector as detector_module
from cone_perception.detector.backends import ort_session
from cone_perception.detector.farband import FarBand
from cone_perception.geometry.calib import load_calibration

# name: (band threads, strip threads or None = no strip, concurrent, ORT spinning)
DESIGNS = {
    "band 1": (1, None, False, True),
    "band 2": (2, None, False, True),
    "seq 2+2": (2, 2, False, True),
    "conc 1+1": (1, 1, True, True),
    "conc 2+1": (2, 1, True, True),
    "band 2 nospin": (2, None, False, False),
    "seq 2+2 nospin": (2, 2, False, False),
    "conc 2+1 nospin": (2, 1, True, False),
}


def _no_spin_session(model, device, threads, source):
    """:func:`ort_session` with the intra-op threads sleeping as soon as their work ends."""
    import onnxruntime as ort

    real = ort.SessionOptions

    def options():
        so = real()
        so.add_session_config_entry("session.intra_op.allow_spinning", "0")
        return so

    ort.SessionOptions = options
    try:
        return ort_session(model, device, threads, source)
    finally:
        ort.SessionOptions = real


def run_design(name: str, frames: int, far_rows: str) -> dict:
    band_threads, strip_threads, concurrent, spin = DESIGNS[name]
    if not spin:
        detector_module.ort_session = _no_spin_session
    calib = load_calibration("example_mainhoop")
    crop = calib.crop
    det = Detector.load_for_band(default_model_path(), (crop.out_width, crop.out_height), threads=band_threads)
    far = None
    if strip_threads is not None:
        far = FarBand.load(default_model_path(), far_rows, calib.image_width, calib.image_height, crop,
                           threads=strip_threads)
    r = bench_pipeline(calib, det, rendered_frames(calib, 16), frames, 20, far, concurrent)
    st = r["stages"]
    med = {k: round(st[k]["median_ms"], 2) for k in ("forward", "far_forward", "far_band", "far_wait", "end_to_end") if k in st}
    return {"design": name, "far_rows": far_rows if far else "", "fps": round(r["fps"], 1), **med}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--design", choices=sorted(DESIGNS), default=None, help="run this one design here (else all, interleaved)")
    p.add_argument("--rounds", type=int, default=3, help="interleaved rounds of all designs (default %(default)s)")
    p.add_argument("--frames", type=int, default=200, help="timed frames a run (default %(default)s)")
    p.add_argument("--far-rows", default="384,480", help="the strip's rows (default %(default)s)")
    p.add_argument("--designs", default=",".join(DESIGNS), help="comma-separated subset of the designs, in this order")
    args = p.parse_args()
    if args.design:
        print(json.dumps(run_design(args.design, args.frames, args.far_rows)))
        return 0
    names = args.designs.split(",")
    for k in range(args.rounds):
        base = None
        for name in names:
            out = subprocess.run([sys.executable, __file__, "--design", name, "--frames", str(args.frames),
                                  "--far-rows", args.far_rows], capture_output=True, text=True, check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
            base = r["fps"] if name == "band 2" else base
            r["round"], r["vs_band_2"] = k + 1, round(r["fps"] / base, 3) if base else None
            print(json.dumps(r), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
