"""Counting every input and every loss, and the node health that ``/diagnostics`` reports (ROS-free).

* :class:`FrameStats`: frames processed (``ok``) and dropped, by cause. Every message a frame callback receives
  is counted exactly once, as ok or dropped (``exception_<Type>`` for an unexpected exception).
* :class:`StampGaps`: what one stream's header stamps tell: frames **missing** (a gap of k periods counts k-1),
  stamps going **backwards** or **repeated**, and a **silence** (a gap longer than the threshold), not missing frames.
* :class:`StreamMonitor`: per input topic, what reached the processing callback and what did not. An image input
  is best effort with a queue of one (newest frame only): the frames replaced in the queue never reach the
  callback. Where the middleware gives the publisher's **sequence number** of each message (rclpy >= Iron, Fast
  DDS), a step of k between two frames taken means k-1 were sent in between: **replaced** in the queue, or lost
  in transport (the middleware's **lost** event, then counted **missing**). Where it does not (Humble), a
  *counting path* (a second subscription that takes every frame as bytes and reads only its stamp,
  :func:`~cone_perception.records.cdr_stamp_ns`) sees every frame that reaches the node, and a
  :class:`FrameLedger` matches them with those taken. Also **stale** frames (stamp older than ``max_age_s`` on
  arrival) and **silence** (no message for ``timeout_s``). With either, every frame sent since the first one
  taken is accounted for::

      sent = ok + dropped (by cause) + replaced + missing (lost upstream) + queued (0 or 1, in flight)

  With neither, ``missing`` holds the replaced frames too (stamp gaps of the frames taken).
* :class:`NodeHealth`: all of a node's, and :meth:`NodeHealth.assess`: OK / WARN / ERROR with the cause, as the
  nodes publish it on ``/diagnostics`` once a second (cumulative counts; the level is of the period).
"""

from __future__ import annotations

import threading
from collections import Counter, OrderedDict, deque
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


# -- stamp gaps ------------------------------------------------------------------------------------

#: Stamp deltas the period is learnt from (:func:`learnt_period`); gaps are counted once this many are seen.
PERIOD_WINDOW, MIN_PERIOD_SAMPLES = 32, 4
#: :func:`learnt_period`: the single-frame steps are those under this many times the lowest tenth of the steps.
SINGLE_STEP_FACTOR = 1.7
#: A stamp delta of more than this many periods counts ``round(delta / period) - 1`` missing frames.
GAP_FACTOR = 1.5
#: A stamp gap longer than this is a silence when the stream has no ``timeout_s`` (optional inputs).
DEFAULT_SILENCE_S = 1.0


def learnt_period(deltas: Iterable[float]) -> float:
    """The period: the median of the single-frame steps (under :data:`SINGLE_STEP_FACTOR` x the lowest tenth), right
    while a tenth of the steps lose no frame, with jitter up to a quarter period. A plain median is a multiple of the
    period once half the steps span lost frames (a lossy link, a starved counting path), and counts none missing."""
    s = sorted(deltas)
    return median(d for d in s if d < SINGLE_STEP_FACTOR * s[len(s) // 10])


@dataclass
class StampGaps:
    """Missing frames, stamps going backwards or repeated, and silences in one sequence of stamps (ns).

    ``period_s``: the publisher's nominal period (0 = learnt from the last :data:`PERIOD_WINDOW` positive stamp
    steps, :func:`learnt_period`; the gaps seen before it is known are judged once it is): right when a tenth
    of the steps lose no frame (a starved counting path), not for a path that takes every other frame.
    ``silence_s``: a gap longer than this is a silence (the publisher stopped), counted in ``silences``."""

    period_s: float = 0.0
    silence_s: float = DEFAULT_SILENCE_S
    missing: int = 0
    backwards: int = 0
    repeated: int = 0
    silences: int = 0
    last_ns: int | None = None
    _deltas: deque = field(default_factory=lambda: deque(maxlen=PERIOD_WINDOW))
    _unsettled: list = field(default_factory=list)  # gaps seen before the period was known

    @property
    def period_ns(self) -> float | None:
        """The stream's period: ``period_s``, or learnt from the last stamp steps once enough are seen."""
        if self.period_s > 0:
            return self.period_s * 1e9
        return learnt_period(self._deltas) if len(self._deltas) >= MIN_PERIOD_SAMPLES else None

    def _gap(self, delta: int, frames: int, period: float) -> int:
        """Frames missing in a stamp step of ``delta`` ns over ``frames`` publisher frames."""
        return max(0, round(delta / period) - frames) if delta > (frames + GAP_FACTOR - 1) * period else 0

    def step(self, stamp_ns: int, frames: int = 1) -> list[str]:
        """The next stamp, ``frames`` publisher frames after the last one (1: the next frame; more when the
        publisher's sequence numbers say frames were sent in between); returns the faults it shows (``missing``,
        ``backwards``, ``repeated``, ``silence``)."""
        last, self.last_ns = self.last_ns, stamp_ns
        if last is None:
            return []
        frames = max(1, int(frames))
        delta = stamp_ns - last
        if delta == 0:
            self.repeated += 1
            return ["repeated"]
        if delta < 0:
            self.backwards += 1
            self._deltas.clear()  # a clock jump or a restarted publisher: learn the period anew
            self._unsettled.clear()
            return ["backwards"]
        period = self.period_ns
        unexplained = delta - (frames - 1) * period if period else delta / frames
        if self.silence_s > 0 and unexplained > self.silence_s * 1e9:
            self.silences += 1
            return ["silence"]
        if self.period_s <= 0:
            self._deltas.append(delta / frames)
        self._unsettled.append((delta, frames))
        period = self.period_ns
        if period is None:  # a step of several frames may still be a silence: only the period tells
            return []
        n = 0
        for d, f in self._unsettled:  # the steps seen before the period was known, and this one
            if self.silence_s > 0 and d - (f - 1) * period > self.silence_s * 1e9:
                self.silences += 1
            else:
                n += self._gap(d, f, period)
        self._unsettled.clear()
        self.missing += n
        return ["missing"] if n else []


# -- frames replaced before processing -------------------------------------------------------------

#: Frames a ledger keeps waiting for the other path before it settles the oldest.
LEDGER_CAP = 4096


class FrameLedger:
    """Matches the frames the counting path saw (:meth:`arrive`) with those the processing path took (:meth:`take`),
    by stamp, in arrival order; thread-safe (the two paths run on two threads).

    The processing path's depth-1 queue delivers in arrival order, so when it takes frame T every frame the
    counting path saw before T and that was not taken never will be: ``replaced``. Either path may run ahead of
    the other. A frame taken that the counting path passed without seeing (its own queue overflowed) is
    ``unseen``: it is in the counting path's stamp gaps although it was processed (the stream subtracts it)."""

    def __init__(self, cap: int = LEDGER_CAP) -> None:
        self.cap, self.replaced, self.unseen = cap, 0, 0
        self.first_ns: int | None = None
        self._pending: OrderedDict[int, int] = OrderedDict()  # arrived, not taken yet: stamp -> count
        self._ahead: OrderedDict[int, int] = OrderedDict()  # taken, not arrived yet (counting path behind)
        self._lock = threading.Lock()

    @property
    def queued(self) -> int:
        """Frames that arrived and are not settled yet: in the depth-1 queue or in the processing callback."""
        return sum(self._pending.values())

    @staticmethod
    def _dec(d: OrderedDict, key: int) -> None:
        d[key] -= 1
        if d[key] <= 0:
            del d[key]

    def arrive(self, stamp_ns: int) -> None:
        with self._lock:
            if self.first_ns is None:
                self.first_ns = stamp_ns
            if stamp_ns in self._ahead:  # taken already: all seen before it and not taken were replaced
                self.replaced += sum(self._pending.values())
                self._pending.clear()
                while True:
                    s, n = next(iter(self._ahead.items()))
                    if s == stamp_ns:
                        break
                    del self._ahead[s]
                    self._count_unseen(s, n)
                self._dec(self._ahead, stamp_ns)
                return
            for s in [s for s in self._ahead if s < stamp_ns]:  # passed without seeing them
                self._count_unseen(s, self._ahead.pop(s))
            self._pending[stamp_ns] = self._pending.get(stamp_ns, 0) + 1
            self._pending.move_to_end(stamp_ns)
            while len(self._pending) > self.cap:
                self.replaced += self._pending.popitem(last=False)[1]

    def _count_unseen(self, stamp_ns: int, n: int) -> None:
        if self.first_ns is not None and stamp_ns > self.first_ns:  # inside the counting path's span
            self.unseen += n

    def take(self, stamp_ns: int) -> None:
        with self._lock:
            if stamp_ns in self._pending:
                while True:
                    s, n = next(iter(self._pending.items()))
                    if s == stamp_ns:
                        break
                    del self._pending[s]
                    self.replaced += n
                self._dec(self._pending, stamp_ns)
                return
            self._ahead[stamp_ns] = self._ahead.get(stamp_ns, 0) + 1
            while len(self._ahead) > self.cap:
                s, n = self._ahead.popitem(last=False)
                self._count_unseen(s, n)


@dataclass
class StreamMonitor:
    """Stamp and arrival bookkeeping of one input topic (stamps and times in ns).

    ``timeout_s``: silence longer than this is an ERROR (0 = never). ``max_age_s``: a frame whose stamp is older
    than this on arrival is stale (0 = not checked; e.g. a bag played with its original stamps). ``period_s``: the
    publisher's nominal period (0 = learnt, :class:`StampGaps`).

    :meth:`observe` is the processing path (every message its callback gets); :meth:`arrive` the counting path,
    where the node has one (``counted``): then the stamp faults and gaps are those of the counting path."""

    topic: str
    timeout_s: float = 1.0
    max_age_s: float = 0.0
    period_s: float = 0.0
    received: int = 0
    ok: int = 0  # of ``received``: processed (counted by the node's guard)
    dropped: int = 0  # of ``received``: dropped with a cause (in :class:`FrameStats`)
    arrived: int = 0  # messages the counting path saw (``counted`` streams)
    lost: int = 0  # reported lost by the middleware (DDS sample lost), where it reports it
    stale: int = 0
    silences: int = 0
    optional: bool = False  # an input the node works without: silence and no publisher are no error
    counted: bool = False  # a counting path calls :meth:`arrive` with every message
    sequenced: bool = False  # the processing path gets the publisher's sequence numbers
    seq_gaps: int = 0  # frames the publisher sent between two the processing path took (sequence numbers)
    seq_resets: int = 0  # sequence numbers going back: a restarted (or a second) publisher
    last_seq: int | None = None
    last_arrival_ns: int | None = None
    started_ns: int | None = None
    gaps: StampGaps = field(default_factory=StampGaps)
    ledger: FrameLedger = field(default_factory=FrameLedger)
    _silent: bool = False

    def __post_init__(self) -> None:
        self.gaps.period_s = self.period_s
        self.gaps.silence_s = self.timeout_s if self.timeout_s > 0 else DEFAULT_SILENCE_S

    def start(self, now_ns: int) -> None:
        """The time from which silence is measured before the first message."""
        if self.started_ns is None:
            self.started_ns = now_ns

    @property
    def period_ns(self) -> float | None:
        return self.gaps.period_ns

    @property
    def last_stamp_ns(self) -> int | None:
        return self.gaps.last_ns

    @property
    def missing(self) -> int:
        """Frames lost upstream: with sequence numbers, those the middleware reports lost in transport
        plus those never published (stamp gaps the sequence numbers do not explain); with a counting
        path, its stamp gaps; else every stamp gap (which then also holds the replaced frames)."""
        if self.sequenced:
            return min(self.lost, self.seq_gaps) + self.gaps.missing
        return max(0, self.gaps.missing - self.ledger.unseen) if self.counted else self.gaps.missing

    @property
    def replaced(self) -> int:
        """Frames replaced in the depth-1 queue before processing (sequence numbers or counting path)."""
        if self.sequenced:
            return max(0, self.seq_gaps - self.lost)
        return self.ledger.replaced if self.counted else 0

    @property
    def queued(self) -> int:
        return self.ledger.queued if self.counted else 0

    backwards = property(lambda self: self.gaps.backwards)
    repeated = property(lambda self: self.gaps.repeated)

    @property
    def total(self) -> int:
        """Every frame sent on the topic as far as the node can tell: received + replaced + queued + missing."""
        return self.received + self.replaced + self.queued + self.missing

    def _arrival(self, now_ns: int) -> None:
        self.start(now_ns)
        if (self.last_arrival_ns is not None and not self._silent and self.timeout_s > 0
                and now_ns - self.last_arrival_ns > self.timeout_s * 1e9):
            self.silences += 1  # silent longer than the timeout between two reports: not seen by is_silent
        self.last_arrival_ns = now_ns
        self._silent = False

    def observe(self, stamp_ns: int | None, now_ns: int, seq: int | None = None) -> list[str]:
        """One message reached the processing callback (``stamp_ns`` its header stamp, ``None`` if it
        has none; ``seq`` the publisher's sequence number of it, where the middleware gives one);
        returns the faults it shows (``missing``, ``backwards``, ``repeated``, ``stale``), each counted."""
        self.received += 1
        if not self.counted:
            self._arrival(now_ns)
        frames = 1
        if seq is not None and not self.counted:  # a stream is accounted for one way: the counting path's, else these
            self.sequenced = True
            if self.last_seq is not None:
                if seq > self.last_seq:
                    frames = seq - self.last_seq
                    self.seq_gaps += frames - 1
                else:  # a restarted publisher (or a second one): a new sequence
                    self.seq_resets += 1
            self.last_seq = seq
        faults = ["replaced"] if frames > 1 else []
        if stamp_ns is None:
            return faults
        if self.max_age_s > 0 and now_ns - stamp_ns > self.max_age_s * 1e9:
            self.stale += 1
            faults.append("stale")
        if self.counted and not self.sequenced:
            self.ledger.take(stamp_ns)
        else:
            faults += [f for f in self.gaps.step(stamp_ns, frames) if f != "silence"]
        return faults

    def arrive(self, stamp_ns: int | None, now_ns: int) -> list[str]:
        """One message seen by the counting path (every one that reaches the node); returns its
        stamp faults (``missing``, ``backwards``, ``repeated``)."""
        self.counted = True
        self.arrived += 1
        self._arrival(now_ns)
        if stamp_ns is None:
            return []
        faults = [f for f in self.gaps.step(stamp_ns) if f != "silence"]
        self.ledger.arrive(stamp_ns)
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
        c = {"received": self.received, "ok": self.ok, "dropped": self.dropped, "replaced": self.replaced,
             "queued": self.queued}
        if self.counted:
            c.update(arrived=self.arrived)
        if self.sequenced:
            c.update(seq_resets=self.seq_resets)
        c.update(missing=self.missing, lost=self.lost, backwards=self.backwards, repeated=self.repeated,
                 stale=self.stale, silences=self.silences)
        return c


@dataclass
class HealthReport:
    level: int
    message: str
    values: list[tuple[str, str]]

    @property
    def level_name(self) -> str:
        return LEVEL_NAMES[self.level]


#: What each stream count means in a ``/diagnostics`` message (``missing``: by whether the stream is counted).
_LABELS = {"replaced": "replaced in the queue before processing", "lost": "lost in transport (middleware)",
           "backwards": "stamps going backwards", "repeated": "stamps repeated", "stale": "stale frames"}
_MISSING = {True: "lost upstream", False: "missing (stamp gaps: replaced or lost upstream)"}


class NodeHealth:
    """A node's :class:`FrameStats` and one :class:`StreamMonitor` per input topic."""

    def __init__(self, timeout_s: float = 1.0, max_age_s: float = 0.0, period_s: float = 0.0) -> None:
        self.stats = FrameStats()
        self.streams: dict[str, StreamMonitor] = {}
        self.timeout_s, self.max_age_s, self.period_s = timeout_s, max_age_s, period_s
        self._last: dict[str, int] = {}
        self._last_ns: int | None = None
        self.watched: dict[str, tuple[Mapping[str, int], frozenset[str]]] = {}
        self.info: dict[str, str] = {}  # facts on every /diagnostics: key -> text (``attitude:box_model``)

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
            for k in ("replaced", "missing", "lost", "backwards", "repeated", "stale"):
                t[f"{s.topic}:{k}"] += getattr(s, k)
            t[f"{s.topic}:ok"] = s.ok
            t[f"{s.topic}:total"] = s.total
        for name, (counts, warn) in self.watched.items():
            for k in warn:
                if counts.get(k, 0):
                    t[f"{name}:{k}"] = int(counts[k])
        return dict(t)

    def assess(self, now_ns: int, publishers: dict[str, int] | None = None) -> HealthReport:
        """The level and cause for this period (since the previous call), and the cumulative counts: ERROR for silence
        or a topic without a publisher (``publishers``: topic -> publishers now; 0: a missing or dead upstream); WARN
        for drops, replaced or missing frames, stamp faults or stale frames; OK otherwise."""
        errors, warns, rates = [], [], []
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
        dt_s = (now_ns - self._last_ns) / 1e9 if self._last_ns is not None and now_ns > self._last_ns else 0.0
        self._last, self._last_ns = totals, now_ns
        for k, v in sorted(new.items()):
            if k.startswith("dropped_"):
                warns.append(f"{v} dropped ({k[len('dropped_'):]})")
            elif k in totals and ":" in k and k.split(":", 1)[0] in self.watched:
                warns.append(f"{v} {k.replace(':', ' ')}")
        for s in self.streams.values():
            fell_behind = False
            for k in ("replaced", "missing", "lost", "backwards", "repeated", "stale"):
                v = new.get(f"{s.topic}:{k}", 0)
                if v:
                    label = _MISSING[s.counted or s.sequenced] if k == "missing" else _LABELS[k]
                    warns.append(f"{v} {label} on {s.topic}")
                    fell_behind |= k in ("replaced", "missing")
            sent, ok = new.get(f"{s.topic}:total", 0), new.get(f"{s.topic}:ok", 0)
            if dt_s > 0 and sent:
                rate = f"processing {ok / dt_s:.0f} of {sent / dt_s:.0f} frames/s on {s.topic}"
                (warns.insert(0, rate) if fell_behind else rates.append(rate))
        level = ERROR if errors else WARN if warns else OK
        message = "; ".join(errors + warns) if errors or warns else "; ".join(rates + [self.summary()])
        values = [("frames_ok", str(self.stats.ok))]
        values += [(f"dropped_{k}", str(v)) for k, v in sorted(self.stats.dropped.items())]
        for s in self.streams.values():
            values += [(f"{s.topic}:{k}", str(v)) for k, v in s.counts().items()]
        for name, (counts, _) in self.watched.items():
            values += [(f"{name}:{k}", str(v)) for k, v in sorted(counts.items())]
        values += list(self.info.items())
        return HealthReport(level, message, values)

    def summary(self) -> str:
        """One line for the log: the frame counts and each stream's faults (never "none dropped"
        while frames were replaced or missing)."""
        lost = sum(s.replaced + s.missing for s in self.streams.values())
        parts = [self.stats.summary() if not lost else self.stats.summary().replace(", none dropped", ", 0 dropped")]
        for s in self.streams.values():
            faults = {k: v for k, v in s.counts().items() if k not in ("received", "ok", "dropped", "arrived") and v}
            if faults:
                parts.append(f"{s.topic}: " + ", ".join(f"{k}={v}" for k, v in faults.items()))
        for name, (counts, _) in self.watched.items():
            if any(counts.values()):
                parts.append(f"{name}: " + ", ".join(f"{k}={v}" for k, v in sorted(counts.items()) if v))
        return "; ".join(parts)
