"""Tracking in the offline ``replay``: drop detections (seeded), track, score against a synthetic drive. ROS-free.

:class:`ReplayTracking` takes each replayed frame's ``/cones``, drops a random share of them when
asked (``replay --drop-detections P``, to measure gap filling), feeds the bag's odometry twists
when there are any, runs the :class:`~cone_perception.tracking.TrackingStage` and scores both the
raw (after the drop) and the tracked cones within :data:`~cone_perception.evaluation.tracking.EVAL_RANGE_M`
against the drive's truth (``<bag>_gt.jsonl``) when it is given.
"""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

import numpy as np

from ..errors import ConfigError, FrameError
from ..evaluation.tracking import EVAL_RANGE_M, DriveEvaluation, DriveTruth, format_drive_evaluation, load_drive_truth
from ..tracking import TrackerConfig, TrackingStage


def drive_truth_beside(bag: str | os.PathLike) -> DriveTruth | None:
    """The ``<bag>_gt.jsonl`` that ``synth bag`` writes beside a bag, loaded; None if there is none."""
    p = Path(bag)
    gt = p.parent / f"{p.name}_gt.jsonl"
    return load_drive_truth(gt) if gt.is_file() else None


def drop_detections(cones: np.ndarray, share: float, rng: np.random.Generator) -> np.ndarray:
    """``cones`` without a random ``share`` (0..1) of them, each dropped independently."""
    if share <= 0 or len(cones) == 0:
        return cones
    return cones[rng.random(len(cones)) >= share]


class ReplayTracking:
    """Per-frame tracking (and scoring) inside a replay; see the module doc."""

    def __init__(self, calib, track: bool = True, drop_share: float = 0.0, seed: int = 0,
                 truth: DriveTruth | None = None, twists: list[tuple[int, float, float, float]] | None = None,
                 config: TrackerConfig | None = None, range_m: float = EVAL_RANGE_M):
        if not 0.0 <= drop_share < 1.0:
            raise ConfigError("--drop-detections", None, f"must be a share in 0..1 (exclusive), got {drop_share}")
        self.stage = TrackingStage(calib, config) if track else None
        self.drop_share = drop_share
        self.rng = np.random.default_rng(seed)
        self.truth = truth
        self.evaluation = DriveEvaluation(truth, range_m) if truth is not None else None
        self.twists = twists or []
        self._next_twist = 0
        self.dropped_detections = 0
        self.not_fused = Counter()

    def frame(self, stamp_ns: int, cones: np.ndarray, attitude=None, weak: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """One frame's ``/cones`` -> (``/cones`` after the drop, tracked records or None when not fused).
        ``attitude``: the :class:`~cone_perception.attitude.Attitude` the cones were mapped with; ``weak``: the
        frame's cones below the ``/cones`` threshold (:attr:`FrameResult.weak_cones`), tracked only (not dropped,
        not scored as ``/cones``)."""
        kept = drop_detections(cones, self.drop_share, self.rng)
        self.dropped_detections += len(cones) - len(kept)
        if self.evaluation is not None:
            self.evaluation.add_raw(stamp_ns, kept)
        if self.stage is None:
            return kept, None
        while self._next_twist < len(self.twists) and self.twists[self._next_twist][0] <= stamp_ns:
            self.stage.add_twist(*self.twists[self._next_twist])
            self._next_twist += 1
        try:
            fused = kept if weak is None or len(weak) == 0 else np.concatenate([kept, weak.astype(kept.dtype)])
            tracked, info = self.stage.process(stamp_ns, fused, attitude)
        except FrameError as e:
            self.not_fused[e.reason] += 1
            return kept, None
        if self.evaluation is not None:
            self.evaluation.add_tracked(stamp_ns, tracked, info.motion if info.motion_source != "none" else None)
        return kept, tracked

    def summary(self) -> dict:
        out: dict = {"drop_share": self.drop_share, "dropped_detections": self.dropped_detections}
        if self.stage is not None:
            out["events"] = dict(self.stage.events)
            out["not_fused"] = dict(self.not_fused)
        if self.evaluation is not None:
            out.update(self.evaluation.summary())
        return out


def format_replay_tracking(s: dict) -> str:
    """Plain-text lines of :meth:`ReplayTracking.summary`."""
    rows = []
    if s["drop_share"] > 0:
        rows.append(f"dropped detections: {s['dropped_detections']} ({s['drop_share']:.0%} share, seeded)")
    if "raw" in s or "tracked" in s:
        rows.append(format_drive_evaluation(s))
    if s.get("events") or s.get("not_fused"):
        ev = {**s.get("events", {}), **{f"not_fused_{k}": v for k, v in s.get("not_fused", {}).items()}}
        rows.append("tracker events: " + ", ".join(f"{k}={v}" for k, v in sorted(ev.items())))
    return "\n".join(rows)
