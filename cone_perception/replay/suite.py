"""The validation suite (``cone-perception validate``, issue 41): the pipeline's settings judged on a fixed list of
rendered drives (:data:`~.suite_drives.DRIVES`) and on the real labelled sets (:data:`~.suite_drives.REAL_SETS`),
one row each, and the distribution over the drives (:mod:`cone_perception.evaluation.spread`).

Each drive is rendered once (``synth bag``, kept in the cache folder: a rerun only replays; a drive whose
specification changed is rendered again) and replayed offline as ``replay --gt-topic /cones_gt --track`` replays
it, through the same :class:`~cone_perception.pipeline.Pipeline` (:func:`.run.offline_pipeline`) with the node's
defaults: the image attitude (the node's default where the calibration has a mount pose), the tracker fed with
the bag's odometry (the node's ``odom_topic``). Its figures: ``/cones`` and ``/cones/tracked`` recall by range
band to 40 m, false cones per frame within 40 m, and the median position error by band with the attitude used and
with the same boxes through the fixed H. A real set runs ``detect`` as the car runs its camera (band and far
strip) and ``eval`` in the band.

A drive that fails (any error) is a failed row with the error, its traceback in its log, and the others run; the
run then ends with 1. A real set not on disk is reported by name, with the command that builds it. Each entry's
output (the replay's lines, the detector's notes and warnings) goes to ``OUT/logs/NAME.log``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import traceback
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import asdict, dataclass
from pathlib import Path

from tqdm import tqdm

from ..attitude import FIXED
from ..data.bags import read_ground_truth, read_twists
from ..data.outfiles import print_written, remove_bag
from ..detector import DEFAULT_BACKEND, RUNTIME_THREADS
from ..detector.farband import BAND_SPLIT_OFF, FAR_ROWS_AUTO, band_rows_for
from ..detector.verifier import load_verifier
from ..errors import ConfigError
from ..evaluation import GT_MIN_VISIBLE, LocalisationReport, format_localisation
from ..evaluation.attitude import format_attitude_report
from ..evaluation.report import MIN_HEIGHT_PX, evaluate_predictions, write_report
from ..evaluation.spread import (
    FAILED, FIGURES, MISSING, OK, REAL_FIGURES, check_targets, distribution, drive_row, format_real, format_tables,
    format_targets, real_row, spread_plot, write_csv, write_json,
)
from ..geometry.calib import load_calibration
from ..mapping import ConeMapper
from ..params import DEFAULT_CONF, DEFAULT_IOU, PARAMS, check_options
from ..resources import far_model_given
from ..synth.writers import GT_TOPIC, ODOM_TOPIC, bag_side_paths, write_scene_bag
from ..tracking import TrackerConfig
from .detect import run_detect
from .offline import offline_replay
from .run import offline_pipeline
from .suite_drives import DRIVES, FPS, QUICK, REAL_SETS, SECONDS, DriveSpec, RealSet, drive_seed, tuning_drives
from .tracking import ReplayTracking, drive_truth_beside, format_replay_tracking


@dataclass
class Settings:
    """The pipeline settings the suite judges, as ``replay`` names them (``--far-rows`` -> ``far_rows``, ...); the
    defaults are the node's."""

    model: str | None = None
    backend: str = DEFAULT_BACKEND
    conf: float = DEFAULT_CONF
    threads: int = RUNTIME_THREADS
    far_rows: str | None = None
    far_model: str | None = None
    far_verifier: str | None = None
    far_box_model: str = PARAMS["far_box_model"].default
    far_every: int = PARAMS["far_every"].default
    far_tiles: int = PARAMS["far_tiles"].default
    band_rows: str | None = None
    band_split: str | None = None
    attitude: str = "image"
    box_model: str = "auto"
    box_behaviour: str = "as-is"
    min_height_ratio: float = PARAMS["min_height_ratio"].default
    one_ray_range: float = PARAMS["one_ray_range_m"].default


def replay_args(settings: Settings, bag: Path) -> argparse.Namespace:
    """The options ``replay BAG --gt-topic /cones_gt`` would have with these settings (what
    :func:`.run.offline_pipeline` reads)."""
    return argparse.Namespace(**asdict(settings), bag=bag, bf16=False, track_conf=None, box_jitter=None,
                              imu_topic="/imu", imu_rest="0,0", gt_topic=GT_TOPIC)


def check_settings(settings: Settings) -> None:
    """ConfigError for settings that would fail every drive, before the first one (the option named)."""
    check_options({"--min-height-ratio": ("min_height_ratio", settings.min_height_ratio),
                   "--one-ray-range": ("one_ray_range_m", settings.one_ray_range),
                   "--far-every": ("far_every", settings.far_every), "--far-tiles": ("far_tiles", settings.far_tiles)})
    far_file = settings.far_model if far_model_given(settings.far_model) else None  # not auto / band
    for opt, path in (("--model", settings.model), ("--far-model", far_file)):
        if path is not None and not Path(path).is_file():
            raise ConfigError(path, None, f"{opt}: model file not found")
    load_verifier(settings.far_verifier, "--far-verifier")  # a missing or bad verifier file: refused here


def suite_list(drives, real) -> str:
    """The drives and real sets, one line each (``validate --list``)."""
    lines = [f"{d.name:<22} seed {d.seed:<7} {d.describe()}  ({d.note})" for d in drives]
    lines += [f"{r.name:<22} real   {r.path}: band rows {r.crop[0]}-{r.crop[1]} / {r.downscale}, far rows {r.far_rows}"
              for r in real]
    return "\n".join(lines)


def select(names: str | None, quick: bool, tuning: bool) -> tuple[tuple[DriveSpec, ...], tuple[RealSet, ...]]:
    """The drives and real sets to run: all, ``--quick``'s handful, or ``--drives NAME,...`` (drive or real-set names;
    with ``--tuning`` the drives' tuning twins, named ``tune-NAME`` or by the judging name)."""
    drives = tuning_drives() if tuning else DRIVES
    if names is None:
        if quick:
            drives = tuple(d for d in drives if d.name.removeprefix("tune-") in QUICK)
        return drives, REAL_SETS
    wanted = [n.strip() for n in names.split(",") if n.strip()]
    by_name = {**{d.name: d for d in drives}, **{d.name.removeprefix("tune-"): d for d in drives}}
    real = {r.name: r for r in REAL_SETS}
    unknown = [n for n in wanted if n not in by_name and n not in real]
    if unknown or not wanted:
        raise ConfigError("--drives", ",".join(unknown) or None,
                          f"unknown name; known: {', '.join([d.name for d in drives] + list(real))}")
    return (tuple(dict.fromkeys(by_name[n] for n in wanted if n in by_name)),
            tuple(dict.fromkeys(real[n] for n in wanted if n in real)))


def render(drive: DriveSpec, cache: Path, seconds: float = SECONDS, fps: float = FPS) -> tuple[Path, int]:
    """The drive's bag in ``cache`` (rendered unless the one there is of this very specification): ``(bag, seed)``."""
    spec = json.loads(json.dumps({**asdict(drive), "seconds": seconds, "fps": fps}))
    bag, meta = cache / drive.name, cache / f"{drive.name}.spec.json"
    if bag.is_dir() and meta.is_file():
        kept = json.loads(meta.read_text(encoding="utf-8"))
        if {**kept.get("spec", {}), "note": drive.note} == spec:  # the note renders nothing
            return bag, int(kept["seed"])
    for p in (meta, *bag_side_paths(bag)):  # another specification, or a render cut short: render again
        p.unlink(missing_ok=True)
    if bag.exists():
        remove_bag(bag)  # a rosbag2 folder only: anything else there is refused, not removed
    cache.mkdir(parents=True, exist_ok=True)
    seed = drive_seed(drive)
    write_scene_bag(drive.config(seed), seconds, fps, bag, drive.compressed, drive.speed_mps, drive.track, progress=False)
    meta.write_text(json.dumps({"spec": spec, "seed": seed}, indent=1), encoding="utf-8")
    return bag, seed


def fixed_h_localisation(boxes: dict, truth: dict, calib, settings: Settings) -> dict:
    """The localisation summary of a replay's boxes (stamp -> BOX_DTYPE) mapped through the calibration's fixed H."""
    mapper = ConeMapper(calib, settings.min_height_ratio, settings.one_ray_range)
    rep = LocalisationReport(max_range_m=calib.max_range_m, min_visible=GT_MIN_VISIBLE)
    for stamp in sorted(boxes):
        if stamp in truth:
            rep.add_frame(mapper.map_boxes(boxes[stamp], FIXED), truth[stamp])
    return rep.summary()


def run_drive(bag: Path, settings: Settings) -> dict:
    """One rendered drive through the pipeline as the node runs it: its row's figures (ConfigError / RuntimeError
    when it cannot run or no frame went through)."""
    calib = load_calibration(bag_side_paths(bag)[0])
    calib = band_rows_for(settings.band_rows, calib, settings.far_rows, "--band-rows").apply(calib)
    tracking = ReplayTracking(calib, True, truth=drive_truth_beside(bag), twists=read_twists(bag, ODOM_TOPIC),
                              config=TrackerConfig())
    pipeline = offline_pipeline(replay_args(settings, bag), calib)
    with pipeline:
        res = offline_replay(bag, pipeline, gt_topic=GT_TOPIC, tracking=tracking)
    if not res.localisation or not res.localisation["frames"]:
        raise RuntimeError(f"no frame went through ({res.stats.summary()})")
    fixed = fixed_h_localisation(res.boxes, read_ground_truth(bag, GT_TOPIC), calib, settings)
    print(f"{res.stats.ok} frames in {res.wall_s:.1f} s; /cones (attitude {res.attitude_mode}):")  # the drive's log
    print(format_localisation(res.localisation))
    print(format_attitude_report(res.localisation["attitude"]))
    print(format_replay_tracking(res.tracking))
    print("the same boxes through the fixed H:")
    print(format_localisation(fixed))
    att = res.localisation["attitude"]
    return {"frames": res.localisation["frames"], "frames_dropped": sum(res.stats.dropped.values()),
            "attitude": res.attitude_mode, "pitch_err_deg": att.get("median_abs_err_pitch_deg"),
            **drive_row(res.localisation, fixed, res.tracking)}


def run_real_set(real: RealSet, settings: Settings, out: Path) -> dict:
    """A real set through ``detect`` (the band and far strip, as the car; far rows: the set's unless the settings
    give rows or none) and ``eval`` in the band; its report in ``out``. A set not on disk: a missing row."""
    gt = Path(real.path)
    if not gt.is_dir():
        return {"status": MISSING, "error": f"{real.path} not found; build it with: {real.build}"}
    out.mkdir(parents=True, exist_ok=True)
    pred = out / "pred.jsonl"
    rows = settings.far_rows
    far_rows = real.far_rows if rows is None or str(rows).strip().lower() == FAR_ROWS_AUTO else rows
    split = settings.band_split
    band_split = None if split is None or split.strip().lower() in BAND_SPLIT_OFF else real.band_split
    run_detect(argparse.Namespace(source=gt, out=pred, model=settings.model, backend=settings.backend, bf16=False, imgsz=None,
                                  crop=real.crop, downscale=real.downscale, calib=None, band_split=band_split, far_rows=far_rows,
                                  far_model=settings.far_model, far_verifier=settings.far_verifier, conf=0.001, iou=DEFAULT_IOU,
                                  topic=None, save_vis=None, every=1, no_progress=True))
    res = evaluate_predictions(pred, gt, real.gt_names, conf=settings.conf, progress=False, verbose=False, band=real.crop)
    write_report(res, out, str(pred), str(gt))
    big = evaluate_predictions(pred, gt, real.gt_names, conf=settings.conf, progress=False, verbose=False,
                               band=real.crop, min_height=MIN_HEIGHT_PX)
    return {"status": OK, "images": res.metrics["inputs"]["images"], **real_row(res.metrics, big.metrics)}


def _entry(kind: str, item, settings: Settings, out: Path, cache: Path, seconds: float, fps: float) -> dict:
    """One drive or real set, its output in its log; any error makes it a failed row."""
    t0 = time.perf_counter()
    with open(out / "logs" / f"{item.name}.log", "w", encoding="utf-8") as log, redirect_stdout(log), redirect_stderr(log):
        try:
            if kind == "drive":
                bag, seed = render(item, cache, seconds, fps)
                row = {"status": OK, "seed": seed, "what": item.describe(), **run_drive(bag, settings)}
            else:
                row = run_real_set(item, settings, out / item.name)
        except Exception as e:  # noqa: BLE001 - a failed entry is a row; the others run
            traceback.print_exc(file=log)
            row = {"status": FAILED, "error": f"{type(e).__name__}: {e}"}
    return {"drive": item.name, **row, "wall_s": round(time.perf_counter() - t0, 1)}


def run_suite(drives: tuple[DriveSpec, ...], real_sets: tuple[RealSet, ...], settings: Settings, out: Path, cache: Path,
              seconds: float = SECONDS, fps: float = FPS, progress: bool = True, command: str = "") -> int:
    """Run the entries, print the tables and write ``suite.json``, ``drives.csv``, ``real.csv`` and ``spread.png``
    to ``out``; 1 when an entry failed, else 0."""
    check_settings(settings)
    (out / "logs").mkdir(parents=True, exist_ok=True)
    items = [("drive", d) for d in drives] + [("real", r) for r in real_sets]
    t0 = time.perf_counter()
    rows, real_rows = [], []
    bar = tqdm(items, unit="entry", disable=not progress, file=sys.stderr, desc="validate")
    for kind, item in bar:
        bar.set_postfix_str(item.name)
        row = _entry(kind, item, settings, out, cache, seconds, fps)
        (rows if kind == "drive" else real_rows).append(row)
    wall = time.perf_counter() - t0
    dist = distribution(rows)
    targets = check_targets(dist)
    if rows:
        print(format_tables(rows, dist))
        print(format_targets(targets))
    if real_rows:
        print(format_real(real_rows))
    failed = [r["drive"] for r in rows + real_rows if r["status"] == FAILED]
    missing = [r["drive"] for r in real_rows if r["status"] == MISSING]
    print(f"validate: {len(rows)} drives ({sum(r['status'] == OK for r in rows)} ran), {len(real_rows)} real sets, "
          f"{wall / 60:.1f} min; settings: " + ", ".join(f"{k} {v}" for k, v in asdict(settings).items()))
    report = {"command": command, "settings": asdict(settings), "seconds": seconds, "fps": fps, "wall_s": wall,
              "drives": rows, "distribution": dist, "targets": targets, "real_sets": real_rows, "failed": failed, "missing": missing}
    keys = ["drive", "status", "seed", "frames", "frames_dropped", "attitude", "pitch_err_deg", "wall_s"]
    files = [write_json(out / "suite.json", report),
             write_csv(out / "drives.csv", rows, keys + [f.key for f in FIGURES] + ["what", "error"]),
             write_csv(out / "real.csv", real_rows, ["drive", "status", "images", *(k for k, _ in REAL_FIGURES),
                                                     "wall_s", "error"])]
    if rows:
        n_ok = sum(r["status"] == OK for r in rows)
        files.append(spread_plot(out / "spread.png", rows, dist, f"validate: {n_ok} drives, attitude {settings.attitude}"))
    print_written(files, "validate")
    for name in missing:
        print(f"validate: real set {name} is missing (see its row); the rest ran", file=sys.stderr)
    if failed:
        print(f"validate: {len(failed)} failed: {', '.join(failed)} (their logs: {out / 'logs'})", file=sys.stderr)
    return 1 if failed else 0
