"""Localisation quality of cones in metres: matching to ground truth, recall and error by distance.

Used by ``replay --gt-topic``, ``make demo``, the CI accuracy bounds and ``eval``. ROS-free.

Matching (per frame): predicted and true cones are paired greedily by ground distance, nearest
first, each at most once, and only within a gate that widens with range
(``gate_m = gate_base_m + gate_frac * range``), since a homography's error grows with range.
Pairs are class-agnostic; the class agreement of pairs is reported separately.

The thesis's own metric (ch. 4.4, 5.4) is the error of the distance between a blue and a yellow
cone across the track: :class:`PairDistanceReport` pairs each true blue cone with the nearest true
yellow one and compares the distance of their matched predictions with the true distance.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Distance groups (m from the rear axle): the thesis's three plus one beyond 15 m.
DISTANCE_GROUPS: tuple[tuple[str, float, float], ...] = (
    ("near 0-4 m", 0.0, 4.0),
    ("mid 4-7 m", 4.0, 7.0),
    ("far 7-15 m", 7.0, 15.0),
    ("very far >15 m", 15.0, np.inf),
)

#: Range bands reported beside the groups, out to 40 m (issue 26's look-ahead table; bands may overlap the
#: groups). They ignore ``max_range_m``: a true cone beyond the calibration's range is a miss in its band
#: (the car does not get it), so a capped range shows as low recall, not as a smaller table.
EXTRA_GROUPS: tuple[tuple[str, float, float], ...] = (
    ("0-7 m", 0.0, 7.0), ("7-15 m", 7.0, 15.0), ("15-25 m", 15.0, 25.0), ("25-40 m", 25.0, 40.0),
)
#: The farthest band edge (m): true cones up to here are matched even beyond ``max_range_m``.
BANDS_MAX_M = max(hi for _, _, hi in EXTRA_GROUPS)
#: ``replay --gt-topic``: the bands count true cones at least this visible (``/cones_gt`` score; issue 26's
#: "cones at least half visible").
GT_MIN_VISIBLE = 0.5


def distance_group(range_m: np.ndarray) -> np.ndarray:
    """(N,) ranges in m -> (N,) group index into :data:`DISTANCE_GROUPS`."""
    r = np.asarray(range_m, dtype=np.float64)
    edges = np.array([g[2] for g in DISTANCE_GROUPS[:-1]])
    return np.searchsorted(edges, r, side="right")


def match_cones(
    pred_xy: np.ndarray, true_xy: np.ndarray, gate_base_m: float = 0.5, gate_frac: float = 0.1
) -> list[tuple[int, int, float]]:
    """Greedy nearest-first pairs ``(pred_index, true_index, distance_m)`` within the range gate."""
    p = np.asarray(pred_xy, dtype=np.float64).reshape(-1, 2)
    t = np.asarray(true_xy, dtype=np.float64).reshape(-1, 2)
    if p.shape[0] == 0 or t.shape[0] == 0:
        return []
    d = np.linalg.norm(p[:, None, :] - t[None, :, :], axis=2)
    gate = gate_base_m + gate_frac * np.hypot(t[:, 0], t[:, 1])
    ok = d <= gate[None, :]
    order = np.argsort(d, axis=None)
    used_p, used_t, pairs = set(), set(), []
    for flat in order:
        i, j = divmod(int(flat), t.shape[0])
        if not ok[i, j]:
            continue
        if i in used_p or j in used_t:
            continue
        used_p.add(i)
        used_t.add(j)
        pairs.append((i, j, float(d[i, j])))
    return pairs


@dataclass
class LocalisationReport:
    """Accumulates matches over frames; :meth:`summary` gives the per-group table.

    ``max_range_m`` cuts the groups (true cones and detections beyond it are not counted there).
    The bands (:data:`EXTRA_GROUPS`) go to :data:`BANDS_MAX_M` whatever ``max_range_m``; in them only
    true cones whose visible fraction (the truth's ``score``, as ``/cones_gt`` of a synthetic bag holds
    it) is at least ``min_visible`` count for recall; a detection on a less visible cone is matched
    (not false) but the cone is no miss. False cones per band: unmatched detections by their own range.
    """

    max_range_m: float = np.inf
    min_visible: float = 0.0
    true_range: list = field(default_factory=list)  # per true cone (within max(max_range_m, BANDS_MAX_M))
    true_matched: list = field(default_factory=list)
    true_visible: list = field(default_factory=list)
    err_x: list = field(default_factory=list)  # per matched pair
    err_y: list = field(default_factory=list)
    err_range: list = field(default_factory=list)
    same_class: list = field(default_factory=list)
    false_range: list = field(default_factory=list)  # per unmatched detection: its own range (m)
    false_positives: int = 0
    frames: int = 0

    def add_frame(self, pred: np.ndarray, truth: np.ndarray) -> list[tuple[int, int, float]]:
        """``pred``/``truth``: record arrays with ``x``, ``y``, ``class_id`` (``CONE_DTYPE``).

        Returns the frame's pairs ``(pred_index, truth_index, distance_m)``, indices into the given arrays.
        """
        self.frames += 1
        t_xy = np.c_[truth["x"], truth["y"]].astype(np.float64)
        t_r = np.hypot(t_xy[:, 0], t_xy[:, 1])
        p_xy = np.c_[pred["x"], pred["y"]].astype(np.float64)
        # matched against every true cone, so that a detection of a cone beyond the counted range is no false cone
        pairs = match_cones(p_xy, t_xy)
        keep = t_r <= max(self.max_range_m, BANDS_MAX_M)  # the true cones counted (groups and bands)
        matched = np.zeros(len(truth), dtype=bool)
        for i, j, _ in pairs:
            matched[j] = True
            if not keep[j]:
                continue
            self.err_x.append(p_xy[i, 0] - t_xy[j, 0])
            self.err_y.append(p_xy[i, 1] - t_xy[j, 1])
            self.err_range.append(t_r[j])
            self.same_class.append(int(pred["class_id"][i]) == int(truth["class_id"][j]))
        self.true_range.extend(t_r[keep].tolist())
        self.true_matched.extend(matched[keep].tolist())
        self.true_visible.extend(np.asarray(truth["score"][keep], np.float64).tolist() if self.min_visible > 0
                                 else [1.0] * int(keep.sum()))
        # unmatched detections beyond the range are of cones outside it (ignored like those), not false
        unmatched = np.ones(len(pred), dtype=bool)
        unmatched[[i for i, _, _ in pairs]] = False
        p_r = np.hypot(p_xy[:, 0], p_xy[:, 1])
        self.false_positives += int(np.count_nonzero(unmatched & (p_r <= self.max_range_m)))
        self.false_range.extend(p_r[unmatched].tolist())
        return pairs

    def summary(self) -> dict:
        """Per distance group and overall: n_true, recall, n_matched, median / p90 error (m), class accuracy;
        per band (``extra_groups``) also false cones (count and per frame)."""
        tr, tm = np.asarray(self.true_range), np.asarray(self.true_matched, dtype=bool)
        ex, ey, er = np.asarray(self.err_x), np.asarray(self.err_y), np.asarray(self.err_range)
        e = np.hypot(ex, ey)
        sc = np.asarray(self.same_class, dtype=bool)
        tin, ein = tr <= self.max_range_m, er <= self.max_range_m  # the groups keep the calibration's range cut
        groups = {}
        tg, mg = distance_group(tr), distance_group(er)
        for k, (name, _, _) in enumerate(DISTANCE_GROUPS):
            t, m = tin & (tg == k), ein & (mg == k)
            groups[name] = _stats(tm[t], e[m], ex[m], ey[m], sc[m])
        extra = {}
        vis = np.asarray(self.true_visible, np.float64) >= self.min_visible
        fr = np.asarray(self.false_range, np.float64)
        for name, lo, hi in EXTRA_GROUPS:
            t_in, m_in = (tr >= lo) & (tr < hi) & vis, (er >= lo) & (er < hi)
            n_false = int(np.count_nonzero((fr >= lo) & (fr < hi)))
            extra[name] = {**_stats(tm[t_in], e[m_in], ex[m_in], ey[m_in], sc[m_in]), "false_cones": n_false,
                           "false_per_frame": n_false / self.frames if self.frames else float("nan")}
        n_false = int(np.count_nonzero(fr < BANDS_MAX_M))
        return {
            "frames": self.frames,
            "false_positives": self.false_positives,
            "groups": groups,
            "extra_groups": extra,
            "bands": {"min_visible": self.min_visible, "max_m": BANDS_MAX_M, "false_cones": n_false,
                      "false_per_frame": n_false / self.frames if self.frames else float("nan")},
            "all": _stats(tm[tin], e[ein], ex[ein], ey[ein], sc[ein]),
        }


def _stats(matched: np.ndarray, e: np.ndarray, ex: np.ndarray, ey: np.ndarray, same: np.ndarray) -> dict:
    n = int(matched.size)
    out = {"n_true": n, "recall": float(matched.mean()) if n else float("nan"), "n_matched": int(e.size)}
    if e.size:
        out.update(
            median_err_m=float(np.median(e)),
            p90_err_m=float(np.percentile(e, 90)),
            median_abs_err_x_m=float(np.median(np.abs(ex))),
            median_abs_err_y_m=float(np.median(np.abs(ey))),
            class_accuracy=float(same.mean()),
        )
    else:
        out.update(median_err_m=float("nan"), p90_err_m=float("nan"), median_abs_err_x_m=float("nan"),
                   median_abs_err_y_m=float("nan"), class_accuracy=float("nan"))
    return out


def format_localisation(summary: dict) -> str:
    """Plain-text table of :meth:`LocalisationReport.summary`."""
    rows = [f"{'group':<16}{'true':>7}{'recall':>8}{'matched':>9}{'med err':>9}{'p90 err':>9}{'|dx|':>7}{'|dy|':>7}{'class':>7}"]
    items = list(summary["groups"].items()) + [("all", summary["all"])]
    for name, s in items:
        rows.append(
            f"{name:<16}{s['n_true']:>7}{s['recall']:>8.3f}{s['n_matched']:>9}{s['median_err_m']:>9.3f}"
            f"{s['p90_err_m']:>9.3f}{s['median_abs_err_x_m']:>7.3f}{s['median_abs_err_y_m']:>7.3f}{s['class_accuracy']:>7.3f}"
        )
    rows.append(f"frames {summary['frames']}, unmatched predictions (false positives) {summary['false_positives']}; errors in m")
    if "bands" in summary:
        b = summary["bands"]
        rows.append(f"{'band':<16}{'true':>7}{'recall':>8}{'matched':>9}{'med err':>9}{'false':>7}{'/frame':>8}"
                    f"   (to {b['max_m']:g} m whatever the range cut; true cones >= {b['min_visible']:g} visible)")
        for name, s in summary["extra_groups"].items():
            rows.append(f"{name:<16}{s['n_true']:>7}{s['recall']:>8.3f}{s['n_matched']:>9}{s['median_err_m']:>9.3f}"
                        f"{s['false_cones']:>7}{s['false_per_frame']:>8.2f}")
        rows.append(f"false cones within {b['max_m']:g} m: {b['false_cones']} ({b['false_per_frame']:.2f} per frame)")
    return "\n".join(rows)


#: Blue-yellow pairs farther apart than this are not across the track (FS track width >= 3 m).
MAX_PAIR_M = 6.0


def blue_yellow_pairs(truth: np.ndarray, max_pair_m: float = MAX_PAIR_M) -> list[tuple[int, int, float]]:
    """Each blue cone with its nearest yellow cone: ``(blue_index, yellow_index, distance_m)``, within ``max_pair_m``."""
    from ..classes import BLUE, YELLOW

    xy = np.c_[truth["x"], truth["y"]].astype(np.float64)
    blue, yellow = np.flatnonzero(truth["class_id"] == BLUE), np.flatnonzero(truth["class_id"] == YELLOW)
    if blue.size == 0 or yellow.size == 0:
        return []
    d = np.linalg.norm(xy[blue, None, :] - xy[None, yellow, :], axis=2)
    j = np.argmin(d, axis=1)
    dmin = d[np.arange(blue.size), j]
    return [(int(b), int(yellow[jj]), float(dd)) for b, jj, dd in zip(blue, j, dmin) if dd <= max_pair_m]


@dataclass
class PairDistanceReport:
    """The thesis metric: measured minus true distance of blue-yellow pairs, by the pair's distance group.

    A pair is grouped by the range of its midpoint; it is measured when both cones are matched.
    """

    max_pair_m: float = MAX_PAIR_M
    pair_range: list = field(default_factory=list)  # per true pair (m)
    pair_measured: list = field(default_factory=list)
    true_dist: list = field(default_factory=list)  # per measured pair (m)
    err: list = field(default_factory=list)  # measured - true (m)
    err_range: list = field(default_factory=list)

    def add_frame(self, pred: np.ndarray, truth: np.ndarray, matches: list[tuple[int, int, float]]) -> None:
        """``matches``: ``(pred_index, truth_index, _)`` as returned by :meth:`LocalisationReport.add_frame`."""
        by_truth = {j: i for i, j, _ in matches}
        for b, y, d_true in blue_yellow_pairs(truth, self.max_pair_m):
            r = float(np.hypot((truth["x"][b] + truth["x"][y]) / 2.0, (truth["y"][b] + truth["y"][y]) / 2.0))
            ok = b in by_truth and y in by_truth
            self.pair_range.append(r)
            self.pair_measured.append(ok)
            if ok:
                pb, py = by_truth[b], by_truth[y]
                d_pred = float(np.hypot(pred["x"][pb] - pred["x"][py], pred["y"][pb] - pred["y"][py]))
                self.true_dist.append(d_true)
                self.err.append(d_pred - d_true)
                self.err_range.append(r)

    def summary(self) -> dict:
        """Per distance group and overall: pairs, measured, median error, median / p90 absolute error (m)."""
        pr, pm = np.asarray(self.pair_range), np.asarray(self.pair_measured, dtype=bool)
        e, er = np.asarray(self.err), np.asarray(self.err_range)
        pg, eg = distance_group(pr), distance_group(er)
        groups = {name: _pair_stats(pm[pg == k], e[eg == k]) for k, (name, _, _) in enumerate(DISTANCE_GROUPS)}
        return {"max_pair_m": self.max_pair_m, "groups": groups, "all": _pair_stats(pm, e)}


def _pair_stats(measured: np.ndarray, e: np.ndarray) -> dict:
    out = {"n_pairs": int(measured.size), "n_measured": int(e.size)}
    nan = float("nan")
    out.update(
        median_err_m=float(np.median(e)) if e.size else nan,
        median_abs_err_m=float(np.median(np.abs(e))) if e.size else nan,
        mean_abs_err_m=float(np.mean(np.abs(e))) if e.size else nan,
        p90_abs_err_m=float(np.percentile(np.abs(e), 90)) if e.size else nan,
    )
    return out
