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
