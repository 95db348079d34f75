"""Per-cause counters of processed and dropped frames (ROS-free).

Nodes and offline tools count every dropped input here so nothing is lost
silently: the counts go to the log, ``/diagnostics`` and summaries.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field


@dataclass
class FrameStats:
    """Counts of frames ``ok`` and ``dropped`` by reason."""

    ok: int = 0
    dropped: Counter = field(default_factory=Counter)

    def count_ok(self) -> None:
        self.ok += 1

    def count_drop(self, reason: str) -> int:
        """Count one dropped frame; returns the count for that reason."""
        self.dropped[reason] += 1
        return self.dropped[reason]

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())

    def summary(self) -> str:
        if not self.dropped:
            return f"{self.ok} frames ok, none dropped"
        causes = ", ".join(f"{k}={v}" for k, v in sorted(self.dropped.items()))
        return f"{self.ok} frames ok, {self.dropped_total} dropped ({causes})"
