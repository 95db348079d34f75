"""Formula Student driverless tracks: autocross-like, skidpad, acceleration.

All positions are metres in the flat track ("world") frame W: x, y on the
ground, z up. Rules followed (FS driverless handbook): blue cones on the left,
yellow on the right, track width 3-5 m, at most 5 m between consecutive cones
of one boundary, turns no tighter than 9 m diameter at the inner boundary,
straights up to 80 m, large orange cones at start / finish (timekeeping)
lines. Every track is reproducible from its seed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..classes import BLUE, LARGE_ORANGE, ORANGE, YELLOW

TRACK_KINDS = ("autocross", "skidpad", "acceleration")
STEP_M = 0.25  # centre-line sampling
MIN_INNER_RADIUS_M = 4.5  # 9 m turn diameter at the inner boundary
MAX_CONE_GAP_M = 5.0
MAX_STRAIGHT_M = 80.0


@dataclass
class Track:
    """A set of cones and the line the car drives.

    ``cones_xy_m``: (N, 2) float64 cone centres on the ground (m, W).
    ``cone_class``: (N,) int project class ids.
    ``centerline_m``: (M, 2) float64 driving line sampled every :data:`STEP_M` m.
    ``boundaries``: ordered (K, 2) cone positions of each boundary (for rule checks), all cones kept.
    ``straights_m``: lengths of the straight segments used.
    """

    kind: str
    seed: int
    width_m: float
    cones_xy_m: np.ndarray
    cone_class: np.ndarray
    centerline_m: np.ndarray
    boundaries: list[np.ndarray] = field(default_factory=list)
    straights_m: list[float] = field(default_factory=list)
    cone_fallen: np.ndarray | None = None  # (N,) bool: knocked over, lying on its side (None = all upright)

    def fallen(self, i: int) -> bool:
        return bool(self.cone_fallen is not None and self.cone_fallen[i])

    @property
    def length_m(self) -> float:
        return float(np.sum(np.hypot(*np.diff(self.centerline_m, axis=0).T)))

    def pose_at(self, s_m: float, interpolate: bool = False) -> tuple[float, float, float]:
        """Position (m) and heading (rad) of the driving line at arc length ``s_m`` (clamped).

        By default the nearest sample (every :data:`STEP_M`); ``interpolate`` blends the two samples
        around ``s_m`` (a drive then moves smoothly, not in 0.25 m steps)."""
        c = self.centerline_m
        if interpolate:
            f = float(np.clip(s_m / STEP_M, 0, len(c) - 1))
            i0 = min(int(np.floor(f)), len(c) - 2) if len(c) > 1 else 0
            a = f - i0
            x0, y0, h0 = self.pose_at(i0 * STEP_M)
            if a <= 0 or len(c) < 2:
                return x0, y0, h0
            x1, y1, h1 = self.pose_at((i0 + 1) * STEP_M)
            dh = (h1 - h0 + np.pi) % (2 * np.pi) - np.pi
            return x0 + a * (x1 - x0), y0 + a * (y1 - y0), float(h0 + a * dh)
        i = int(np.clip(round(s_m / STEP_M), 0, len(c) - 1))
        j0, j1 = max(i - 4, 0), min(i + 4, len(c) - 1)  # heading over +-1 m
        d = c[j1] - c[j0]
        return float(c[i, 0]), float(c[i, 1]), float(np.arctan2(d[1], d[0]))


class _Path:
    """Centre line built from straights and arcs (turtle style)."""

    def __init__(self, x: float = 0.0, y: float = 0.0, heading: float = 0.0):
        self.pts = [np.array([x, y])]
        self.curv = [0.0]
        self.heading = heading

    def _points(self, length: float, k: float) -> tuple[np.ndarray, float]:
        n = max(int(round(length / STEP_M)), 1)
        s = np.arange(1, n + 1) * (length / n)
        p0, h = self.pts[-1], self.heading
        if abs(k) < 1e-9:
            pts = p0 + np.outer(s, [np.cos(h), np.sin(h)])
            return pts, h
        hs = h + k * s
        pts = p0 + np.column_stack([(np.sin(hs) - np.sin(h)) / k, -(np.cos(hs) - np.cos(h)) / k])
        return pts, h + k * length

    def candidate(self, length: float, k: float) -> tuple[np.ndarray, float]:
        return self._points(length, k)

    def append(self, pts: np.ndarray, heading: float, k: float) -> None:
        self.pts.extend(pts)
        self.curv.extend([k] * len(pts))
        self.heading = heading

    def straight_run_m(self) -> float:
        """Length of the straight the line currently ends in (0 in a turn)."""
        c = np.array(self.curv[1:])
        nz = np.flatnonzero(c != 0.0)
        return STEP_M * (len(c) - (nz[-1] + 1 if len(nz) else 0))

    def array(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array(self.pts), np.array(self.curv)

    def straights_m(self) -> list[float]:
        """Lengths of the maximal straight runs (m)."""
        out, run = [], 0
        for k in self.curv[1:]:
            if k == 0.0:
                run += 1
            elif run:
                out.append(run * STEP_M)
                run = 0
        return out + ([run * STEP_M] if run else [])


def _place_boundary(edge: np.ndarray, curv: np.ndarray, fixed_idx: list[int], rng: np.random.Generator) -> np.ndarray:
    """Indices into ``edge`` where cones stand: spacing 2-4.5 m by curvature, never above 5 m, fixed indices kept."""
    seg = np.hypot(*np.diff(edge, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    fixed = sorted(set(fixed_idx))
    out, i = [0], 0
    while True:
        k = abs(curv[i])
        spacing = float(np.clip(4.5 - 11.0 * k, 2.0, 4.5) * rng.uniform(0.9, 1.05))
        target = s[i] + min(spacing, MAX_CONE_GAP_M - 0.05)
        nxt_fixed = [f for f in fixed if f > i and s[f] <= target + 1e-9]
        if nxt_fixed:
            j = nxt_fixed[0]
        elif s[-1] <= target:  # last cone at the end of the line
            j = len(s) - 1
        else:
            j = max(int(np.searchsorted(s, target, side="right") - 1), i + 1)
        if j >= len(s) - 1:
            out.append(len(s) - 1)
            break
        out.append(j)
        i = j
    return np.array(sorted(set(out)))


def _boundaries(
    center: np.ndarray, curv: np.ndarray, width_m: float, lines_s: list[float], rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Blue left / yellow right cones along a centre line; large orange pairs at the given line stations (m)."""
    d = np.gradient(center, axis=0)
    t = d / np.linalg.norm(d, axis=1, keepdims=True)
    n = np.column_stack([-t[:, 1], t[:, 0]])  # left normal
    half = width_m / 2.0
    xy, cls, bounds = [], [], []
    for side, colour in ((+1.0, BLUE), (-1.0, YELLOW)):
        edge = center + side * half * n
        k_edge = curv / (1.0 - side * curv * half)
        fixed, orange = [], set()
        for s_line in lines_s:
            for ds in (-0.4, 0.4):
                j = int(np.clip(round((s_line + ds) / STEP_M), 0, len(center) - 1))
                fixed.append(j)
                orange.add(j)
        idx = _place_boundary(edge, k_edge, fixed, rng)
        bounds.append(edge[idx])
        xy.append(edge[idx])
        cls.append(np.array([LARGE_ORANGE if j in orange else colour for j in idx]))
    return np.concatenate(xy), np.concatenate(cls), bounds


def _too_close(new: np.ndarray, old: np.ndarray, min_gap: float) -> bool:
    if len(old) == 0:
        return False
    sub = old[:: 4]
    d2 = ((new[::4, None, :] - sub[None, :, :]) ** 2).sum(-1)
    return bool(d2.min() < min_gap**2)


def autocross(seed: int, width_m: float | None = None, length_m: float | None = None, attempt: int = 0) -> Track:
    """Random open autocross track: straights, turns, hairpins, chicanes, slaloms; start and finish lines."""
    rng = np.random.default_rng([seed, attempt]) if attempt else np.random.default_rng(seed)
    w = float(rng.uniform(3.0, 5.0) if width_m is None else width_m)
    target = float(rng.uniform(250.0, 450.0) if length_m is None else length_m)
    r_min = MIN_INNER_RADIUS_M + w / 2.0
    path = _Path()
    pts, h = path.candidate(25.0, 0.0)
    path.append(pts, h, 0.0)
    clearance = w + 4.0
    length = 25.0
    while length < target:
        kind = rng.choice(["straight", "turn", "hairpin", "chicane", "slalom"], p=[0.25, 0.37, 0.12, 0.14, 0.12])
        sign = rng.choice([-1.0, 1.0])
        if kind == "straight":
            pieces = [(float(rng.uniform(10.0, MAX_STRAIGHT_M)), 0.0)]
        elif kind == "turn":
            r = rng.uniform(r_min, 25.0)
            pieces = [(r * np.radians(rng.uniform(30, 120)), sign / r)]
        elif kind == "hairpin":
            r = rng.uniform(r_min, r_min + 2.0)
            pieces = [(8.0, 0.0), (r * np.pi, sign / r), (8.0, 0.0)]
        elif kind == "chicane":
            r = rng.uniform(max(r_min, 8.0), 15.0)
            a = np.radians(rng.uniform(30, 50))
            pieces = [(r * a, sign / r), (2 * r * a, -sign / r), (r * a, sign / r)]
        else:  # slalom
            r = rng.uniform(max(r_min, 8.0), 12.0)
            a = np.radians(rng.uniform(35, 55))
            m = int(rng.integers(3, 6))
            pieces = [(r * a, sign / r)] + [(2 * r * a, (-1) ** (i + 1) * sign / r) for i in range(m)]
            pieces.append((r * a, (-1) ** (m + 1) * sign / r))
        run = path.straight_run_m()
        if pieces[0][1] == 0.0 and run + pieces[0][0] > MAX_STRAIGHT_M:
            continue
        if pieces[-1][1] == 0.0 and pieces[-1][0] > MAX_STRAIGHT_M - 20.0:
            continue  # leave room for the finish straight
        trial = _Path()
        trial.pts, trial.heading = [path.pts[-1]], path.heading
        new_pts = []
        for L, k in pieces:
            p, hh = trial.candidate(L, k)
            trial.append(p, hh, k)
            new_pts.append(p)
        new = np.concatenate(new_pts)
        old = np.array(path.pts[: max(len(path.pts) - int(3 * clearance / STEP_M), 0)])
        if _too_close(new, old, clearance):
            if rng.random() < 0.05:
                break  # boxed in: finish here
            continue
        for L, k in pieces:
            p, hh = path.candidate(L, k)
            path.append(p, hh, k)
        length += sum(L for L, _ in pieces)
    fin = max(min(20.0, MAX_STRAIGHT_M - path.straight_run_m()), 0.0)
    p, h = path.candidate(max(fin, STEP_M), 0.0)  # finish straight
    old = np.array(path.pts[: max(len(path.pts) - int(3 * clearance / STEP_M), 0)])
    if _too_close(p, old, clearance) and attempt < 20:
        return autocross(seed, width_m, length_m, attempt + 1)
    path.append(p, h, 0.0)
    center, curv = path.array()
    total = float(np.sum(np.hypot(*np.diff(center, axis=0).T)))
    xy, cls, bounds = _boundaries(center, curv, w, [10.0, total - 10.0], rng)
    return Track("autocross", seed, w, xy, cls, center, bounds, path.straights_m())


def acceleration(seed: int, width_m: float | None = None) -> Track:
    """75 m acceleration straight from a start line, then 100 m braking zone with small orange cones."""
    rng = np.random.default_rng(seed)
    w = float(rng.uniform(3.0, 5.0) if width_m is None else width_m)
    path = _Path(x=-10.0)
    p, h = path.candidate(75.0 + 10.0, 0.0)
    path.append(p, h, 0.0)
    p, h = path.candidate(100.0, 0.0)
    path.append(p, h, 0.0)
    center, curv = path.array()
    xy, cls, bounds = _boundaries(center, curv, w, [10.0, 85.0], rng)
    cls = np.where((xy[:, 0] > 76.0) & (cls != LARGE_ORANGE), ORANGE, cls)
    return Track("acceleration", seed, w, xy, cls, center, bounds, path.straights_m())


def skidpad(seed: int) -> Track:
    """FS skidpad: circles of 15.25 m (inner) / 21.25 m (outer) diameter, centres 18.25 m apart.

    Entry along +x through the crossing at the origin, two laps on the right
    circle (clockwise), two on the left (counter-clockwise), exit along +x.
    Right circle: inner yellow, outer blue; left circle: inner blue, outer
    yellow; entry / exit lanes orange; four large orange cones at the timekeeping line.
    """
    rng = np.random.default_rng(seed)
    rc, ri, ro = 9.125, 7.625, 10.625
    xy, cls = [], []
    for cy, inner_cls, outer_cls in ((-rc, YELLOW, BLUE), (rc, BLUE, YELLOW)):
        a = np.arange(16) * 2 * np.pi / 16
        pts = np.column_stack([ri * np.cos(a), cy + ri * np.sin(a)])
        keep = np.hypot(pts[:, 0], pts[:, 1]) > 1.6  # the timekeeping cones stand there
        xy.append(pts[keep])
        cls.append(np.full(keep.sum(), inner_cls))
        a = np.arange(16) * 2 * np.pi / 16 + np.pi / 16
        pts = np.column_stack([ro * np.cos(a), cy + ro * np.sin(a)])
        keep = np.abs(pts[:, 1]) > 3.0  # open where the circles cross
        xy.append(pts[keep])
        cls.append(np.full(keep.sum(), outer_cls))
    lane = np.arange(-15.0, -5.0, 3.0)
    for sx in (lane, -lane[::-1]):
        for y in (-1.5, 1.5):
            xy.append(np.column_stack([sx, np.full(len(sx), y)]))
            cls.append(np.full(len(sx), ORANGE))
    xy.append(np.array([[-0.3, -1.5], [0.3, -1.5], [-0.3, 1.5], [0.3, 1.5]]))
    cls.append(np.full(4, LARGE_ORANGE))
    path = _Path(x=-20.0)
    p, h = path.candidate(20.0, 0.0)
    path.append(p, h, 0.0)
    for k in (-1.0 / rc, 1.0 / rc):
        p, h = path.candidate(2 * 2 * np.pi * rc, k)
        path.append(p, h, k)
    p, h = path.candidate(20.0, 0.0)
    path.append(p, h, 0.0)
    center, _ = path.array()
    return Track("skidpad", seed, 3.0, np.concatenate(xy), np.concatenate(cls), center, [], path.straights_m())


def make_track(kind: str, seed: int, missing_frac: float = 0.0, stray: int = 0, knocked_frac: float = 0.0) -> Track:
    """A track of ``kind`` (:data:`TRACK_KINDS`), optionally with missing, stray (off-track) and knocked-over cones."""
    if kind == "autocross":
        tr = autocross(seed)
    elif kind == "acceleration":
        tr = acceleration(seed)
    elif kind == "skidpad":
        tr = skidpad(seed)
    else:
        raise ValueError(f"track kind must be one of {TRACK_KINDS}, got {kind!r}")
    rng = np.random.default_rng([seed, 7])
    if missing_frac > 0:
        keep = (rng.random(len(tr.cone_class)) >= missing_frac) | (tr.cone_class == LARGE_ORANGE)
        tr.cones_xy_m, tr.cone_class = tr.cones_xy_m[keep], tr.cone_class[keep]
    if stray > 0:
        lo, hi = tr.centerline_m.min(0) - 10, tr.centerline_m.max(0) + 10
        cand = rng.uniform(lo, hi, size=(stray * 20, 2))
        d = np.min(np.hypot(*(cand[:, None, :] - tr.centerline_m[None, ::8, :]).transpose(2, 0, 1)), axis=1)
        cand = cand[d > tr.width_m / 2 + 2.0][:stray]
        tr.cones_xy_m = np.concatenate([tr.cones_xy_m, cand])
        tr.cone_class = np.concatenate([tr.cone_class, rng.choice([BLUE, YELLOW, ORANGE], len(cand))])
    if knocked_frac > 0:
        tr.cone_fallen = rng.random(len(tr.cone_class)) < knocked_frac
    return tr
