"""The spread of the figures over drives (``cone-perception validate``, issue 41): one row per drive, and per figure
its median, its worst tenth and its worst drive; the printed tables, the CSV / JSON files and the picture. ROS-free.

A drive's row (:func:`drive_row`) is read from what the offline replay already computes: the ``/cones``
:class:`~cone_perception.evaluation.LocalisationReport` summary (recall by range band to 40 m of the true cones at
least half visible, false cones per frame within 40 m, the median position error by band with the attitude the
pipeline used), the same report of the same boxes mapped through the fixed H, and the tracker's scoring
(:class:`~cone_perception.evaluation.tracking.DriveEvaluation`, ``/cones/tracked`` by band).

The targets (:data:`TARGETS`, issue 41's for the rendered drives, :func:`check_targets`) are read off the
distribution: met or missed, with the drive that decides it.

The distribution (:func:`distribution`) of each figure over the drives that ran (failed rows left out, a drive
where a band holds no true cone left out of that figure): the median; the *worst tenth*, the 10th percentile of a
figure where higher is better (recall) and the 90th where lower is better (false cones, errors), linearly
interpolated between drives (numpy's default); the worst value and its drive.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data.outfiles import json_safe
from ..vis import pyplot
from .localisation import EXTRA_GROUPS

#: The range bands of every figure (m): :data:`~cone_perception.evaluation.EXTRA_GROUPS`, 0-7, 7-15, 15-25, 25-40.
BANDS: tuple[tuple[str, str], ...] = tuple((name, name.removesuffix(" m").replace("-", "_")) for name, _, _ in EXTRA_GROUPS)


@dataclass(frozen=True)
class Figure:
    """One column of the suite: ``key`` in a row, ``label`` in the tables, ``higher_better`` (recall) or not (false
    cones, errors), ``table``: which printed table it belongs to, ``panel``: which panel of the picture (its table's
    where empty)."""

    key: str
    label: str
    higher_better: bool
    table: str
    panel: str = ""

    @property
    def where(self) -> str:
        """The picture's panel."""
        return self.panel or self.table


#: The suite's figures per drive, in the order of its tables.
FIGURES: tuple[Figure, ...] = (
    *(Figure(f"recall_{k}", f"{n}", True, "/cones recall") for n, k in BANDS),
    Figure("false_per_frame", "false/frame", False, "/cones recall", "false cones per frame within 40 m"),
    *(Figure(f"tracked_recall_{k}", f"{n}", True, "/cones/tracked recall") for n, k in BANDS),
    Figure("tracked_false_per_frame", "false/frame", False, "/cones/tracked recall", "false cones per frame within 40 m"),
    *(Figure(f"err_att_{k}", f"att {n}", False, "median position error (m)") for n, k in BANDS),
    *(Figure(f"err_fixed_{k}", f"fixed {n}", False, "median position error (m)") for n, k in BANDS),
)
TABLES: tuple[str, ...] = tuple(dict.fromkeys(f.table for f in FIGURES))
#: What the tables' columns mean, printed under them.
TABLE_NOTES: dict[str, str] = {
    "/cones recall": "recall of the true cones >= 0.5 visible by range band; false/frame: /cones on no true cone within 40 m",
    "/cones/tracked recall": "the tracker's output, scored as /cones (the bag's odometry in)",
    "median position error (m)": "att: the attitude the pipeline used (image at the defaults); fixed: the same boxes "
                                 "mapped through the calibration's fixed H",
}

OK, FAILED, MISSING = "ok", "failed", "missing"


def drive_row(localisation: dict, fixed_localisation: dict, tracking: dict | None) -> dict[str, float]:
    """A drive's figures (:data:`FIGURES`) from the replay's ``/cones`` localisation summary
    (:meth:`~cone_perception.evaluation.LocalisationReport.summary`), the same of the boxes through the fixed H,
    and the tracker's summary (:meth:`~cone_perception.replay.ReplayTracking.summary`; None: no tracked figures)."""
    row: dict[str, float] = {}
    for name, k in BANDS:
        row[f"recall_{k}"] = localisation["extra_groups"][name]["recall"]
        row[f"err_att_{k}"] = localisation["extra_groups"][name]["median_err_m"]
        row[f"err_fixed_{k}"] = fixed_localisation["extra_groups"][name]["median_err_m"]
    row["false_per_frame"] = localisation["bands"]["false_per_frame"]
    bands = (tracking or {}).get("tracked", {}).get("bands", {})
    for name, k in BANDS:
        row[f"tracked_recall_{k}"] = bands[name]["recall"] if name in bands else float("nan")
    # the bands are contiguous from 0 to 40 m: their false cones per frame add up to those within 40 m
    row["tracked_false_per_frame"] = (sum(bands[n]["false_per_frame"] for n, _ in BANDS) if bands else float("nan"))
    return {k: float(v) for k, v in row.items()}


def spread(values: list[float], higher_better: bool) -> dict:
    """``{n, median, worst_tenth, worst, worst_index}`` of ``values`` (NaN left out; ``worst_index`` into
    ``values``); all NaN and -1 where no value is finite."""
    v = np.asarray(values, np.float64)
    ok = np.flatnonzero(np.isfinite(v))
    if ok.size == 0:
        return {"n": 0, "median": math.nan, "worst_tenth": math.nan, "worst": math.nan, "worst_index": -1}
    w = v[ok]
    i = ok[int(np.argmin(w) if higher_better else np.argmax(w))]
    return {"n": int(ok.size), "median": float(np.median(w)),
            "worst_tenth": float(np.quantile(w, 0.1 if higher_better else 0.9)), "worst": float(v[i]), "worst_index": int(i)}


def distribution(rows: list[dict], figures: tuple[Figure, ...] = FIGURES) -> dict[str, dict]:
    """Per figure key, :func:`spread` over the rows whose ``status`` is ok, the worst one named (``worst_drive``)."""
    good = [r for r in rows if r.get("status") == OK]
    out = {}
    for f in figures:
        s = spread([r.get(f.key, math.nan) for r in good], f.higher_better)
        s["worst_drive"] = good[s.pop("worst_index")]["drive"] if s["n"] else None
        out[f.key] = s
    return out


@dataclass(frozen=True)
class Target:
    """A target on the rendered drives: the ``stat`` (``worst``: every drive; ``median``: the middle one) of figure
    ``key`` at least ``bound`` where the figure is higher-better (recall), at most ``bound`` where not."""

    key: str
    stat: str
    bound: float
    label: str


#: Issue 41's targets for the rendered drives at the defaults.
TARGETS: tuple[Target, ...] = (
    Target("recall_15_25", "worst", 0.98, "/cones recall 15-25 m, every drive"),
    Target("recall_25_40", "worst", 0.80, "/cones recall 25-40 m, every drive"),
    Target("false_per_frame", "worst", 0.3, "false cones per frame within 40 m, every drive"),
    Target("false_per_frame", "median", 0.2, "false cones per frame within 40 m, median of the drives"),
    Target("err_att_7_15", "median", 0.10, "the attitude's median position error 7-15 m (m), median of the drives"),
)


def check_targets(dist: dict[str, dict], targets: tuple[Target, ...] = TARGETS,
                  figures: tuple[Figure, ...] = FIGURES) -> list[dict]:
    """Per target ``{label, key, stat, bound, at_least, value, met, drive}`` from :func:`distribution`'s ``dist`` (``drive``: the
    worst drive for a ``worst`` target, else None; ``met`` False where no drive had the figure)."""
    higher = {f.key: f.higher_better for f in figures}
    out = []
    for t in targets:
        d = dist.get(t.key, {})
        v = float(d.get(t.stat, math.nan))
        met = bool(math.isfinite(v) and (v >= t.bound if higher[t.key] else v <= t.bound))
        out.append({"label": t.label, "key": t.key, "stat": t.stat, "bound": t.bound, "at_least": higher[t.key],
                    "value": v, "met": met,
                    "drive": d.get("worst_drive") if t.stat == "worst" else None})
    return out


def format_targets(checks: list[dict]) -> str:
    """One line per target: its value against its bound, met or MISSED, and the deciding drive."""
    lines = ["targets (issue 41, rendered drives):"]
    for c in checks:
        op = ">=" if c["at_least"] else "<="
        where = f" ({c['drive']})" if c["drive"] else ""
        lines.append(f"  {c['label']}: {c['value']:.3f}{where} {op} {c['bound']:g} {'met' if c['met'] else 'MISSED'}")
    return "\n".join(lines)


def _cell(v, width: int = 8, nd: int = 3) -> str:
    return f"{'-':>{width}}" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:>{width}.{nd}f}"


def format_tables(rows: list[dict], dist: dict[str, dict], figures: tuple[Figure, ...] = FIGURES) -> str:
    """The printed report: per table of :data:`TABLES`, one line per drive (a failed one with its error), then the
    median, worst tenth and worst over the drives that ran."""
    name_w = max([len(r["drive"]) for r in rows] + [12]) + 1
    out = []
    for table in dict.fromkeys(f.table for f in figures):
        cols = [f for f in figures if f.table == table]
        w = max(8, *(len(f.label) + 1 for f in cols))
        out.append(f"{table}: {TABLE_NOTES.get(table, '')}")
        out.append(f"{'drive':<{name_w}}" + "".join(f"{f.label:>{w}}" for f in cols))
        for r in rows:
            if r["status"] != OK:
                out.append(f"{r['drive']:<{name_w}}  {r['status'].upper()}: {r.get('error', '')}")
                continue
            out.append(f"{r['drive']:<{name_w}}" + "".join(_cell(r.get(f.key), w) for f in cols))
        for stat, title in (("median", "median"), ("worst_tenth", "worst tenth"), ("worst", "worst")):
            out.append(f"{title:<{name_w}}" + "".join(_cell(dist[f.key][stat], w) for f in cols))
        out.append(f"{'worst drive':<{name_w}}" + "".join(f"{(dist[f.key]['worst_drive'] or '-')[:w - 1]:>{w}}" for f in cols))
        out.append("")
    return "\n".join(out).rstrip()


def write_csv(path: Path, rows: list[dict], keys: list[str]) -> Path:
    """``rows`` as CSV with the columns ``keys`` (a missing value or NaN: empty)."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for r in rows:
            vals = json_safe([r.get(k) for k in keys])
            w.writerow(["" if v is None else v for v in vals])
    return path


def write_json(path: Path, report: dict) -> Path:
    path.write_text(json.dumps(json_safe(report), indent=1, allow_nan=False), encoding="utf-8")
    return path


def spread_plot(path: Path, rows: list[dict], dist: dict[str, dict], title: str = "",
                figures: tuple[Figure, ...] = FIGURES) -> Path:
    """PNG: one panel per :attr:`Figure.where`, per figure a box over the drives with each drive a dot (the worst
    named)."""
    plt = pyplot()
    good = [r for r in rows if r.get("status") == OK]
    panels = list(dict.fromkeys(f.where for f in figures))
    fig, axes = plt.subplots(len(panels), 1, figsize=(12, 3.3 * len(panels)), squeeze=False)
    rng = np.random.default_rng(0)  # the dots' sideways jitter only
    for ax, panel in zip(axes[:, 0], panels):
        cols = [f for f in figures if f.where == panel]
        data = [np.array([r.get(f.key, math.nan) for r in good], np.float64) for f in cols]
        finite = [d[np.isfinite(d)] for d in data]
        ax.boxplot([d if d.size else [math.nan] for d in finite], positions=range(len(cols)), widths=0.5,
                   showfliers=False, medianprops={"color": "tab:red"})
        for k, (f, d) in enumerate(zip(cols, data)):
            ok = np.isfinite(d)
            ax.plot(k + rng.uniform(-0.15, 0.15, int(ok.sum())), d[ok], "o", ms=3, color="tab:blue", alpha=0.7)
            wd = dist[f.key]["worst_drive"]
            if wd is not None:
                ax.annotate(wd, (k, dist[f.key]["worst"]), fontsize=6, xytext=(4, 0), textcoords="offset points")
        ax.set_xticks(range(len(cols)))
        # a panel of its own gathers one figure of several tables: named by its table (/cones, /cones/tracked)
        ax.set_xticklabels([f.table.split()[0] if f.panel else f.label for f in cols], fontsize=8)
        ax.set_title(f"{panel} over {len(good)} drives", fontsize=10)
        ax.grid(alpha=0.3, axis="y")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


#: A real set's figures (``eval`` in the car's band): (key, label). Its own table, no distribution (one row per set).
REAL_FIGURES: tuple[tuple[str, str], ...] = (
    ("map50", "mAP@0.5"), ("map50_95", "mAP@.5:.95"), ("precision", "precision"), ("recall", "recall"),
    ("recall_0_8px", "rec <8px"), ("recall_8_12px", "rec 8-12px"), ("recall_ge_12px", "rec >=12px"),
    ("map50_ge_12px", "mAP >=12px"),
)


def real_row(metrics: dict, metrics_ge_12px: dict) -> dict[str, float]:
    """A real set's figures (:data:`REAL_FIGURES`) from ``eval``'s ``metrics.json`` in the band, and from the same
    with ``--min-height 12`` (cones under 12 px at the model input set aside, as the real clips' "no loss at >= 12 px"
    is measured). Box heights at the model input."""
    d = metrics["detection"]
    a = d["operating_point"]["per_class"]["all"]
    bins = metrics["by_box_height"]["bins"]
    return {"map50": d["map50"], "map50_95": d["map50_95"], "precision": a["precision"], "recall": a["recall"],
            "recall_0_8px": bins["0-8 px"]["recall"], "recall_8_12px": bins["8-12 px"]["recall"],
            "recall_ge_12px": metrics["by_box_height"]["at_least_min_height"]["recall"],
            "map50_ge_12px": metrics_ge_12px["detection"]["map50"]}


def format_real(rows: list[dict]) -> str:
    """The real sets' table: one line per set (a missing or failed one with why)."""
    name_w = max([len(r["drive"]) for r in rows] + [12]) + 1
    out = [f"real sets (eval in the car's band; box heights at the model input): ",
           f"{'set':<{name_w}}" + "".join(f"{label:>11}" for _, label in REAL_FIGURES)]
    for r in rows:
        if r["status"] != OK:
            out.append(f"{r['drive']:<{name_w}}  {r['status'].upper()}: {r.get('error', '')}")
        else:
            out.append(f"{r['drive']:<{name_w}}" + "".join(_cell(r.get(k), 11) for k, _ in REAL_FIGURES))
    return "\n".join(out)
