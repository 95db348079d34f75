"""The one entry of ``cone-perception replay``: a bag offline (no ROS, :mod:`.offline`) or through live node
processes (:mod:`cone_perception.rostools.live_replay`), with the tracker when asked (:mod:`.tracking`); prints
frames, throughput, stage latencies, drops and, with ground truth, the localisation, attitude and tracking
tables.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import fields as dataclass_fields
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..attitude import ImuAttitude
from ..data.bagio import bag_topics, check_new_output
from ..data.bags import read_attitude_truth, read_ground_truth, read_twists
from ..data.outfiles import print_written, refuse_existing, remove_bag
from ..resources import far_model_for, far_model_given
from ..detector import Detector, default_model_path
from ..detector.fartiles import FarTiles
from ..detector.farband import FarBand, SplitDetector, band_rows_for, band_split_for, far_rows_for
from ..detector.verifier import load_verifier, verifier_path_for
from ..detector.parallel import ForwardPlan
from ..detector.model_files import attitude_config_for, box_model_or_default, far_reading_for
from ..errors import ConfigError
from ..evaluation import GT_MIN_VISIBLE, LocalisationReport, format_localisation
from ..evaluation.attitude import attitude_plot, format_attitude_report
from ..evaluation.tracking import DriveEvaluation, format_drive_evaluation
from ..geometry.calib import load_calibration, resolve_calibration_path
from ..params import PARAMS, check_options
from ..pipeline import Pipeline
from ..synth.boxlook import real_box_behaviour
from ..timing import format_table, summarize
from ..tracking import TrackerConfig
from .offline import offline_replay
from .tracking import ReplayTracking, drive_truth_beside, format_replay_tracking


def _progress(disable: bool):
    return lambda it, total: tqdm(it, total=total, unit="frame", disable=disable, file=sys.stderr)


def run_replay(args: argparse.Namespace) -> int:
    calib = load_calibration(args.calib)
    if args.live and (args.drop_detections or args.odom_topic or args.track_conf is not None
                      or args.tracker or args.max_range is not None):
        raise ConfigError("--live", None, "--drop-detections, --odom-topic, --track-conf, --tracker and --max-range "
                                          "work offline only")
    if args.live and args.box_behaviour != "as-is" or args.box_jitter is not None and args.box_behaviour != "real":
        raise ConfigError("--box-behaviour" if args.live else "--box-jitter", None,
                          "--box-behaviour real works offline only; --box-jitter needs it")
    if args.track_conf is not None and not (args.track and 0.0 < args.track_conf < args.conf):
        raise ConfigError("--track-conf", None, f"needs --track and a score in (0, --conf {args.conf:g}), got {args.track_conf:g}")
    if args.max_range is not None and not (np.isfinite(args.max_range) and args.max_range > 0):
        raise ConfigError("--max-range", None, f"must be a positive number of metres, got {args.max_range:g}")
    if args.tracker and not args.track:
        raise ConfigError("--tracker", None, "needs --track")
    check_options({"--min-height-ratio": ("min_height_ratio", args.min_height_ratio),
                   "--one-ray-range": ("one_ray_range_m", args.one_ray_range),
                   "--far-every": ("far_every", args.far_every), "--far-tiles": ("far_tiles", args.far_tiles)})
    if args.far_tiles and args.box_behaviour == "real":
        raise ConfigError("--far-tiles", None, "not with --box-behaviour real (it acts on the far band's own network)")
    if args.live and args.min_height_ratio != PARAMS["min_height_ratio"].default:
        raise ConfigError("--min-height-ratio", None, "works offline only (live: the nodes' min_height_ratio)")
    if args.live and args.one_ray_range != PARAMS["one_ray_range_m"].default:
        raise ConfigError("--one-ray-range", None, "works offline only (live: the nodes' one_ray_range_m)")
    if args.max_range is not None:
        calib = replace(calib, max_range_m=float(args.max_range))
    band = band_rows_for(args.band_rows, calib, args.far_rows, "--band-rows")
    if args.live == "separate" and band.crop != calib.crop:
        raise ConfigError("--band-rows", None, "needs the fused pipeline node (--live fused or offline)")
    if band.crop != calib.crop:
        print(f"replay: {band.what}")
    calib = band.apply(calib)
    split = band_split_for(args.band_split, calib, "--band-split")  # a bad value fails before any model loads
    if args.live and split.upper is not None:
        raise ConfigError("--band-split", None, "offline only (the nodes run the band in one piece)")
    far_rows = far_rows_for(args.far_rows, calib, "--far-rows")  # a bad value fails before any model loads
    if args.live == "separate" and far_rows.crop is not None:
        if args.far_rows is not None:
            raise ConfigError("--far-rows", None, "needs the fused pipeline node (--live fused or offline)")
        print("replay: no far strip with --live separate (the detection node runs the band only)")
    if far_model_given(args.far_model) and far_rows.crop is None:
        raise ConfigError("--far-model", None, f"needs a far band ({far_rows.what})")
    refuse_existing([p for p in (args.out, args.json) if p is not None], args.force, "replay")
    if args.out is not None:
        if args.force and args.out.exists():
            remove_bag(args.out)
        check_new_output(args.out, "replay")
    if args.live:
        summary = _run_live(args, calib)
    else:
        summary = _run_offline(args, calib)
    if args.json:
        args.json.write_text(json.dumps(summary, indent=1))
        print_written([args.json], "replay")
    return 1 if summary.get("died") else 0


def _imu_source(args, calib):
    """An ImuAttitude when the bag has the IMU topic and the mode may use it, else None."""
    if args.attitude in ("fixed", "image") or not calib.has_attitude_model and args.attitude is None:
        return None
    if args.imu_topic not in bag_topics(args.bag):
        if args.attitude in ("imu", "fused"):
            raise ConfigError(str(args.bag), args.imu_topic, f"--attitude {args.attitude} needs this IMU topic in the bag")
        return None
    try:
        rest = tuple(float(v) for v in args.imu_rest.split(","))
        assert len(rest) == 2 and all(np.isfinite(rest))
    except (ValueError, AssertionError):
        raise ConfigError("--imu-rest", None, f"must be PITCH,ROLL in degrees, got {args.imu_rest!r}") from None
    return ImuAttitude(rest)


def box_model_choice(args) -> str:
    """``model`` or ``rendered``: how the image attitude reads the boxes, offline and in the live nodes
    (their ``box_model``) alike: ``--box-model``; ``auto``: rendered with ``--gt-topic`` (a synthetic drive with
    truth) unless ``--box-behaviour real``, else model."""
    if args.box_model != "auto":
        return args.box_model
    return "rendered" if args.gt_topic and args.box_behaviour != "real" else "model"


def offline_pipeline(args: argparse.Namespace, calib) -> Pipeline:
    """The :class:`Pipeline` of an offline replay with ``replay``'s options (``args``: the attributes of its parsed
    command line that build it, ``--model`` to ``--one-ray-range``), for ``calib`` as ``replay`` has prepared it (band
    rows, range). Used by ``replay`` and the validation suite (:mod:`.suite`), so both judge the very same stages."""
    # built for the calibration's band, as the pipeline node does (a fixed-size backend never letterboxes)
    conf = args.track_conf if args.track_conf is not None else args.conf  # the pipeline splits at --conf
    strip_on = far_rows_for(args.far_rows, calib, "--far-rows").crop is not None  # auto (None): the calibration's
    plan = ForwardPlan.of(args.threads, strip_on)  # with a strip and 2 threads: both forwards at once
    split = band_split_for(args.band_split, calib, "--band-split")
    if split.upper is None:
        det = Detector.load_for_band(args.model or default_model_path(), (calib.crop.out_width, calib.crop.out_height),
                                     backend=args.backend, conf=conf, threads=plan.network_threads or None, bf16=args.bf16)
        det.warmup()
    else:
        print(f"replay: {split.what}")
        det = SplitDetector.load(args.model or default_model_path(), split, backend=args.backend, conf=conf,
                                 threads=plan.network_threads or None, bf16=args.bf16)
    far_model = far_model_for(args.far_model, det.source)
    far = FarBand.for_calibration(far_model, args.far_rows, calib, "--far-rows", "--far-model",
                                  say=lambda t: print(f"replay: {t}"),
                                  verifier=load_verifier(args.far_verifier, "--far-verifier"), backend=args.backend, conf=conf,
                                  threads=plan.network_threads or None, bf16=args.bf16)
    imu = _imu_source(args, calib)
    # the fit reads each network's boxes through its own box model (the far strip's of a far model: issue 26f)
    att_cfg, att_what = attitude_config_for(box_model_choice(args), det.source, far_model if far else None, True,
                                            args.far_box_model)
    if args.box_behaviour == "real":  # the real frames' boxes on a rendered drive, each network's as its box model says
        far_real = far_reading_for("model", far_model if far else None, det.source, False, "own")[0]
        far_table = far_reading_for("rendered", far_model if far else None, det.source, True)[0]  # its rendered offset
        det, far = real_box_behaviour(det, far, box_model_or_default(det.source), args.box_jitter,
                                      far_real.box_model if far_real is not None else None,
                                      far_rendered_table=far_table.table if far_table is not None else ())
    pipeline = Pipeline(calib, det, args.attitude, imu, far, cones_conf=args.conf if args.track_conf is not None else None,
                        attitude_config=att_cfg, concurrent=plan.concurrent, min_height_ratio=args.min_height_ratio,
                        one_ray_range_m=args.one_ray_range,
                        far_every=args.far_every, far_tiles=FarTiles.for_setting(
                            far_model, args.far_tiles, far, args.far_every, "--far-tiles", backend=args.backend, conf=conf,
                            threads=plan.network_threads or None, bf16=args.bf16))
    if pipeline.attitude_mode in ("image", "fused"):
        print(f"replay: the image attitude reads the boxes through {att_what}")
    return pipeline


def _run_offline(args, calib) -> dict:
    tracking = _tracking(args, calib)  # its bad options fail before the model loads
    pipeline = offline_pipeline(args, calib)
    far = pipeline.far
    with pipeline:  # joins the strip's worker thread, if one ran
        res = offline_replay(args.bag, pipeline, args.topic, args.out, args.gt_topic,
                             _progress(args.no_progress), imu_topic=args.imu_topic, tracking=tracking)
    stages = res.timer.summary()
    n = res.stats.ok
    print(f"replay (offline) {args.bag}: {n} frames processed, {res.stats.summary()}")
    for stamp, why in res.drops[:10]:
        print(f"  dropped frame at {stamp} ns: {why}")
    print(f"throughput: {n / res.wall_s if res.wall_s else 0:.1f} frames/s over {res.wall_s:.1f} s")
    print(format_table(stages))
    if res.localisation:
        print(format_localisation(res.localisation))
        print(format_attitude_report(res.localisation["attitude"]))
    if res.pipeline_attitude is not None:
        print(f"attitude ({res.attitude_mode}): " + ", ".join(f"{k} {v}" for k, v in res.pipeline_attitude.items()))
    if res.tracking:
        print(format_replay_tracking(res.tracking))
    if args.out:
        print_written([args.out], "replay")
    if far is not None:
        print(f"far band: {format_strip_counts(pipeline)}")
    print("boxes dropped: " + ", ".join(f"{k} {v}" for k, v in pipeline.mapper.dropped.items())
          + f" (a flat box: lower than {args.min_height_ratio:g} x a cone there)")
    if args.attitude_png:
        stamps = sorted(res.attitude)
        attitude_plot(args.attitude_png, stamps, [res.attitude[s] for s in stamps], read_attitude_truth(args.bag),
                      f"{args.bag.name}: attitude {res.attitude_mode}")
        print_written([args.attitude_png], "replay")
    return {"mode": "offline", "frames": n, "dropped": dict(res.stats.dropped), "wall_s": res.wall_s,
            "stages": stages, "localisation": res.localisation, "tracking": res.tracking,
            "attitude_fits": res.pipeline_attitude, "boxes_dropped": dict(pipeline.mapper.dropped),
            "far_strip": strip_summary(pipeline) if far is not None else None}


def strip_summary(pipeline) -> dict:
    """The replay summary's ``far_strip``: its rows at the calibration's attitude, whether it moves, frames
    with it and those where the attitude would have moved it out of the image (clamped)."""
    far = pipeline.far
    return {"rows": [far.crop.v0, far.crop.v1], "moves": far.plan is not None, **pipeline.strip_counts}


def format_strip_counts(pipeline) -> str:
    s = strip_summary(pipeline)
    how = "moved with the attitude" if s["moves"] else "fixed"
    return (f"rows {s['rows'][0]}-{s['rows'][1]} at the calibration's attitude ({how}), {s['frames']} frames, "
            f"clamped to the image in {s['clamped']}" + (f", skipped (far_every) in {s['skipped']}" if "skipped" in s else "")
            + (f", of those run as tiles {s['tiles']}, as the whole strip (tiles too wide) {s['tiles_full']}"
               if "tiles" in s else "")
            + (f", boxes dropped by its verifier {s['verifier_dropped']}" if "verifier_dropped" in s else ""))


def tracker_config(settings: list[str]) -> TrackerConfig:
    """A :class:`TrackerConfig` with ``FIELD=VALUE`` settings (``--tracker``); a bad one raises ConfigError naming it."""
    config, fields = TrackerConfig(), {f.name: f for f in dataclass_fields(TrackerConfig)}
    for item in settings:
        name, sep, text = item.partition("=")
        if not sep or name not in fields:
            raise ConfigError("--tracker", item, f"must be FIELD=VALUE with a TrackerConfig field ({', '.join(fields)})")
        kind = type(getattr(config, name))
        try:
            if kind is bool:
                if text.lower() not in ("true", "false", "1", "0"):
                    raise ValueError(text)
                value = text.lower() in ("true", "1")
            else:
                value = kind(text)
                if not np.isfinite(value) and not (kind is float and np.isposinf(value)):
                    raise ValueError(text)
        except ValueError:
            raise ConfigError("--tracker", item, f"{name} takes a {kind.__name__}, got {text!r}") from None
        setattr(config, name, value)
    return config


def _tracking(args, calib):
    """The replay's tracking (``--track``, ``--drop-detections``), or None."""
    if not args.track and args.drop_detections == 0:
        return None

    truth = drive_truth_beside(args.bag) if args.gt_topic else None
    twists = read_twists(args.bag, args.odom_topic) if (args.odom_topic and args.track) else None
    config = tracker_config(args.tracker)
    if args.track_conf is not None:
        config.strong_score = args.conf
    return ReplayTracking(calib, args.track, args.drop_detections, args.drop_seed, truth, twists, config)


def _run_live(args, calib) -> dict:
    from ..rostools.live_replay import live_replay, write_result_bag  # rclpy, and it sets the DDS environment

    params = {"calibration": str(resolve_calibration_path(args.calib)), "backend": args.backend, "conf": args.conf}
    if args.model:
        params["model"] = str(Path(args.model).resolve())
    params["threads"] = args.threads
    if args.box_model != "auto" or args.gt_topic:  # as offline: a rendered drive's boxes through the rendered tables
        params["box_model"] = box_model_choice(args)
    if args.far_rows is not None:
        params["far_rows"] = args.far_rows
    for name in ("far_every", "far_tiles"):
        if getattr(args, name) != PARAMS[name].default:
            params[name] = getattr(args, name)
    if args.band_rows is not None:
        params["band_rows"] = args.band_rows
    if far_model_given(args.far_model):
        params["far_model"] = str(Path(args.far_model).resolve())
    elif args.far_model is not None:
        params["far_model"] = args.far_model
    if args.far_verifier is not None:  # the file it stands for, absolute (the node runs elsewhere), or none
        path = verifier_path_for(args.far_verifier)
        params["far_verifier"] = str(path.resolve()) if path is not None else "none"
    if args.far_box_model != "band":  # the pipeline node's far_box_model, where not its default
        params["far_box_model"] = args.far_box_model
    if args.bf16:
        params["bf16"] = True
    res = live_replay(args.bag, mode=args.live, topic=args.topic, params=params, pace=args.pace,
                      progress=_progress(args.no_progress), track=args.track)
    got = len(res.cones)
    print(f"replay (live, {args.live} nodes, {args.pace}) {args.bag}: {res.sent} frames sent, {got} /cones received, "
          f"{len(res.lost)} lost" + (f", {len(res.tracked)} /cones/tracked received" if args.track else ""))
    for exe, code in res.died.items():
        tail = "\n".join(res.node_output.get(exe, "").strip().splitlines()[-15:])
        print(f"replay: node {exe} died during the replay (exit code {code}); its last output:\n{tail}", file=sys.stderr)
    lat = summarize([v / 1e3 for v in res.latency_ms.values()])
    print(format_table({"frame->/cones": lat}))
    if got:
        print(f"throughput: {got / res.wall_s:.1f} frames/s over {res.wall_s:.1f} s")
    loc = None
    if args.gt_topic:
        truth = read_ground_truth(args.bag, args.gt_topic)
        rep = LocalisationReport(max_range_m=calib.max_range_m, min_visible=GT_MIN_VISIBLE)
        for stamp, cones in sorted(res.cones.items()):
            if stamp in truth:
                rep.add_frame(cones, truth[stamp])
        loc = rep.summary()
        print(format_localisation(loc))
    tracking = _live_tracking(args, res) if args.track and args.gt_topic else None
    if args.out:
        write_result_bag(res, args.out)
        print_written([args.out], "replay")
    return {"mode": f"live-{args.live}", "sent": res.sent, "received": got, "lost": len(res.lost),
            "latency": lat, "wall_s": res.wall_s, "localisation": loc, "died": res.died, "tracking": tracking}


def _live_tracking(args, res) -> dict | None:
    """The tracking table of a live replay (``--track --gt-topic`` on a synthetic bag); no ego-motion figures."""
    truth = drive_truth_beside(args.bag)
    if truth is None:
        print(f"replay: no {Path(args.bag).name}_gt.jsonl beside the bag: tracking not scored", file=sys.stderr)
        return None
    ev = DriveEvaluation(truth)
    for stamp in sorted(res.cones):
        ev.add_raw(stamp, res.cones[stamp])
    for stamp in sorted(res.tracked):
        ev.add_tracked(stamp, res.tracked[stamp])
    summary = ev.summary()
    print(format_drive_evaluation(summary))
    return summary
