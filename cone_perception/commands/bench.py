"""``cone-perception bench``: per-stage timings on real-size frames, through the code the nodes run (``bench/``):
``adapter``, ``pipeline`` (the fused stages as the ``pipeline`` node runs them; ``--repeat N``: N fresh processes),
``tracker``, ``table`` (the runtime table), ``startup`` (the node from exec to its first ``/cones``, cold, warm and
after ``kill -9``: ``rostools/startup.py``, docs/robustness.md), ``report`` (docs/benchmarks.md's tables). Warm-up
frames excluded; median, p90, p99, min-max and peak RSS."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..bench.pipeline import BYTES_PER_PX
from ..bench.run import run_bench
from ..bench.report import TOPICS
from ..bench.table import INPUT_SETTINGS
from ..detector import BACKEND_CHOICES, DEFAULT_BACKEND, RUNTIME_THREADS
from ..geometry.calib import DEFAULT_CAMERA
from ..params import DEFAULT_CONF, PARAMS
from ._args import add_band_split, add_far_model, add_far_verifier, parse_crop


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = ("Benchmark per-frame stages on real-size frames (warm-up excluded); `table` adds mAP on real "
                     "validation frames per model and input setting (the thesis's runtime table).")
    p.add_argument("target", choices=["adapter", "pipeline", "table", "tracker", "startup", "report"],
                   help="what to benchmark: adapter, pipeline, table (the runtime table: bench + mAP per model and input "
                        "setting), tracker (the cone tracker's update per frame on a simulated drive), startup (the "
                        "pipeline node from exec to ready and to its first /cones, cold, warm and after kill -9), or "
                        "report (the defaults' figures, one table per topic, written into docs/benchmarks.md)")
    p.add_argument("--frames", type=int, default=300, help="timed frames (>= 200 recommended; default %(default)s)")
    p.add_argument("--warmup", type=int, default=20, help="untimed warm-up frames (default %(default)s)")
    p.add_argument("--calib", default=DEFAULT_CAMERA, help="calibration (crop, downscale, image size); default %(default)s")
    p.add_argument("--encoding", default="yuv422_yuy2", choices=sorted(BYTES_PER_PX), help="input encoding")
    p.add_argument("--threads", type=int, default=RUNTIME_THREADS,
                   help="torch and ONNX Runtime threads of the network (default %(default)s, as the nodes; "
                        "OpenCV runs on one, see adapter.OPENCV_THREADS)")
    p.add_argument("--model", default=None, help="pipeline: model file (default: the shipped default model)")
    p.add_argument("--backend", default=DEFAULT_BACKEND, choices=BACKEND_CHOICES,
                   help="pipeline, table: inference backend (default %(default)s: ONNX Runtime on the CPU where "
                        "installed, else torch; fixed-size ones are built for each band's input size)")
    p.add_argument("--bf16", action="store_true", help="pipeline, table: backend torch with bfloat16 autocast on the CPU")
    p.add_argument("--device", default=PARAMS["device"].default, metavar="cpu|cuda|cuda:N",
                   help="pipeline: where the networks run (the nodes' device parameter; with --backend onnx ONNX "
                        "Runtime's TensorRT or CUDA provider, docs/jetson.md; default %(default)s)")
    p.add_argument("--fp16", action="store_true",
                   help="pipeline, with --device cuda: half precision (torch fp16, or TensorRT's fp16 engine with "
                        "--backend onnx)")
    p.add_argument("--far-rows", default=None, metavar="auto|none|V0,V1",
                   help="pipeline: the far band, image rows also run at full resolution (docs/detector.md 'Far band'): "
                        "auto (default) = the calibration's far strip; V0,V1 = these rows; none (or off) = the band alone")
    p.add_argument("--far-every", type=int, default=PARAMS["far_every"].default, metavar="N",
                   help="pipeline: the far band's strip on every N-th frame only, the band alone between (the pipeline "
                        "node's far_every; default %(default)s = every frame); the frame rate is then bimodal: read the "
                        "mean (frames/s over the mean end to end)")
    p.add_argument("--far-tiles", type=int, default=PARAMS["far_tiles"].default, metavar="W",
                   help="pipeline, with --far-every above 1: on the frames between, the strip's windows around the last "
                        "two frames' far cones in one mosaic at most W columns wide (the node's far_tiles; default "
                        "%(default)s = off). The rendered scenes cycle: the tiles look where another scene's far cones "
                        "were (docs/experiments/far_cadence_cost.py measures them on a drive's frames)")
    p.add_argument("--band-rows", default=None, metavar="crop|auto|V0,V1",
                   help="pipeline: the band's rows (docs/detector.md 'Band rows'): crop (default) = the calibration's crop, "
                        "auto = placed from the calibration, V0,V1 = these rows")
    add_band_split(p, "pipeline: ")
    add_far_model(p, "pipeline: ")
    add_far_verifier(p, "pipeline: ")
    p.add_argument("--sequential", action="store_true",
                   help="pipeline with a far band: the band's and the strip's forwards one after the other, each network "
                        "on --threads intra-op threads (default: with --threads >= 2 at once, the strip on a worker "
                        "thread, each network on threads // 2; detector/parallel.py)")
    p.add_argument("--scenes", type=int, default=16, help="pipeline, table: distinct rendered scenes, cycled (default %(default)s)")
    p.add_argument("--input", default=None, choices=INPUT_SETTINGS,
                   help="pipeline: override the calibration's crop: full = all rows, downscale 1; half = all rows, "
                        "downscale 2; crop = the calibration's band, downscale 1; crop_half = the band, downscale 2 "
                        "(default: the calibration's own crop and downscale)")
    p.add_argument("--rows", type=int, default=8,
                   help="tracker: rows of cones beside the simulated drive, 2 m apart along it (default %(default)s: "
                        "about 100 tracks, 50 cones a frame with the default calibration)")
    p.add_argument("--starts", type=int, default=10,
                   help="startup: warm starts, and as many restarts right after a kill -9 (default %(default)s)")
    p.add_argument("--cold-starts", type=int, default=3,
                   help="startup: starts with the ONNX cache emptied before each (default %(default)s)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (--json implies it for pipeline)")
    p.add_argument("--repeat", type=int, default=1,
                   help="pipeline: run it this many times, each in a fresh process (this machine's speed varies "
                        "between processes), and report the spread: median range, each run's p99 / median, "
                        "how many runs kept p99 within 1.5x the median (default %(default)s)")
    r = p.add_argument_group("report", "bench report: runs the commands behind each table of docs/benchmarks.md")
    r.add_argument("--topics", default="all", help=f"report: topics, comma-separated, of {', '.join(TOPICS)} (default all)")
    r.add_argument("--quick", action="store_true", help="report: fewer frames, shorter and fewer drives (minutes, not an hour)")
    r.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"), help="report: the document (default %(default)s)")
    r.add_argument("--work", type=Path, default=Path("runs/bench_report"), help="report: scratch folder (default %(default)s)")
    t = p.add_argument_group("table", "bench table: for each model and input setting, bench pipeline + detect + eval on real frames")
    t.add_argument("--models", default=None, help="table: model files, comma-separated (default: the shipped default model)")
    t.add_argument("--val", type=Path, default=None, help="table, report: YOLO folder (images/, labels/) of real validation "
                                                           "frames (report's default: data/real_val_1080)")
    t.add_argument("--gt-names", default=None, help="table: class names of --val in id order, comma-separated (as eval --gt-names)")
    t.add_argument("--band", type=parse_crop, default=None, metavar="V0,V1[,U0,U1]",
                   help="table: the band of the --val frames (their camera is not the calibration's), as detect --crop")
    t.add_argument("--out", type=Path, default=None, help="table: output folder (table.md, table.json, predictions, eval reports)")
    t.add_argument("--settings", default=",".join(INPUT_SETTINGS),
                   help="table: input settings, comma-separated (default %(default)s)")
    t.add_argument("--det-conf", type=float, default=0.001, help="table: detector score threshold for the mAP run (default %(default)s)")
    t.add_argument("--conf", type=float, default=DEFAULT_CONF, help="table: operating score threshold for recall (default %(default)s)")


def run(args: argparse.Namespace) -> int:
    if args.target == "startup":
        from ..rostools.startup import run_startup  # rclpy and the localhost DDS environment: on use only

        return run_startup(args)
    return run_bench(args)
