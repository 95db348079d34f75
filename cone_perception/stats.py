"""Counting every input and every loss, and the node health that ``/diagnostics`` reports (ROS-free).

* :class:`FrameStats`: frames processed (``ok``) and dropped, by cause. Every message a frame
  callback receives is counted exactly once, as ok or dropped (``exception_<Type>`` for an
  unexpected exception).
* :class:`StreamMonitor`: what the header stamps and arrival times of one input topic tell about
  frames the node never saw or should not trust: frames **skipped** before the callback (replaced
  in a depth-1 queue while the node was busy, or lost upstream: estimated from gaps in the
  publisher's stamps against the stream's own period), stamps going **backwards** or **repeated**,
  **stale** frames (stamp older than ``max_age_s`` on arrival), **silence** (no message for
  ``timeout_s``), and frames the middleware reports **lost** (DDS sample lost, where supported).
* :class:`NodeHealth`: both, and :meth:`NodeHealth.assess`: OK / WARN / ERROR with the cause, as
  the nodes publish it on ``/diagnostics`` once a second: ERROR for silence or a topic without a
  publisher (a missing or dead upstream node), WARN for drops, skips, stamp faults or stale frames
  since the previous report, OK otherwise. The counts are cumulative; the level is of the period.
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from statistics import median

OK, WARN, ERROR = 0, 1, 2  # the levels of diagnostic_msgs/DiagnosticStatus
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR"}


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

    @property
    def received(self) -> int:
        """Messages counted: ``ok + dropped_total``."""
        return self.ok + self.dropped_total

    def summary(self) -> str:
        if not self.dropped:
            return f"{self.ok} frames ok, none dropped"
        causes = ", ".join(f"{k}={v}" for k, v in sorted(self.dropped.items()))
        return f"{self.ok} frames ok, {self.dropped_total} dropped ({causes})"


#: Stamp deltas the stream's period is the median of; gaps are counted once this many are seen.
PERIOD_WINDOW = 16
MIN_PERIOD_SAMPLES = 4
#: A stamp delta of more than this many periods counts ``round(delta / period) - 1`` skipped frames.
GAP_FACTOR = 1.5


@dataclass
class StreamMonitor:
    """Stamp and arrival bookkeeping of one input topic (stamps and times in ns).

    ``timeout_s``: silence longer than this is an ERROR (0 = never). ``max_age_s``: a frame whose
    stamp is older than this on arrival is stale (0 = not checked; e.g. a bag played with its
    original stamps). ``period_s``: the publisher's nominal period (0 = learnt: the median of the
    last stamp deltas, which misses skips of a consumer that never sees two frames in a row).
    """

    topic: str
    timeout_s: float = 1.0
    max_age_s: float = 0.0
    period_s: float = 0.0
    received: int = 0
    ok: int = 0  # of ``received``: processed (counted by the node's guard)
    dropped: int = 0  # of ``received``: dropped with a cause (in :class:`FrameStats`)
    skipped: int = 0
    lost: int = 0  # reported lost by the middleware (DDS sample lost), where it reports it
    backwards: int = 0
    repeated: int = 0
    stale: int = 0
    silences: int = 0
    optional: bool = False  # an input the node works without: silence and no publisher are no error
    last_stamp_ns: int | None = None
    last_arrival_ns: int | None = None
    started_ns: int | None = None
    _deltas: deque = field(default_factory=lambda: deque(maxlen=PERIOD_WINDOW))
    _silent: bool = False

    def start(self, now_ns: int) -> None:
        """The time from which silence is measured before the first message."""
        if self.started_ns is None:
            self.started_ns = now_ns

    @property
    def period_ns(self) -> float | None:
        """The stream's period: ``period_s``, or the median of the last stamp deltas once enough are seen."""
        if self.period_s > 0:
            return self.period_s * 1e9
        return median(self._deltas) if len(self._deltas) >= MIN_PERIOD_SAMPLES else None

    def observe(self, stamp_ns: int | None, now_ns: int) -> list[str]:
        """One message arrived (``stamp_ns`` its header stamp, ``None`` if it has none); returns the
        faults it shows (``skipped``, ``backwards``, ``repeated``, ``stale``), each counted."""
        self.start(now_ns)
        self.received += 1
        self.last_arrival_ns = now_ns
        self._silent = False
        faults = []
        if stamp_ns is None:
            return faults
        if self.max_age_s > 0 and now_ns - stamp_ns > self.max_age_s * 1e9:
            self.stale += 1
            faults.append("stale")
        last, self.last_stamp_ns = self.last_stamp_ns, stamp_ns
        if last is None:
            return faults
        delta = stamp_ns - last
        if delta == 0:
            self.repeated += 1
            faults.append("repeated")
        elif delta < 0:
            self.backwards += 1
            self._deltas.clear()  # a clock jump: learn the period anew
            faults.append("backwards")
        else:
            period = self.period_ns
            if period and delta > GAP_FACTOR * period:
                self.skipped += max(0, round(delta / period) - 1)
                faults.append("skipped")
            self._deltas.append(delta)
        return faults

    def silent_for_s(self, now_ns: int) -> float:
        """Seconds since the last message (or since :meth:`start` before the first)."""
        ref = self.last_arrival_ns if self.last_arrival_ns is not None else self.started_ns
        return 0.0 if ref is None else max(0.0, (now_ns - ref) / 1e9)

    def is_silent(self, now_ns: int) -> bool:
        """True while silent for more than ``timeout_s``; each silence is counted once."""
        silent = self.timeout_s > 0 and self.silent_for_s(now_ns) > self.timeout_s
        if silent and not self._silent:
            self.silences += 1
        self._silent = silent
        return silent

    def counts(self) -> dict[str, int]:
        return {"received": self.received, "ok": self.ok, "dropped": self.dropped, "skipped": self.skipped,
                "lost": self.lost, "backwards": self.backwards,
                "repeated": self.repeated, "stale": self.stale, "silences": self.silences}


@dataclass
class HealthReport:
    level: int
    message: str
    values: list[tuple[str, str]]

    @property
    def level_name(self) -> str:
        return LEVEL_NAMES[self.level]


class NodeHealth:
    """A node's :class:`FrameStats` and one :class:`StreamMonitor` per input topic."""

    def __init__(self, timeout_s: float = 1.0, max_age_s: float = 0.0, period_s: float = 0.0) -> None:
        self.stats = FrameStats()
        self.streams: dict[str, StreamMonitor] = {}
        self.timeout_s, self.max_age_s, self.period_s = timeout_s, max_age_s, period_s
        self._last: dict[str, int] = {}
        self.watched: dict[str, tuple[Mapping[str, int], frozenset[str]]] = {}

    def watch(self, name: str, counts: Mapping[str, int], warn: Iterable[str] = ()) -> None:
        """Report a stage's own event counts (e.g. the tracker's ``events``, read at each
        :meth:`assess`) with the node's: each as the value ``name:event``; an event in ``warn`` that grew
        in the period makes it WARN (``"N name event"`` in the message)."""
        self.watched[name] = (counts, frozenset(warn))

    def stream(self, topic: str, now_ns: int | None = None) -> StreamMonitor:
        if topic not in self.streams:
            self.streams[topic] = StreamMonitor(topic, self.timeout_s, self.max_age_s, self.period_s)
        if now_ns is not None:
            self.streams[topic].start(now_ns)
        return self.streams[topic]

    def _totals(self) -> dict[str, int]:
        t = Counter({f"dropped_{k}": v for k, v in self.stats.dropped.items()})
        for s in self.streams.values():
            for k in ("skipped", "lost", "backwards", "repeated", "stale"):
                t[f"{k}"] += getattr(s, k)
        for name, (counts, warn) in self.watched.items():
            for k in warn:
                if counts.get(k, 0):
                    t[f"{name}:{k}"] = int(counts[k])
        return dict(t)

    def assess(self, now_ns: int, publishers: dict[str, int] | None = None) -> HealthReport:
        """The level and cause for this period (since the previous call) and the cumulative counts.

        ``publishers``: topic -> number of publishers now (0: a missing or dead upstream)."""
        errors, warns = [], []
        for topic, n in sorted((publishers or {}).items()):
            if n == 0:
                errors.append(f"no publisher on {topic}")
        for s in self.streams.values():
            if s.is_silent(now_ns):
                what = "since start" if s.last_arrival_ns is None else "for"
                errors.append(f"no message on {s.topic} {what} {s.silent_for_s(now_ns):.1f} s "
                              f"(timeout {s.timeout_s:g} s)")
        totals = self._totals()
        new = {k: v - self._last.get(k, 0) for k, v in totals.items() if v > self._last.get(k, 0)}
        self._last = totals
        labels = {"skipped": "skipped before processing (stamp gaps)", "lost": "lost in transport (middleware)", "backwards": "stamps going backwards",
                  "repeated": "stamps repeated", "stale": "stale frames"}
        for k, v in sorted(new.items()):
            if k.startswith("dropped_"):
                warns.append(f"{v} dropped ({k[len('dropped_'):]})")
            elif ":" in k:
                warns.append(f"{v} {k.replace(':', ' ')}")
            else:
                warns.append(f"{v} {labels[k]}")
        level = ERROR if errors else WARN if warns else OK
        message = "; ".join(errors + warns) if errors or warns else self.stats.summary()
        values = [("frames_ok", str(self.stats.ok))]
        values += [(f"dropped_{k}", str(v)) for k, v in sorted(self.stats.dropped.items())]
        for s in self.streams.values():
            values += [(f"{s.topic}:{k}", str(v)) for k, v in s.counts().items()]
        for name, (counts, _) in self.watched.items():
            values += [(f"{name}:{k}", str(v)) for k, v in sorted(counts.items())]
        return HealthReport(level, message, values)

    def summary(self) -> str:
        """One line for the log: the frame counts and each stream's faults."""
        parts = [self.stats.summary()]
        for s in self.streams.values():
            faults = {k: v for k, v in s.counts().items() if k not in ("received", "ok", "dropped") and v}
            if faults:
                parts.append(f"{s.topic}: " + ", ".join(f"{k}={v}" for k, v in faults.items()))
        for name, (counts, _) in self.watched.items():
            if any(counts.values()):
                parts.append(f"{name}: " + ", ".join(f"{k}={v}" for k, v in sorted(counts.items()) if v))
        return "; ".join(parts)
