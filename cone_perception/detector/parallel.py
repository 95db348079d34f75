"""The band's and the far strip's detectors at the same time, on two threads.

With a far strip (:mod:`.farband`) every frame runs two forwards. On two CPU threads they can run
one after the other, each network on two intra-op threads, or at once, each network on one intra-op
thread: the strip on a worker thread, the band on the calling thread. ONNX Runtime and torch release
the GIL in the forward, so the two overlap: a strip smaller than the band hides behind the band's
forward, and neither network has an intra-op pool to synchronise (a pool's threads wait for each
other at every parallel section; since issue 26h they no longer spin while waiting, backends.ort_spinning,
and one after the other on 2+2 threads was then 1.06-1.29x at once under load: docs/benchmarks.md, "Band
rows and ONNX Runtime spinning"; the quiet machine is unmeasured). It needs two free cores: with one core
busy elsewhere, one thread one after the other is faster (docs/benchmarks.md, "Band and far strip at
once on two threads").

* :class:`ForwardPlan`: the rule, from the ``threads`` setting and whether a strip runs:
  ``threads >= 2`` and a strip: at once, each network on ``threads // 2`` intra-op threads;
  else one after the other on ``threads`` (``threads: 1``, the car's default, stays sequential and
  leaves the other core to the rest of the car; 0, the library's default, too).
* :class:`PairRunner`: runs two calls (sequentially or at once) and times each; an exception of
  either is the frame's; :meth:`PairRunner.close` joins the worker.

The boxes are the same either way: each network sees the same input, and the merge runs after both.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable, TypeVar

#: The worker thread's name (its prefix: ``cone-far-strip_0``).
WORKER_NAME = "cone-far-strip"

A = TypeVar("A")
B = TypeVar("B")


@dataclass(frozen=True)
class ForwardPlan:
    """How the band's and the strip's forwards share the network's ``threads``."""

    concurrent: bool  # the two forwards at once (the strip on a worker thread)
    network_threads: int  # intra-op threads each network is loaded with (0: the library's default)

    @classmethod
    def of(cls, threads: int, strip: bool) -> "ForwardPlan":
        """The plan for ``threads`` network threads (the ``threads`` parameter, ``--threads``; 0 = the
        library's default) with or without a far ``strip``: at once when ``threads >= 2`` and a strip,
        each network on ``threads // 2``; else sequential, each on ``threads``."""
        threads = int(threads)
        if threads < 0:
            raise ValueError(f"threads must be >= 0, got {threads}")
        if strip and threads >= 2:
            return cls(True, threads // 2)
        return cls(False, threads)

    def describe(self) -> str:
        """A few words for logs and ``bench``: ``band and strip at once, 1 thread each`` or ``sequential``."""
        if self.concurrent:
            return f"band and strip at once, {self.network_threads} thread{'s' if self.network_threads != 1 else ''} each"
        return "sequential"


def _timed(fn: Callable[[], A]) -> tuple[A, float, float]:
    """``fn()`` and its start and end (``perf_counter`` s)."""
    t0 = time.perf_counter()
    out = fn()
    return out, t0, time.perf_counter()


class PairRunner:
    """Runs two calls per frame: the first (the band's detect) on the calling thread, the second (the
    strip's) one after it (``concurrent=False``) or at the same time on one worker thread.

    The worker is started at the first concurrent :meth:`run` and joined by :meth:`close` (a later
    :meth:`run` starts a new one). A call that raises makes :meth:`run` raise that exception, the same
    object (a :class:`~cone_perception.errors.FrameError` stays one, with its reason); :meth:`run`
    always waits for the worker's call to end first, so no call outlives its frame. When both raise,
    the first's is raised. Not for two callers at once: a pipeline runs one frame at a time."""

    def __init__(self, concurrent: bool):
        self.concurrent = bool(concurrent)
        self._pool: ThreadPoolExecutor | None = None

    @property
    def alive(self) -> bool:
        """Whether a worker thread is held (from the first concurrent :meth:`run` to :meth:`close`)."""
        return self._pool is not None

    def close(self) -> None:
        """Join the worker (after the call it may be running); idempotent."""
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True)

    # -- running --------------------------------------------------------------------------------
    def run(self, first: Callable[[], A], second: Callable[[], B]) -> tuple[A, B, dict[str, float]]:
        """``(first(), second(), timing)``: ``timing`` in ms: ``first`` and ``second``, each call's own
        time (on its thread), and ``wall``, from the start of the first to the end of the later one."""
        if not self.concurrent:
            a, a0, a1 = _timed(first)
            b, b0, b1 = _timed(second)
            return a, b, {"first": (a1 - a0) * 1e3, "second": (b1 - b0) * 1e3, "wall": (b1 - a0) * 1e3}
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=WORKER_NAME)
        t0 = time.perf_counter()
        fut = self._pool.submit(_timed, second)
        try:
            a, a0, a1 = _timed(first)
        except BaseException:
            fut.exception()  # wait for the strip's call: it must not run on into the next frame
            raise
        b, b0, b1 = fut.result()  # the worker's exception, if any, raised here
        return a, b, {"first": (a1 - a0) * 1e3, "second": (b1 - b0) * 1e3, "wall": (max(a1, b1) - t0) * 1e3}

    def __enter__(self) -> "PairRunner":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


__all__ = ["ForwardPlan", "PairRunner"]
