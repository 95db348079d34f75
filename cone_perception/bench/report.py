"""``cone-perception bench report``: the defaults' figures today, one table per topic, written into
``docs/benchmarks.md`` (the command: ``commands/bench.py``).

Each topic runs the package's own commands, each in a fresh process with ``--json`` (``bench pipeline``,
``detect`` + ``eval``, ``synth bag`` + ``replay``, ``bench tracker``, ``fuzz``, ``soak``): the figures are those
commands' figures, measured by the code they run (``bench/pipeline.py``, ``evaluation/``, ``replay/``), never
a copy of it. The topics (:data:`TOPICS`): ``speed`` (backend and threads), ``real`` (the real validation
clips), ``rendered`` (held-out rendered drives), ``validation`` (the rendered validation suite, ``validate``),
``attitude``, ``tracking``, ``robustness``.

The table of each topic goes between the markers ``<!-- bench report TOPIC -->`` and
``<!-- /bench report TOPIC -->`` of the document, under a line stamping the date, the commit, the machine
(CPU model, vector flags, cores, the load average before and after) and the mode (``--quick``: fewer frames,
shorter drives). A topic not asked for is left as it stands. A new table is a function ``(Runner) -> Section``
added to :data:`TOPICS`, with its pair of markers in the document.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from tqdm import tqdm

from ..errors import ConfigError

SRC = "bench report"
#: The real validation clips' classes, in the label ids' order (docs/evaluation.md).
REAL_NAMES = "blue_cone,large_orange_cone,orange_cone,yellow_cone"
#: The car's band on the real clips (the cards' protocol) and the far strip's rows there (issue 26).
REAL_BAND, REAL_STRIP = "96,672", "240,432"
#: Where ``data restore-aspect`` puts the real validation clips (docs/benchmarks.md; ``--val`` elsewhere).
REAL_VAL = Path("data/real_val_1080")
#: Held-out rendered drives (seeds never used for tuning): full and quick lengths in seconds.
DRIVES, QUICK_DRIVES = (2601, 2602), (2601,)
DRIVE_S, QUICK_DRIVE_S = 10, 3
RANGE_BANDS = ("0-7 m", "7-15 m", "15-25 m", "25-40 m")
#: CPU flags worth naming in the machine stamp (what the backends can use).
CPU_FLAGS = ("avx2", "fma", "avx512f", "avx512_vnni", "avx512_bf16", "amx_bf16", "amx_int8")


@dataclass
class Runner:
    """Runs ``cone-perception`` sub-commands in fresh processes, each once per report (cached by its arguments)."""

    work: Path
    quick: bool
    val: Path
    progress: tqdm | None = None
    cache: dict = field(default_factory=dict)

    def cli(self, *args: str, ok: tuple[int, ...] = (0,)) -> str:
        """Run ``cone-perception ARGS``; its stdout. An exit code not in ``ok`` raises naming the command and its last
        error line (``soak`` exits 1 where a target is missed: its table says so)."""
        key = tuple(args)
        if key not in self.cache:
            if self.progress is not None:
                self.progress.set_postfix_str(" ".join(args[:2]) if args[0] in ("bench", "synth") else args[0])
            proc = subprocess.run([sys.executable, "-m", "cone_perception.cli", *args], capture_output=True, text=True)
            if proc.returncode not in ok:
                err = proc.stderr.strip().splitlines()
                raise ConfigError(SRC, " ".join(args[:2]), f"`cone-perception {' '.join(args)}` failed (exit "
                                  f"{proc.returncode}): {err[-1] if err else 'no message'}")
            self.cache[key] = proc.stdout
            if self.progress is not None:
                self.progress.update(1)
        return self.cache[key]

    def json_out(self, *args: str, name: str, flag: str = "--json", ok: tuple[int, ...] = (0,)) -> dict:
        """Run a command that writes its figures to a JSON file (``flag FILE``); the file's content."""
        out = self.work / name
        self.cli(*args, flag, str(out), "--force", ok=ok)
        return json.loads(out.read_text())

    def drive(self, seed: int) -> tuple[Path, Path]:
        """A held-out rendered drive (``synth bag``; made once per work folder): the bag and its calibration."""
        secs = QUICK_DRIVE_S if self.quick else DRIVE_S
        bag = self.work / f"drive{seed}_{secs}s"
        if not bag.exists():
            self.cli("synth", "bag", "--seed", str(seed), "--seconds", str(secs), "--out", str(bag), "--no-progress")
        return bag, bag.with_name(bag.name + "_calib.yaml")

    def replay(self, seed: int, *extra: str) -> dict:
        """``replay`` of :meth:`drive` ``seed`` with ``--gt-topic`` and ``extra`` options: its JSON figures."""
        bag, calib = self.drive(seed)
        tag = "_".join(e.strip("-") for e in extra) or "defaults"
        return self.json_out("replay", str(bag), "--calib", str(calib), "--gt-topic", "/cones_gt", "--no-progress",
                             *extra, name=f"{bag.name}_{tag}.json")

    def drives(self) -> tuple[int, ...]:
        return QUICK_DRIVES if self.quick else DRIVES


@dataclass
class Section:
    """One topic's table: markdown lines, and the commands that anyone reruns for it."""

    lines: list[str]
    commands: list[str]
    notes: list[str] = field(default_factory=list)


def _f(x, digits: int = 3) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + ["| " + " | ".join(r) + " |" for r in rows]


def _ms(stages: dict, name: str) -> str:
    return _f(stages[name]["median_ms"], 1) if name in stages else "-"


def speed(r: Runner) -> Section:
    """``bench pipeline`` at the defaults (band + far strip) and the band alone, by backend and network threads, the
    row-scaled band (an option); and the YOLO11n-sized ``n`` network's forward alone on two threads (``speed``), the
    peer of issue 43's goal: each two-thread row's end to end against it."""
    frames, warmup = ("40", "5") if r.quick else ("300", "20")
    designs = [("defaults (band + far strip)", "onnx", t, ()) for t in (1, 2)]
    designs += [("defaults (band + far strip)", "torch", t, ()) for t in (1, 2)]
    designs += [("the band alone", "onnx", t, ("--far-rows", "none")) for t in (1, 2)]
    designs += [("row-scaled band + far strip (`--band-split auto`, an option)", "onnx", 2, ("--band-split", "auto"))]
    peer = json.loads(r.cli("speed", "--sizes", "n", "--backends", "onnx", "--threads", "2", "--imgsz", "960x288",
                            "--frames", "20" if r.quick else "100", "--json"))[0]["median_ms"]
    rows = []
    for what, backend, threads, extra in designs:
        d = json.loads(r.cli("bench", "pipeline", "--json", "--frames", frames, "--warmup", warmup, "--backend", backend,
                             "--threads", str(threads), "--encoding", "yuv422_yuy2", "--no-progress", *extra))
        s, e2e = d["stages"], d["stages"]["end_to_end"]
        rows.append([what, "ONNX Runtime" if d["backend"] == "onnx" else d["backend"], str(threads), _ms(s, "forward"),
                     _ms(s, "far_forward"), _f(e2e["median_ms"], 1), f"{e2e['p99_ms'] / e2e['median_ms']:.2f}x",
                     _f(d["fps"], 1), f"{peer / e2e['median_ms']:.2f}x" if threads == 2 else "-",
                     f"{d['peak_rss_mb']:.0f}"])
    rows.append(["YOLO11n-sized `n`, its forward alone (`speed`)", "ONNX Runtime", "2", _f(peer, 1), "-", "-", "-",
                 _f(1000.0 / peer, 1), "1.00x", "-"])
    head = ["design", "backend", "network threads", "band forward (ms)", "strip forward (ms)", "end to end (ms)",
            "p99 / median", "frames/s", "vs `n`'s forward", "peak RSS (MB)"]
    return Section(_table(head, rows), [f"cone-perception bench pipeline --frames {frames} --warmup {warmup} --encoding "
                                        "yuv422_yuy2 --backend onnx|torch --threads 1|2 [--far-rows none | --band-split auto]",
                                        "cone-perception speed --sizes n --backends onnx --threads 2 --imgsz 960x288 "
                                        f"--frames {20 if r.quick else 100}"],
                   [f"1920x1080 YUYV rendered scenes, {frames} timed frames a run after {warmup} of warm-up, one run "
                    "each, back to back; medians. \"vs `n`'s forward\": the YOLO11n-sized network's forward alone at "
                    "960x288 on two threads (the peer of issue 43's goal, 2x) over the row's end to end."])


def _eval(r: Runner, pred: Path, name: str, *extra: str) -> dict:
    out = r.work / name
    r.cli("eval", "--pred", str(pred), "--gt", str(r.val), "--gt-names", REAL_NAMES, "--out", str(out), *extra)
    return json.loads((out / "metrics.json").read_text())


def real(r: Runner) -> Section:
    """``detect`` + ``eval`` on the real validation clips: the band alone (the cards' protocol) and band + strip."""
    if not (r.val / "images").is_dir():
        raise ConfigError(str(r.val), None, "the real validation clips are not there; make them with `cone-perception "
                          "data restore-aspect ../shared/datasets/bgracing-real data/real_val_1080 --width 1920 --clips "
                          f"autox4,autox2,accel --names {REAL_NAMES}` (or pass --val)")
    rows = []
    for what, extra in (("band alone (the cards' protocol)", ()), ("defaults: band + far strip", ("--far-rows", REAL_STRIP))):
        tag = "strip" if extra else "band"
        pred = r.work / f"real_{tag}.jsonl"
        r.cli("detect", str(r.val), "--crop", REAL_BAND, "--downscale", "2", "--conf", "0.001", "--out", str(pred),
              "--no-progress", *extra)
        for proto, ev in (("whole frame", ()), ("in band", ("--band", REAL_BAND)),
                          ("in band, cones >= 12 px", ("--band", REAL_BAND, "--min-height", "12"))):
            m = _eval(r, pred, f"real_{tag}_{len(ev)}", *ev)
            d = m["detection"]
            rows.append([what, proto, _f(d["map50"]), _f(d["map50_95"]),
                         _f(m["by_box_height"]["at_least_min_height"]["recall"]),
                         _f(d["operating_point"]["per_class"]["all"]["precision"])])
    head = ["detector", "scored", "mAP@0.5", "mAP@0.5:0.95", "recall, boxes >= 12 px", "precision at 0.25"]
    return Section(_table(head, rows), [
        f"cone-perception detect {r.val} --crop {REAL_BAND} --downscale 2 --conf 0.001 [--far-rows {REAL_STRIP}] --out R.jsonl",
        f"cone-perception eval --pred R.jsonl --gt {r.val} --gt-names {REAL_NAMES} [--band {REAL_BAND} [--min-height 12]] --out DIR"],
        [f"{r.val}: the 71 frames of the held-out clips autox4, autox2, accel (640x360 video upscaled to 1920x1080); "
         "the car's band 96-672 at 960x288; recall and precision at score 0.25, IoU 0.5."])


def rendered(r: Runner) -> Section:
    """``replay`` of held-out rendered drives at the defaults: ``/cones`` recall by range band, false cones, error
    (two long drives; the suite's many short ones: :func:`validation`)."""
    rows = []
    for seed in r.drives():
        d = r.replay(seed, "--track")
        bands = d["tracking"]["raw"]["bands"]
        loc = d["localisation"]["extra_groups"]
        rows.append([str(seed)] + [_f(bands[b]["recall"]) for b in RANGE_BANDS]
                    + [_f(d["localisation"]["bands"]["false_per_frame"], 2)]
                    + [_f(loc[b]["median_err_m"]) for b in RANGE_BANDS])
    head = (["drive"] + [f"recall {b}" for b in RANGE_BANDS] + ["false cones per frame (< 40 m)"]
            + [f"median error {b} (m)" for b in RANGE_BANDS])
    return Section(_table(head, rows), _drive_commands(r, "--track"),
                   [f"`/cones` on rendered drives never used for tuning (seeds {', '.join(map(str, r.drives()))}, "
                    f"{QUICK_DRIVE_S if r.quick else DRIVE_S} s at 20 Hz, 1920x1080, jitter on), the defaults (far strip, "
                    "attitude `fused`); true cones at least half visible, counted to 40 m."])


def validation(r: Runner) -> Section:
    """``validate`` (the rendered validation suite, docs/validation.md) at the defaults: per figure the median, the worst
    tenth and the worst drive over its drives (``--quick``: a handful of them); the real set is the ``real`` topic's."""
    out = r.work / "validate"
    quick = ("--quick",) if r.quick else ()
    proc = subprocess.run([sys.executable, "-m", "cone_perception.cli", "validate", "--out", str(out), "--cache",
                           str(r.work / "validate_bags"), "--no-progress", *quick], capture_output=True, text=True)
    suite = json.loads((out / "suite.json").read_text()) if (out / "suite.json").is_file() else None
    if suite is None:  # exit 1 (a failed drive) still writes the suite's figures; anything else is the report's error
        err = proc.stderr.strip().splitlines()
        raise ConfigError(SRC, "validate", f"`cone-perception validate` failed (exit {proc.returncode}): "
                          f"{err[-1] if err else 'no message'}")
    if r.progress is not None:
        r.progress.update(1)
    return suite_section(suite, r.quick)


def suite_section(suite: dict, quick: bool) -> Section:
    """The ``validation`` table of a ``validate`` run's ``suite.json`` content: one row per figure, its spread."""
    from ..evaluation.spread import FIGURES

    dist = suite["distribution"]
    rows = [[f"{f.table}: {f.label}", _f(dist[f.key]["median"]), _f(dist[f.key]["worst_tenth"]),
             f"{_f(dist[f.key]['worst'])} ({dist[f.key]['worst_drive']})"] for f in FIGURES if f.key in dist]
    notes = [f"{len(suite['drives'])} rendered drives across cameras, mounts, lenses, scenes and motion (docs/validation.md; "
             f"judging seeds), {suite['seconds']:g} s at {suite['fps']:g} Hz each, the defaults as the node runs them; "
             "worst tenth: the 10th percentile of a recall, the 90th of a count or an error."]
    if suite.get("failed"):
        notes.append(f"failed drives: {', '.join(suite['failed'])}")
    return Section(_table(["figure", "median", "worst tenth", "worst (drive)"], rows),
                   [f"cone-perception validate --out DIR{' --quick' if quick else ''}"], notes)


def _drive_commands(r: Runner, extra: str) -> list[str]:
    secs = QUICK_DRIVE_S if r.quick else DRIVE_S
    return [f"cone-perception synth bag --seed SEED --seconds {secs} --out BAG      # SEED: {', '.join(map(str, r.drives()))}",
            f"cone-perception replay BAG --calib BAG_calib.yaml --gt-topic /cones_gt {extra} --json F"]


def attitude(r: Runner) -> Section:
    """``replay --attitude MODE`` on the held-out drives: the attitude's error against the truth, and what it does to
    the cones' placement 7-25 m ahead."""
    rows = []
    for seed in r.drives():
        for mode in ("fixed", "image", "imu", "fused"):
            d = r.replay(seed, "--track") if mode == "fused" else r.replay(seed, "--attitude", mode)
            a, loc = d["localisation"].get("attitude", {}), d["localisation"]["extra_groups"]
            rows.append([str(seed), mode + (" (replay's default)" if mode == "fused" else ""),
                         _f(a.get("median_abs_err_pitch_deg")), _f(a.get("p90_abs_err_pitch_deg")),
                         _f(a.get("median_abs_err_roll_deg")), _f(loc["7-15 m"]["median_err_m"]),
                         _f(loc["15-25 m"]["median_err_m"]), _ms(d["stages"], "attitude")])
    head = ["drive", "attitude", "median pitch error (deg)", "p90 pitch error (deg)", "median roll error (deg)",
            "median error 7-15 m (m)", "median error 15-25 m (m)", "attitude stage (ms)"]
    return Section(_table(head, rows), _drive_commands(r, "--attitude fixed|image|imu|fused"),
                   ["The drives of the rendered table; `fixed` is the calibration's pitch and roll, `imu` the bag's "
                    "IMU, `image` the fit to the boxes, `fused` both (`replay`'s default on a bag with an IMU; the nodes run "
                    "`image` unless their `attitude` parameter asks for `imu` or `fused`)."])


def tracking(r: Runner) -> Section:
    """``replay --track`` on the held-out drives (``/cones/tracked``), and the tracker's cost (``bench tracker``)."""
    rows = []
    for seed in r.drives():
        t = r.replay(seed, "--track")["tracking"]["tracked"]
        rows.append([str(seed)] + [_f(t["bands"][b]["recall"]) for b in RANGE_BANDS]
                    + [_f(sum(b["false_per_frame"] for b in t["bands"].values()), 2), _f(t["id_switches_per_100_frames"], 2),
                       _f(t["idf1"]), f"{100 * t['ego_median_err_frac']:.1f} %", _f(t["ego_median_err_yaw_deg"])])
    head = (["drive"] + [f"recall {b}" for b in RANGE_BANDS]
            + ["false per frame (< 40 m)", "id switches / 100 frames", "IDF1", "ego-motion error (of the distance)",
               "ego-motion yaw error (deg)"])
    frames = "60" if r.quick else "300"
    b = json.loads(r.cli("bench", "tracker", "--json", "--frames", frames))
    cost = (f"The tracker's update: {_f(b['stages']['tracker']['median_ms'], 2)} ms median per frame with "
            f"{b['tracks_mean']:.0f} tracks and {b['cones_per_frame']:.0f} cones a frame (`bench tracker`, {frames} frames).")
    return Section(_table(head, rows), _drive_commands(r, "--track") + [f"cone-perception bench tracker --frames {frames}"],
                   ["`/cones/tracked` on the drives of the rendered table, motion from the cones (no odometry).", cost])


def robustness(r: Runner) -> Section:
    """``fuzz`` (malformed messages through each node's callbacks) and ``soak`` (a rendered drive into the live
    pipeline node at 30 Hz)."""
    n = "200" if r.quick else "2000"
    fz = r.json_out("fuzz", "--n", n, "--no-progress", name="fuzz.json")
    rows = [[t["target"], str(t["messages"]), str(t["crashes"]), str(t["counted"]), str(t["ok"]), _f(t["max_ms"], 1),
             f"{t['rss_start_mb']:.0f} -> {t['rss_end_mb']:.0f}"] for t in fz["targets"]]
    lines = _table(["node (fuzz)", "messages", "crashes", "counted", "ok", "max ms / message", "RSS (MB)"], rows)
    secs = "10" if r.quick else "60"
    sk = r.json_out("soak", "--rate", "30", "--seconds", secs, "--window", str(int(secs) // 2), "--no-progress",
                    name="soak.json", ok=(0, 1))  # 1: a target missed, said in the table
    lines += ["", *_table(["soak", "sent", "processed", "replaced in the queue", "dropped", "uncounted", "RSS growth",
                           "latency p50 / p99 (ms)", "targets met"],
                          [[f"30 Hz, {secs} s", str(sk["sent"]), str(sk["processed"]), str(sk["replaced"]),
                            str(sum(sk["dropped"].values())), str(sk["uncounted"]), f"{100 * sk['rss_growth']:+.1f} %",
                            f"{sk['latency_p50_ms']:.0f} / {sk['latency_p99_ms']:.0f}", "yes" if sk["passed"] else "no"]])]
    return Section(lines, [f"cone-perception fuzz --n {n} --json F",
                           f"cone-perception soak --rate 30 --seconds {secs} --window {int(secs) // 2} --json F"],
                   ["docs/robustness.md says what each counter means; the kill-and-restart figures are there too."])


#: Topic name -> its measurement, in the document's order.
TOPICS = {"speed": speed, "real": real, "rendered": rendered, "validation": validation, "attitude": attitude,
          "tracking": tracking, "robustness": robustness}
#: Topics that replay the held-out drives (each drive rendered and replayed at the defaults once per report).
DRIVE_TOPICS = ("rendered", "attitude", "tracking")


def planned_runs(topics: list[str], quick: bool) -> int:
    """How many sub-commands a report of ``topics`` runs (the progress bar's total)."""
    n = len(QUICK_DRIVES if quick else DRIVES)
    runs = {"speed": 8, "real": 8, "validation": 1, "tracking": 1, "robustness": 2, "attitude": 3 * n}
    return sum(runs.get(t, 0) for t in topics) + (2 * n if any(t in DRIVE_TOPICS for t in topics) else 0)


def machine() -> str:
    """CPU model, the vector flags of :data:`CPU_FLAGS` it has, and its cores (from /proc/cpuinfo where there is one)."""
    model, flags = platform.processor() or platform.machine(), set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, val = line.partition(":")
            if key.strip() == "model name":
                model = val.strip()
            elif key.strip() == "flags":
                flags = set(val.split())
    except OSError:
        pass
    have = [f for f in CPU_FLAGS if f in flags]
    return f"{model}, {os.cpu_count()} cores" + (f", {' '.join(have)}" if have else "")


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def commit() -> str:
    """The commit measured, ``+ local changes`` where the code, models or calibrations differ from it."""
    head = _git("rev-parse", "--short", "HEAD") or "unknown"
    return head + (" + local changes" if _git("status", "--porcelain", "--", "cone_perception", "models", "calib") else "")


def load() -> float | None:
    """The 1-minute load average (None where the system has none)."""
    try:
        return os.getloadavg()[0]
    except OSError:
        return None


def stamp(started: float, load_before: float | None, quick: bool) -> str:
    """The line over each table: when, at which commit, on what, how loaded (loaded: a 1-minute load average of at
    least half the cores before or after), how long it took."""
    when = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    loads = [x for x in (load_before, load()) if x is not None]
    busy = ("" if not loads else "loaded" if max(loads) >= 0.5 * (os.cpu_count() or 1) else "quiet")
    how = f"{busy}: load average {' -> '.join(f'{x:.1f}' for x in loads)}" if loads else "load not known"
    return (f"*{when}, commit {commit()}; {machine()}; {how}; {'quick mode, ' if quick else ''}"
            f"{time.perf_counter() - started:.0f} s.*")


def write_section(doc: Path, topic: str, body: list[str]) -> None:
    """Replace what stands between ``topic``'s markers in ``doc`` by ``body``."""
    begin, end = f"<!-- bench report {topic} -->", f"<!-- /bench report {topic} -->"
    text = doc.read_text()
    i, j = text.find(begin), text.find(end)
    if i < 0 or j < i:
        raise ConfigError(str(doc), topic, f"no markers {begin} ... {end} in the document")
    doc.write_text(text[:i + len(begin)] + "\n" + "\n".join(body) + "\n" + text[j:])


def run_report(doc: Path, topics: list[str], quick: bool, work: Path, val: Path, progress: bool = True) -> dict:
    """Measure ``topics`` and write each table into ``doc``; per topic, the seconds it took."""
    bad = [t for t in topics if t not in TOPICS]
    if bad or not topics:
        raise ConfigError(SRC, "--topics", f"unknown topic(s) {', '.join(bad) or '(none)'}; choose from {', '.join(TOPICS)}")
    if not doc.is_file():
        raise ConfigError(str(doc), None, "document not found (run from the repository root, or pass --doc)")
    work.mkdir(parents=True, exist_ok=True)
    took = {}
    with tqdm(total=planned_runs(topics, quick), unit="run", desc=SRC, file=sys.stderr, disable=not progress) as bar:
        runner = Runner(work, quick, val, bar)
        for topic in topics:
            started, load_before = time.perf_counter(), load()
            sec = TOPICS[topic](runner)
            body = [stamp(started, load_before, quick), "", *sec.lines, "", *sec.notes, "", "```bash", *sec.commands, "```"]
            write_section(doc, topic, body)
            took[topic] = time.perf_counter() - started
    return took
