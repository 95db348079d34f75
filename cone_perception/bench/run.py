"""The ``cone-perception bench`` run: the stages' timing table on real-size frames, repeated runs, and the
tracker's cost (the command parses the arguments).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from dataclasses import replace

from tqdm import tqdm

from ..bench.frames import rendered_frames
from ..bench.pipeline import bench_adapter, bench_pipeline, bench_tracker, load_for_crop
from ..bench.report import REAL_VAL, TOPICS, run_report
from ..bench.table import crop_for_setting, run_table
from ..resources import far_model_for, far_model_given
from ..detector import default_model_path
from ..detector.fartiles import FarTiles
from ..detector.farband import FarBand, SplitDetector, band_rows_for, band_split_for, far_rows_for
from ..detector.verifier import load_verifier
from ..detector.parallel import ForwardPlan
from ..errors import ConfigError
from ..params import PARAMS, check_options
from ..geometry.calib import load_calibration
from ..timing import format_runs, format_table, summarize_runs
from ..words import plural


def forward_plan(threads: int, strip: bool, sequential: bool = False) -> ForwardPlan:
    """:meth:`ForwardPlan.of` (the nodes' rule), or with ``sequential`` (``--sequential``) the two forwards one
    after the other, each network on all ``threads``: the design the rule replaces, for comparison."""
    return ForwardPlan(False, threads) if sequential else ForwardPlan.of(threads, strip)


def _network_kw(args: argparse.Namespace) -> dict:
    """The networks' precision and device options of ``bench pipeline`` (``--bf16``, ``--device``, ``--fp16``)."""
    return dict(bf16=args.bf16, device=args.device, fp16=args.fp16)


def _bench_pipeline(args: argparse.Namespace, calib) -> dict:
    if args.input:
        calib = replace(calib, crop=crop_for_setting(calib.crop, args.input, calib.image_width, calib.image_height))
    band = band_rows_for(args.band_rows, calib, args.far_rows, "--band-rows")
    if args.input and band.crop != calib.crop:
        raise ConfigError("--band-rows", None, "sets the band's rows: not with --input, which sets the whole crop")
    calib = band.apply(calib)
    far_rows = far_rows_for(args.far_rows, calib, "--far-rows")  # a bad value fails before any model loads
    if far_model_given(args.far_model) and far_rows.crop is None:
        raise ConfigError("--far-model", None, f"needs a far band ({far_rows.what})")
    check_options({"--far-every": ("far_every", args.far_every), "--far-tiles": ("far_tiles", args.far_tiles)})
    plan = forward_plan(args.threads, far_rows.crop is not None, args.sequential)
    split = band_split_for(args.band_split, calib, "--band-split")
    if split.upper is None:
        det = load_for_crop(args.model, args.backend, calib.crop, plan.network_threads, **_network_kw(args))
    else:
        det = SplitDetector.load(args.model or default_model_path(), split, backend=args.backend,
                                 threads=plan.network_threads, **_network_kw(args))
    far = FarBand.for_calibration(far_model_for(args.far_model, det.source), args.far_rows, calib, "--far-rows", "--far-model",
                                  verifier=load_verifier(args.far_verifier, "--far-verifier"),
                                  backend=args.backend, threads=plan.network_threads, **_network_kw(args))
    tiles = FarTiles.for_setting(far.detector.source if far else None, args.far_tiles, far, args.far_every,
                                 "--far-tiles", backend=args.backend, threads=plan.network_threads, **_network_kw(args))
    result = bench_pipeline(calib, det, rendered_frames(calib, max(1, args.scenes)), args.frames, args.warmup, far,
                            plan.concurrent, args.far_every, tiles)
    result["far_rows"] = f"{far.crop.v0},{far.crop.v1}" if far is not None else "none"
    result["far_band"] = far_rows.what if split.upper is None else f"{far_rows.what}; {split.what}"
    result["band_split"] = split.what
    result["far_model"] = far.detector.source if far is not None and args.far_model else ""
    result["forwards"] = plan.describe() if far is not None else ""
    result["far_every"] = args.far_every if far is not None else None
    result["setting"] = args.input or "calibration"
    result["threads"] = args.threads
    return result


def _repeat_pipeline(args: argparse.Namespace) -> int:
    """``bench pipeline --repeat N``: N runs of ``bench pipeline --json``, each in its own process."""
    cmd = [sys.executable, "-m", "cone_perception.cli", "bench", "pipeline", "--json",
           "--frames", str(args.frames), "--warmup", str(args.warmup), "--calib", str(args.calib),
           "--threads", str(args.threads), "--backend", args.backend, "--scenes", str(args.scenes)]
    cmd += (["--model", str(args.model)] if args.model else []) + (["--bf16"] if args.bf16 else [])
    cmd += ["--device", args.device] + (["--fp16"] if args.fp16 else [])
    cmd += ["--input", args.input] if args.input else []
    cmd += (["--far-rows", args.far_rows] if args.far_rows is not None else []) + (["--far-model", args.far_model] if args.far_model else [])
    cmd += ["--sequential"] if args.sequential else []
    cmd += ["--far-every", str(args.far_every)] if args.far_every != PARAMS["far_every"].default else []
    cmd += ["--far-tiles", str(args.far_tiles)] if args.far_tiles != PARAMS["far_tiles"].default else []
    cmd += ["--band-rows", args.band_rows] if args.band_rows is not None else []
    cmd += ["--band-split", args.band_split] if args.band_split is not None else []
    runs = []
    for i in tqdm(range(args.repeat), unit="run", desc="bench pipeline", file=sys.stderr,
                  disable=args.json or args.no_progress):
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise ConfigError("bench", "--repeat", f"run {i + 1} failed (exit {proc.returncode}): "
                              f"{proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else 'no message'}")
        runs.append(json.loads(proc.stdout))
    summary = summarize_runs(runs)
    if args.json:
        json.dump({"summary": summary, "runs": runs}, sys.stdout, indent=1)
        print()
        return 0
    r0 = runs[0]
    print(f"bench pipeline ({r0['setting']}) x {args.repeat} processes: {r0['input']} -> {r0['output']}; model "
          f"{r0['model']} ({r0['backend']}, {plural(r0['threads'], 'thread')}), {args.frames} frames each")
    print(format_runs(summary))
    return 0


def run_bench(args: argparse.Namespace) -> int:
    if args.target == "report":
        topics = list(TOPICS) if args.topics == "all" else [t.strip() for t in args.topics.split(",") if t.strip()]
        took = run_report(args.doc, topics, args.quick, args.work, args.val or REAL_VAL, not args.no_progress)
        print(f"bench report: wrote {', '.join(f'{t} ({s:.0f} s)' for t, s in took.items())} into {args.doc}")
        return 0
    if args.frames < 1 or args.warmup < 0:
        raise ConfigError("bench", "--frames/--warmup", "need --frames >= 1 and --warmup >= 0")
    if args.repeat < 1 or (args.repeat > 1 and args.target != "pipeline"):
        raise ConfigError("bench", "--repeat", "need --repeat >= 1; more than one run is for `bench pipeline`")
    calib = load_calibration(args.calib)
    if args.target == "tracker":
        return _bench_tracker(args, calib)
    if args.target == "table":
        return run_table(args, calib)
    if args.target == "pipeline" and args.repeat > 1:
        return _repeat_pipeline(args)
    if args.target == "pipeline":
        result = _bench_pipeline(args, calib)
        if args.json:
            return _print_json(result)
        print(f"bench pipeline ({result['setting']}): {result['input']} -> {result['output']}, model input "
              f"{result['model_input'][0]}x{result['model_input'][1]}; model {result['model']} "
              f"({result['backend']} on {result['runs_on']}, {plural(result['threads'], 'thread')}), {args.frames} frames, "
              f"{result['boxes_per_frame']:.1f} boxes/frame; {result['far_band']}")
        print(format_table(result["stages"]))
        if (result["far_every"] or 1) > 1:  # bimodal: frames with the strip and without
            print(f"far strip on one frame in {result['far_every']}: frames/s over the mean end to end "
                  f"{result['fps_mean']:.1f}")
        print(f"frames/s (median end to end): {result['fps']:.1f}   everything but the forward: "
              f"{result['non_forward_median_ms']:.2f} ms   peak RSS: {result['peak_rss_mb']:.0f} MiB")
        if result["forwards"]:
            st = result["stages"]
            print(f"far strip {result['far_rows']} ({result['forwards']}): its own time {st['far_band']['median_ms']:.2f} ms "
                  f"(forward {st['far_forward']['median_ms']:.2f}), adds {st['far_wait']['median_ms']:.2f} ms to the frame "
                  "(medians; far_band - far_wait: the time hidden behind the band's detect)")
        return 0
    result = bench_adapter(calib, args.encoding, args.frames, args.warmup)
    result["threads"] = args.threads
    s = result["stages"]
    if args.json:
        return _print_json(result)
    print(f"bench {args.target}: {result['input']} -> {result['output']}, {args.frames} frames, {plural(args.threads, 'thread')}")
    print(format_table(s))
    print(f"frames/s (median): {result['fps']:.1f}   peak RSS: {result['peak_rss_mb']:.0f} MiB")
    return 0


def _bench_tracker(args: argparse.Namespace, calib) -> int:
    """``bench tracker``: :meth:`ConeTracker.update` (motion from the cones: registration, association,
    Kalman update) per frame of a simulated drive through rows of cones, seen through the calibration's band."""
    if args.rows < 1:
        raise ConfigError("bench", "--rows", f"must be >= 1, got {args.rows}")
    result = bench_tracker(calib, args.rows, args.frames, args.warmup)
    s = result["stages"]
    if args.json:
        return _print_json(result)
    print(f"bench tracker: {args.frames} frames of a simulated drive ({args.rows} rows of cones, {calib.camera} band), "
          f"{result['tracks_mean']:.0f} tracks and {result['cones_per_frame']:.0f} cones a frame on average; "
          "motion from the cones")
    print(format_table(s))
    return 0


def _print_json(result: dict) -> int:
    """``--json``: the result on stdout, nothing else."""
    json.dump(result, sys.stdout, indent=1)
    print()
    return 0
