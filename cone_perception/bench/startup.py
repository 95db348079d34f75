"""The figures of ``cone-perception bench startup`` (ROS-free): how soon a node started as ``ros2 run`` starts it
is ready and publishes its first ``/cones`` under a 30 Hz camera, cold (no ONNX cache) and warm, and after a
``kill -9``; the node's peak RSS; and the targets of issue 43 they are held to. The starts themselves are driven by
:mod:`cone_perception.rostools.startup` (rclpy).

Per start: ``ready_s``, seconds from the exec of the node's console script to its ``/cones`` publisher in the ROS
graph; ``first_cones_s``, from the exec to the first ``/cones`` it publishes; ``peak_rss_mb``, the process's peak
resident set (``VmHWM``) after a second of frames.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

#: The camera's rate while the node starts (frames published from before the exec).
CAMERA_HZ = 30.0
#: Targets: a warm start (the ONNX cache present), median exec -> first /cones, and the same after ``kill -9``.
FIRST_CONES_TARGET_S = 2.0
#: Target: peak RSS of the pipeline node on ONNX Runtime (its warm starts: a cold start imports torch to export).
PEAK_RSS_TARGET_MB = 400.0
#: The phases of the benchmark: no ONNX cache before each start; the cache warm, the previous node stopped
#: (SIGINT) and gone; the cache warm, the previous node killed with SIGKILL under the camera just before.
PHASES = ("cold", "warm", "kill")


@dataclass
class Start:
    """One start of the node: ``phase`` (:data:`PHASES`), seconds from exec to ready and to the first /cones (NaN:
    never, within the timeout), its peak RSS in MiB, and what became of it (``ok`` or why not)."""

    phase: str
    ready_s: float = math.nan
    first_cones_s: float = math.nan
    peak_rss_mb: float = math.nan
    outcome: str = "ok"


def spread(values: list[float]) -> dict:
    """``n``, ``median``, ``min``, ``max`` of the finite ``values`` (NaN where none), and how many were not."""
    a = np.asarray([v for v in values if v == v], dtype=float)
    if a.size == 0:
        return {"n": 0, "median": math.nan, "min": math.nan, "max": math.nan, "missing": len(values)}
    return {"n": int(a.size), "median": float(np.median(a)), "min": float(a.min()), "max": float(a.max()),
            "missing": len(values) - int(a.size)}


def summarize(starts: list[Start]) -> dict:
    """Per phase: the spread of ``ready_s`` and ``first_cones_s``, the highest peak RSS, the starts that failed;
    ``targets``: each target's figure and whether it is met; ``starts``: every start."""
    out: dict = {"phases": {}, "starts": [asdict(s) for s in starts]}
    for phase in PHASES:
        mine = [s for s in starts if s.phase == phase]
        if not mine:
            continue
        rss = [s.peak_rss_mb for s in mine if s.peak_rss_mb == s.peak_rss_mb]
        out["phases"][phase] = {"ready_s": spread([s.ready_s for s in mine]),
                                "first_cones_s": spread([s.first_cones_s for s in mine]),
                                "peak_rss_mb": max(rss) if rss else math.nan,
                                "failed": [f"{i}: {s.outcome}" for i, s in enumerate(mine) if s.outcome != "ok"]}
    targets = {}
    for phase in ("warm", "kill"):
        if phase in out["phases"]:
            m = out["phases"][phase]["first_cones_s"]
            ok = m["missing"] == 0 and m["median"] <= FIRST_CONES_TARGET_S
            targets[f"{phase} exec->first /cones median <= {FIRST_CONES_TARGET_S:g} s"] = (m["median"], bool(ok))
    rss = [p["peak_rss_mb"] for k, p in out["phases"].items() if k != "cold" and p["peak_rss_mb"] == p["peak_rss_mb"]]
    if rss:
        targets[f"peak RSS (warm, kill) <= {PEAK_RSS_TARGET_MB:g} MiB"] = (max(rss), max(rss) <= PEAK_RSS_TARGET_MB)
    out["targets"] = targets
    return out


def _fmt(s: dict) -> str:
    if s["n"] == 0:
        return f"none of {s['missing']}"
    miss = f" ({s['missing']} never)" if s["missing"] else ""
    return f"{s['median']:.2f} ({s['min']:.2f}-{s['max']:.2f}){miss}"


def format_summary(summary: dict) -> str:
    """A table: per phase the starts, exec -> ready and exec -> first /cones (median (min-max) s), peak RSS; then
    the targets, each met or MISSED."""
    rows = [f"{'phase':<6} {'starts':>6}  {'exec->ready s':<20} {'exec->first /cones s':<22} {'peak RSS MiB':>12}"]
    for phase, p in summary["phases"].items():
        n = p["ready_s"]["n"] + p["ready_s"]["missing"]
        rows.append(f"{phase:<6} {n:>6}  {_fmt(p['ready_s']):<20} {_fmt(p['first_cones_s']):<22} "
                    f"{p['peak_rss_mb']:>12.0f}")
        rows += [f"       failed start {f}" for f in p["failed"]]
    for name, (value, ok) in summary["targets"].items():
        rows.append(f"target {name}: {value:.2f} {'met' if ok else 'MISSED'}")
    return "\n".join(rows)
