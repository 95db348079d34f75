"""Quality of the tracked cone map on synthetic drives: recall, false cones, error, ids, ego-motion. ROS-free.

Truth comes from the ``<bag>_gt.jsonl`` that ``cone-perception synth bag`` writes beside a bag: per
frame (by ``stamp_ns``) the car pose in the track frame and every cone with a visible pixel. Cones
get a truth id by their track-frame position (the same cone seen in many frames). Per frame,
within :attr:`TrackingReport.range_m` (15 m) of the rear axle:

* **recall**: of the cones the frame shows (as ``/cones_gt``), the share a tracked cone lies on
  (matching as :func:`cone_perception.evaluation.match_cones`);
* **false cones**: tracked cones that lie on no real cone (any cone of the drive seen at or before
  this frame: a tracked cone beside the car, out of view, is real, not false);
* **position error** per distance group of the cones the frame shows (the pairs of the recall), so
  that it compares with the ``/cones`` error (:data:`DISTANCE_GROUPS`);
* **ids**: an id switch when a truth cone that stayed within range (and in front of the axle) is
  matched to another track id than at its last match (``id_switches``; ``id_switches_all`` also
  counts a cone that comes back into range, e.g. where the course passes a place again, under a new
  id: the tracker keeps a local map, not a map of the course);
  **IDF1** (Ristani et al. 2016): truth ids and track ids paired one-to-one over the whole drive to
  maximise the frames they are matched in, ``IDF1 = 2 IDTP / (n_truth + n_tracked)``;
* **ego-motion**: the estimated motion between consecutive frames against the true one
  (translation error, also as a share of the distance travelled; yaw error).

:class:`DriveEvaluation` scores the raw ``/cones`` (recall, false cones and error within the same
range, :class:`~cone_perception.evaluation.LocalisationReport`) beside the tracked ones: the table
``replay --track --gt-topic`` prints, and ``eval --tracked`` from a replay's output bag
(:func:`evaluate_tracking_bag`, :func:`write_tracking_report`).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ConfigError
from ..tracking import Motion2D
from . import BANDS_MAX_M, DISTANCE_GROUPS, EXTRA_GROUPS, GT_MIN_VISIBLE, LocalisationReport, distance_group, match_cones

EVAL_RANGE_M = 15.0


@dataclass
class DriveFrame:
    """Truth of one frame: car pose in the track frame and the visible cones (``rear_axle`` m)."""

    pose: tuple[float, float, float]  # x_m, y_m, yaw_rad
    xy_m: np.ndarray  # (N, 2) float64
    class_ids: np.ndarray  # (N,) int
    cone_ids: np.ndarray  # (N,) int truth id
    visible: np.ndarray | None = None  # (N,) visible fraction (None: not in the truth file)


@dataclass
class DriveTruth:
    frames: dict[int, DriveFrame]  # stamp ns -> frame
    world_xy_m: np.ndarray  # (M, 2) every cone seen, track frame
    first_seen_ns: np.ndarray  # (M,) stamp of the first frame that shows it

    def motion(self, t0_ns: int, t1_ns: int) -> Motion2D:
        """True motion from frame ``t0`` to frame ``t1`` (pose of t1 in t0's rear_axle)."""
        x0, y0, a0 = self.frames[t0_ns].pose
        x1, y1, a1 = self.frames[t1_ns].pose
        c, s = np.cos(a0), np.sin(a0)
        dx, dy = x1 - x0, y1 - y0
        return Motion2D(c * dx + s * dy, -s * dx + c * dy, float((a1 - a0 + np.pi) % (2 * np.pi) - np.pi))

    def world_in_frame(self, stamp_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """Cones seen at or before ``stamp_ns`` in that frame's ``rear_axle``: ((K, 2) m, (K,) truth ids)."""
        x, y, a = self.frames[stamp_ns].pose
        ids = np.flatnonzero(self.first_seen_ns <= stamp_ns)
        c, s = np.cos(a), np.sin(a)
        d = self.world_xy_m[ids] - (x, y)
        return np.c_[c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], ids


def load_drive_truth(path: str | os.PathLike, cell_m: float = 0.05) -> DriveTruth:
    """Read a synthetic bag's ``gt.jsonl`` (lines with ``stamp_ns``, ``pose``, ``cones``)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(str(path), None, "drive ground truth (gt.jsonl of cone-perception synth bag) not found")
    frames, keys, world, first = {}, {}, [], []
    with open(path, encoding="utf-8") as f:
        for n, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                d = json.loads(line)
                stamp = int(d["stamp_ns"])
                p = d["pose"]
                pose = (float(p["x_m"]), float(p["y_m"]), float(np.radians(p["yaw_deg"])))
                xy = np.array([[c["x_m"], c["y_m"]] for c in d["cones"]], dtype=np.float64).reshape(-1, 2)
                cls = np.array([int(c["class_id"]) for c in d["cones"]], dtype=np.int64)
                vis = np.array([float(c.get("visible_fraction", 1.0)) for c in d["cones"]], dtype=np.float64)
            except (ValueError, KeyError, TypeError) as e:
                raise ConfigError(str(path), f"line {n}", f"not a synth bag truth line (stamp_ns, pose, cones): {e}") from None
            c, s = np.cos(pose[2]), np.sin(pose[2])
            w = np.c_[pose[0] + c * xy[:, 0] - s * xy[:, 1], pose[1] + s * xy[:, 0] + c * xy[:, 1]]
            ids = np.empty(len(w), dtype=np.int64)
            for i, (wx, wy) in enumerate(w):
                k = (int(round(wx / cell_m)), int(round(wy / cell_m)))
                if k not in keys:
                    keys[k] = len(world)
                    world.append((wx, wy))
                    first.append(stamp)
                ids[i] = keys[k]
            frames[stamp] = DriveFrame(pose, xy, cls, ids, vis)
    return DriveTruth(frames, np.array(world, dtype=np.float64).reshape(-1, 2), np.array(first, dtype=np.int64))


def idf1(pair_counts: dict[tuple[int, int], int], n_truth: int, n_tracked: int) -> tuple[float, int]:
    """``(IDF1, IDTP)`` from the frames each (truth id, track id) pair was matched in.

    The one-to-one pairing of ids that maximises the matched frames (linear sum assignment) gives
    IDTP; ``n_truth`` / ``n_tracked`` are the truth and tracked cone-frames counted.
    """
    from scipy.optimize import linear_sum_assignment

    if not pair_counts or n_truth + n_tracked == 0:
        return (0.0 if n_truth + n_tracked else float("nan")), 0
    gts = sorted({g for g, _ in pair_counts})
    trs = sorted({t for _, t in pair_counts})
    gi, ti = {g: i for i, g in enumerate(gts)}, {t: i for i, t in enumerate(trs)}
    m = np.zeros((len(gts), len(trs)))
    for (g, t), c in pair_counts.items():
        m[gi[g], ti[t]] = c
    r, c = linear_sum_assignment(-m)
    idtp = int(m[r, c].sum())
    return 2.0 * idtp / (n_truth + n_tracked), idtp


@dataclass
class TrackingReport:
    """Accumulates frames of tracked cones against a :class:`DriveTruth`; :meth:`summary` gives the figures."""

    truth: DriveTruth
    range_m: float = EVAL_RANGE_M
    frames: int = 0
    n_visible: int = 0
    n_found: int = 0
    n_false: int = 0
    err: list = field(default_factory=list)
    err_range: list = field(default_factory=list)
    id_switches: int = 0  # while the cone stays within range
    id_switches_all: int = 0  # CLEAR MOT: also when a cone comes back into range under a new id
    last_id: dict = field(default_factory=dict)  # truth id -> track id
    last_in_range: dict = field(default_factory=dict)  # truth id -> last frame number it was within range
    pairs: dict = field(default_factory=dict)  # (truth id, track id) -> frames
    n_truth_ids: int = 0  # truth cone-frames (for IDF1)
    n_tracked_ids: int = 0
    ego_err_m: list = field(default_factory=list)
    ego_err_frac: list = field(default_factory=list)
    ego_err_yaw: list = field(default_factory=list)
    # the look-ahead bands (EXTRA_GROUPS, to BANDS_MAX_M whatever range_m): per band [true cones at least
    # GT_MIN_VISIBLE visible, of them found, tracked cones on no real cone]
    band_counts: dict = field(default_factory=lambda: {name: [0, 0, 0] for name, _, _ in EXTRA_GROUPS})
    _last_stamp: int | None = None

    def add_frame(self, stamp_ns: int, tracked: np.ndarray, motion: Motion2D | None = None) -> None:
        """``tracked``: records with ``x``, ``y`` and ``track_id``; ``motion``: the tracker's estimate from the
        previous frame added (None: no ego-motion figure)."""
        if stamp_ns not in self.truth.frames:
            return
        fr = self.truth.frames[stamp_ns]
        if motion is not None and self._last_stamp is not None:
            true = self.truth.motion(self._last_stamp, stamp_ns)
            e = float(np.hypot(motion.dx - true.dx, motion.dy - true.dy))
            self.ego_err_m.append(e)
            if true.translation_m > 1e-3:
                self.ego_err_frac.append(e / true.translation_m)
            self.ego_err_yaw.append(abs((motion.dyaw - true.dyaw + np.pi) % (2 * np.pi) - np.pi))
        self._last_stamp = stamp_ns
        self.frames += 1
        p = np.c_[tracked["x"], tracked["y"]].astype(np.float64).reshape(-1, 2)
        p_in = np.hypot(p[:, 0], p[:, 1]) <= self.range_m
        # recall over what the frame shows
        r_vis = np.hypot(fr.xy_m[:, 0], fr.xy_m[:, 1])
        vis = r_vis <= self.range_m
        self.n_visible += int(vis.sum())
        vis_pairs = match_cones(p, fr.xy_m[vis])
        self.n_found += len(vis_pairs)
        for _, j, d in vis_pairs:  # errors of the cones the frame shows, as for /cones
            self.err.append(d)
            self.err_range.append(r_vis[vis][j])
        # false cones, errors and ids against every real cone seen so far
        w_xy, w_id = self.truth.world_in_frame(stamp_ns)
        w_r = np.hypot(w_xy[:, 0], w_xy[:, 1])
        near = w_r <= self.range_m + 1.0  # a tracked cone at 14.9 m may be a real one at 15.3 m
        w_xy, w_id, w_r = w_xy[near], w_id[near], w_r[near]
        pairs = match_cones(p, w_xy)
        matched_p = np.zeros(len(p), dtype=bool)
        for i, _, _ in pairs:
            matched_p[i] = True
        self.n_false += int((p_in & ~matched_p).sum())
        self._add_bands(stamp_ns, p)
        # ids: truth cones within range (in front of the axle), tracked cones within range
        tid = tracked["track_id"] if len(tracked) else np.zeros(0, np.int64)
        in_t = (w_r <= self.range_m) & (w_xy[:, 0] >= 0.0)
        self.n_truth_ids += int(in_t.sum())
        stayed = {int(g) for g in w_id[in_t] if self.last_in_range.get(int(g)) == self.frames - 1}
        for g in w_id[in_t]:
            self.last_in_range[int(g)] = self.frames
        self.n_tracked_ids += int((p_in & (p[:, 0] >= 0.0)).sum())
        for i, j, _ in pairs:
            if not in_t[j] or not p_in[i] or p[i, 0] < 0.0:
                continue
            g, t = int(w_id[j]), int(tid[i])
            self.pairs[(g, t)] = self.pairs.get((g, t), 0) + 1
            if g in self.last_id and self.last_id[g] != t:
                self.id_switches_all += 1
                self.id_switches += g in stayed
            self.last_id[g] = t

    def _add_bands(self, stamp_ns: int, p: np.ndarray) -> None:
        """The look-ahead bands: recall of the cones the frame shows (at least half visible) by their range,
        false cones (on no cone of the drive seen so far) by the tracked cone's own range."""
        fr = self.truth.frames[stamp_ns]
        r_t = np.hypot(fr.xy_m[:, 0], fr.xy_m[:, 1])
        vis = fr.visible if fr.visible is not None else np.ones(len(r_t))
        found = np.zeros(len(r_t), dtype=bool)
        for _, j, _ in match_cones(p, fr.xy_m):
            found[j] = True
        w_xy, _ = self.truth.world_in_frame(stamp_ns)  # every cone seen so far, at any range
        real = np.zeros(len(p), dtype=bool)
        for i, _, _ in match_cones(p, w_xy):
            real[i] = True
        r_p = np.hypot(p[:, 0], p[:, 1])
        for name, lo, hi in EXTRA_GROUPS:
            t = (r_t >= lo) & (r_t < hi) & (vis >= GT_MIN_VISIBLE)
            c = self.band_counts[name]
            c[0] += int(t.sum())
            c[1] += int((t & found).sum())
            c[2] += int(((r_p >= lo) & (r_p < hi) & ~real).sum())

    def bands_summary(self) -> dict:
        """Per look-ahead band: true cones, recall, false cones and false cones per frame."""
        f = self.frames
        return {name: {"n_true": c[0], "recall": c[1] / c[0] if c[0] else float("nan"), "false_cones": c[2],
                       "false_per_frame": c[2] / f if f else float("nan")} for name, c in self.band_counts.items()}

    def summary(self) -> dict:
        e, er = np.asarray(self.err), np.asarray(self.err_range)
        g = distance_group(er)
        groups = {}
        for k, (name, lo, _) in enumerate(DISTANCE_GROUPS):
            if lo >= self.range_m:
                continue
            eg = e[g == k]
            groups[name] = {"n": int(eg.size), "median_err_m": float(np.median(eg)) if eg.size else float("nan"),
                            "p90_err_m": float(np.percentile(eg, 90)) if eg.size else float("nan")}
        near = e[er < 7.0]
        f1, idtp = idf1(self.pairs, self.n_truth_ids, self.n_tracked_ids)
        ego = np.asarray(self.ego_err_m)
        frac = np.asarray(self.ego_err_frac)
        nan = float("nan")
        return {
            "frames": self.frames,
            "range_m": self.range_m,
            "recall": self.n_found / self.n_visible if self.n_visible else nan,
            "false_per_frame": self.n_false / self.frames if self.frames else nan,
            "median_err_0_7_m": float(np.median(near)) if near.size else nan,
            "groups": groups,
            "id_switches": self.id_switches,
            "id_switches_per_100_frames": 100.0 * self.id_switches / self.frames if self.frames else nan,
            "id_switches_all": self.id_switches_all,
            "idf1": f1,
            "ego_frames": int(ego.size),
            "ego_median_err_m": float(np.median(ego)) if ego.size else nan,
            "ego_median_err_frac": float(np.median(frac)) if frac.size else nan,
            "ego_p90_err_frac": float(np.percentile(frac, 90)) if frac.size else nan,
            "ego_median_err_yaw_deg": float(np.degrees(np.median(self.ego_err_yaw))) if self.ego_err_yaw else nan,
            "bands": self.bands_summary(),
        }


def format_tracking(s: dict, title: str = "/cones/tracked") -> str:
    """Plain-text lines of :meth:`TrackingReport.summary`."""
    rows = [f"{title} within {s['range_m']:g} m over {s['frames']} frames: recall {s['recall']:.3f}, "
            f"false cones {s['false_per_frame']:.2f}/frame, id switches {s['id_switches']} "
            f"({s['id_switches_per_100_frames']:.2f}/100 frames; {s['id_switches_all']} counting cones back in range "
            f"under a new id), IDF1 {s['idf1']:.3f}"]
    rows.append("  position error (m): " + ", ".join(
        f"{name} median {g['median_err_m']:.3f} p90 {g['p90_err_m']:.3f} (n {g['n']})" for name, g in s["groups"].items()))
    if s.get("bands"):
        rows.append(f"  by range (to {BANDS_MAX_M:g} m, cones >= {GT_MIN_VISIBLE:g} visible): " + ", ".join(
            f"{name} recall {b['recall']:.3f} (n {b['n_true']}) false {b['false_per_frame']:.2f}/frame"
            for name, b in s["bands"].items()))
    if s["ego_frames"]:
        rows.append(f"  ego-motion per frame ({s['ego_frames']} frames): median translation error {s['ego_median_err_m'] * 100:.2f} cm = "
                    f"{s['ego_median_err_frac'] * 100:.1f} % of the distance travelled (p90 {s['ego_p90_err_frac'] * 100:.1f} %), "
                    f"median yaw error {s['ego_median_err_yaw_deg']:.3f} deg")
    return "\n".join(rows)


class DriveEvaluation:
    """``/cones`` (raw) and ``/cones/tracked`` of one drive against its :class:`DriveTruth`, within ``range_m``.

    :meth:`add_raw` and :meth:`add_tracked` take a frame by its capture stamp (frames the truth does not
    have are skipped); :meth:`summary` gives ``{"raw": ..., "tracked": ...}`` for what was added.
    """

    def __init__(self, truth: DriveTruth, range_m: float = EVAL_RANGE_M):
        self.truth = truth
        self.raw = LocalisationReport(max_range_m=range_m, min_visible=GT_MIN_VISIBLE)
        self.tracked = TrackingReport(truth, range_m)

    def add_raw(self, stamp_ns: int, cones: np.ndarray) -> None:
        """One frame's ``/cones`` (``CONE_DTYPE``) against every cone the frame shows."""
        if stamp_ns not in self.truth.frames:
            return
        fr = self.truth.frames[stamp_ns]
        gt = np.zeros(len(fr.xy_m), dtype=cones.dtype)
        gt["x"], gt["y"], gt["class_id"] = fr.xy_m[:, 0], fr.xy_m[:, 1], fr.class_ids
        gt["score"] = fr.visible if fr.visible is not None else 1.0
        self.raw.add_frame(cones, gt)

    def add_tracked(self, stamp_ns: int, tracked: np.ndarray, motion: Motion2D | None = None) -> None:
        """One frame's ``/cones/tracked``; ``motion``: the tracker's ego-motion estimate, if known."""
        self.tracked.add_frame(stamp_ns, tracked, motion)

    def summary(self) -> dict:
        out: dict = {}
        if self.raw.frames:
            r = self.raw.summary()
            e = np.hypot(np.asarray(self.raw.err_x), np.asarray(self.raw.err_y))
            near = e[np.asarray(self.raw.err_range) < 7.0]
            out["raw"] = {"range_m": self.raw.max_range_m, "frames": r["frames"], "recall": r["all"]["recall"],
                          "false_per_frame": r["false_positives"] / r["frames"],
                          "median_err_0_7_m": float(np.median(near)) if near.size else float("nan"),
                          "median_err_7_15_m": r["groups"]["far 7-15 m"]["median_err_m"],
                          "bands": {k: {"n_true": b["n_true"], "recall": b["recall"], "false_cones": b["false_cones"],
                                        "false_per_frame": b["false_per_frame"]} for k, b in r["extra_groups"].items()}}
        if self.tracked.frames:
            out["tracked"] = self.tracked.summary()
            if "raw" in out:
                t = out["tracked"]["groups"].get("far 7-15 m", {}).get("median_err_m", float("nan"))
                out["tracked"]["err_7_15_ratio_to_raw"] = t / out["raw"]["median_err_7_15_m"]
        return out


def format_drive_evaluation(s: dict) -> str:
    """Plain-text lines of :meth:`DriveEvaluation.summary` (raw line, then the tracked lines)."""
    rows = []
    if "raw" in s:
        r = s["raw"]
        rows.append(f"/cones within {r['range_m']:g} m: recall {r['recall']:.3f}, false cones {r['false_per_frame']:.2f}/frame, "
                    f"median error 0-7 m {r['median_err_0_7_m']:.3f}, 7-15 m {r['median_err_7_15_m']:.3f}")
        if r.get("bands"):
            rows.append(f"  by range (to {BANDS_MAX_M:g} m, cones >= {GT_MIN_VISIBLE:g} visible): " + ", ".join(
                f"{name} recall {b['recall']:.3f} (n {b['n_true']}) false {b['false_per_frame']:.2f}/frame"
                for name, b in r["bands"].items()))
    if "tracked" in s:
        rows.append(format_tracking(s["tracked"]))
        if "err_7_15_ratio_to_raw" in s["tracked"]:
            rows.append(f"  median error 7-15 m tracked / raw: {s['tracked']['err_7_15_ratio_to_raw']:.2f}")
    return "\n".join(rows)


def evaluate_tracking_bag(bag: str | os.PathLike, truth: DriveTruth, cones_topic: str = "/cones",
                          tracked_topic: str = "/cones/tracked", range_m: float = EVAL_RANGE_M) -> dict:
    """:meth:`DriveEvaluation.summary` of a bag with ``/cones`` and ``/cones/tracked`` (e.g. the ``--out`` of
    ``replay --track``), messages taken by header stamp. No ego-motion figures (the bag has no estimate)."""
    from ..data import bagio
    from ..records import CONE_DTYPE, TRACKED_CONE_DTYPE, from_pointcloud2

    topics = bagio.bag_topics(bag)
    ev = DriveEvaluation(truth, range_m)
    n = {cones_topic: 0, tracked_topic: 0}
    for topic, dtype, add in ((cones_topic, CONE_DTYPE, ev.add_raw), (tracked_topic, TRACKED_CONE_DTYPE, ev.add_tracked)):
        if topic not in topics:
            continue
        for m in bagio.read_messages(bag, topic):
            add(bagio.stamp_ns(m.msg.header), from_pointcloud2(m.msg, dtype))
            n[topic] += 1
    if not any(n.values()):
        raise ConfigError(str(bag), None, f"has no {cones_topic} or {tracked_topic} messages (a replay --track --out bag?)")
    out = ev.summary()
    if not out:
        raise ConfigError(str(bag), None, "no frame of the bag is in the drive's ground truth (another drive's gt.jsonl?)")
    out["messages"] = n
    return out


def write_tracking_report(summary: dict, out_dir: str | os.PathLike, bag: str, gt: str) -> dict[str, Path]:
    """``report.md`` (the table of :func:`format_drive_evaluation`) and ``metrics.json`` in ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {"metrics": out / "metrics.json", "report": out / "report.md"}
    files["metrics"].write_text(json.dumps({"bag": bag, "gt": gt, **summary}, indent=1), encoding="utf-8")
    files["report"].write_text(f"# Tracking: {bag}\n\nGround truth: `{gt}`. Definitions: `cone_perception/evaluation/tracking.py`.\n\n"
                               f"```\n{format_drive_evaluation(summary)}\n```\n", encoding="utf-8")
    return files


def simulated_drive(n_frames: int, fov, rows_m: tuple[float, ...] = (1.75, -1.75, 5.0, -5.0, 8.5, -8.5),
                    spacing_m: float = 2.0, step_m: float = 0.4, yaw_step_rad: float = 0.0, sigma_m: float = 0.05,
                    drop: float = 0.1, seed: int = 0):
    """Frames of cones seen from a car driving straight through rows of cones (benchmarks, tests).

    Yields ``(true Motion2D from the last frame, CONE_DTYPE records of the cones inside ``fov``
    (a :class:`~cone_perception.tracking.FieldOfView`), each kept with probability 1 - ``drop`` and
    moved by ``sigma_m`` noise)``. Classes alternate blue / yellow by row.
    """
    from ..records import CONE_DTYPE

    rng = np.random.default_rng(seed)
    length = n_frames * step_m + 60.0
    xs = np.arange(-5.0, length, spacing_m)
    world = np.array([(x, y) for y in rows_m for x in xs])
    cls = np.array([k % 2 for k, _ in enumerate(rows_m) for _ in xs])
    pose = np.zeros(3)
    for k in range(n_frames):
        m = Motion2D(step_m, 0.0, yaw_step_rad) if k else Motion2D()
        c, s = np.cos(pose[2]), np.sin(pose[2])
        pose = np.array([pose[0] + c * m.dx - s * m.dy, pose[1] + s * m.dx + c * m.dy, pose[2] + m.dyaw])
        c, s = np.cos(pose[2]), np.sin(pose[2])
        d = world - pose[:2]
        local = np.c_[c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]]
        near = (local[:, 0] > 0) & (local[:, 0] < 40)
        idx = np.flatnonzero(near)[fov.visible(local[near])]
        idx = idx[rng.random(len(idx)) >= drop]
        out = np.zeros(len(idx), CONE_DTYPE)
        out["x"] = local[idx, 0] + rng.normal(0, sigma_m, len(idx))
        out["y"] = local[idx, 1] + rng.normal(0, sigma_m, len(idx))
        out["class_id"], out["score"] = cls[idx], 0.8
        out["cov_xx"] = out["cov_yy"] = sigma_m**2
        yield m, out
