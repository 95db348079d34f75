"""Timing of per-frame stages, shared by ``cone-perception bench`` and the replay tools.

:class:`StageTimer` collects wall-clock durations per stage name;
:func:`summarize` turns them into median / p90 / p99 / min / max in ms.
"""

from __future__ import annotations

import resource
import sys
import time
from collections import defaultdict
from contextlib import contextmanager
from typing import Iterator

import numpy as np


class StageTimer:
    """Collects durations (seconds) per stage; ``with timer("forward"): ...``."""

    def __init__(self) -> None:
        self.samples: dict[str, list[float]] = defaultdict(list)

    @contextmanager
    def __call__(self, stage: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.samples[stage].append(time.perf_counter() - t0)

    def add(self, stage: str, seconds: float) -> None:
        self.samples[stage].append(seconds)

    def clear(self) -> None:
        self.samples.clear()

    def summary(self) -> dict[str, dict[str, float]]:
        return {k: summarize(v) for k, v in self.samples.items()}


def summarize(seconds: list[float] | np.ndarray) -> dict[str, float]:
    """Durations in s -> ``{n, median_ms, p90_ms, p99_ms, min_ms, max_ms, mean_ms}``."""
    a = np.asarray(seconds, dtype=np.float64) * 1e3
    if a.size == 0:
        return {"n": 0}
    return {
        "n": int(a.size),
        "median_ms": float(np.median(a)),
        "p90_ms": float(np.percentile(a, 90)),
        "p99_ms": float(np.percentile(a, 99)),
        "min_ms": float(a.min()),
        "max_ms": float(a.max()),
        "mean_ms": float(a.mean()),
    }


def peak_rss_mb() -> float:
    """Peak resident set size of this process in MiB."""
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb / 1024.0 if sys.platform != "darwin" else kb / 2**20


def rss_mb(pid: int | str = "self") -> float:
    """Resident set size of process ``pid`` (default this one) now, in MiB (Linux /proc; NaN where unreadable)."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


def format_table(summary: dict[str, dict[str, float]]) -> str:
    """Plain-text table of a :meth:`StageTimer.summary`."""
    head = f"{'stage':<16}{'n':>6}{'median':>10}{'p90':>10}{'p99':>10}{'min':>10}{'max':>10}  (ms)"
    rows = [head]
    for name, s in summary.items():
        if not s.get("n"):
            continue
        rows.append(
            f"{name:<16}{s['n']:>6}{s['median_ms']:>10.3f}{s['p90_ms']:>10.3f}{s['p99_ms']:>10.3f}"
            f"{s['min_ms']:>10.3f}{s['max_ms']:>10.3f}"
        )
    return "\n".join(rows)


#: The tail the real-time target allows: end-to-end p99 at most this many times the median.
TAIL_LIMIT = 1.5


def summarize_runs(runs: list[dict], tail_limit: float = TAIL_LIMIT) -> dict:
    """Repeated ``bench pipeline`` results (each with ``stages.end_to_end``, ``fps``,
    ``peak_rss_mb``) -> the spread across runs: median end to end and frames/s min-max, each run's
    p99 / median, and how many runs kept p99 within ``tail_limit`` x the median."""
    if not runs:
        raise ValueError("summarize_runs needs at least one run")
    med = np.array([r["stages"]["end_to_end"]["median_ms"] for r in runs])
    ratio = np.array([r["stages"]["end_to_end"]["p99_ms"] for r in runs]) / med
    fwd = np.array([r["stages"]["forward"]["median_ms"] for r in runs if "forward" in r["stages"]])
    return {
        "runs": len(runs),
        "median_ms": {"min": float(med.min()), "median": float(np.median(med)), "max": float(med.max())},
        "fps": {"min": float(1e3 / med.max()), "max": float(1e3 / med.min())},
        "forward_median_ms": {"min": float(fwd.min()), "max": float(fwd.max())} if fwd.size else None,
        "p99_over_median": [round(float(x), 3) for x in ratio],
        "p99_over_median_median": float(np.median(ratio)),
        "tail_limit": tail_limit,
        "runs_within_tail_limit": int((ratio <= tail_limit).sum()),
        "peak_rss_mb_max": float(max(r["peak_rss_mb"] for r in runs)),
    }


def format_runs(s: dict) -> str:
    """One paragraph of a :func:`summarize_runs` result."""
    m, f = s["median_ms"], s["fps"]
    lines = [
        f"{s['runs']} runs: end to end median {m['min']:.2f}-{m['max']:.2f} ms (median run {m['median']:.2f}), "
        f"{f['min']:.0f}-{f['max']:.0f} frames/s",
        f"p99 / median per run: {', '.join(f'{x:.2f}' for x in sorted(s['p99_over_median']))}",
        f"runs with p99 <= {s['tail_limit']:g}x median: {s['runs_within_tail_limit']} of {s['runs']} "
        f"(median run {s['p99_over_median_median']:.2f}x); peak RSS up to {s['peak_rss_mb_max']:.0f} MiB",
    ]
    if s["forward_median_ms"]:
        lines.insert(1, f"forward median {s['forward_median_ms']['min']:.2f}-{s['forward_median_ms']['max']:.2f} ms")
    return "\n".join(lines)
