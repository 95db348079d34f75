"""A local map of static cones in ``rear_axle``: tracks that survive missed frames, with ids. ROS-free.

Per frame (:meth:`ConeTracker.update`): the tracks are moved by the car's motion since the last
frame (odometry when given, else a registration of the frame's cones against the tracks with a
constant-velocity prior, see :mod:`cone_perception.geometry.motion`), associated with the frame's cones
by gated Mahalanobis distance and one-to-one assignment (``scipy.optimize.linear_sum_assignment``),
and updated by a Kalman filter with each cone's own covariance (its attitude part, when the frame's
attitude is given, as one error common to the frame: :meth:`ConeTracker.update`). Per track: id (uint32, never
reused), fused class probabilities, position + covariance, hits, misses, age, and a certainty that
rises with each confident hit (Bayes odds of the detection score) and decays only while the cone should be visible (inside the band's ground
footprint, :class:`FieldOfView`) and is not seen. Tracks are deleted below
:attr:`TrackerConfig.delete_below` or more than :attr:`TrackerConfig.behind_m` behind the axle.

Bad input: a stamp not after the last fused one raises ``FrameError`` (``stamp_backwards`` /
``stamp_repeated``: not fused, tracks kept); a gap above :attr:`TrackerConfig.max_gap_s` predicts
the tracks with inflated covariance and certainty lowered by the gap, and registers without the
constant-velocity prior; a failed registration predicts from the last motion. Each case is counted
in :attr:`ConeTracker.events`.

Arrays are held per field (struct of arrays), so one frame costs a fixed number of numpy calls.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from ..classes import NUM_CLASSES, UNKNOWN
from ..errors import FrameError
from ..geometry.linalg import inv2
from ..geometry.motion import Motion2D, from_twist, register_cones
from ..records import CONE_DTYPE, TRACKED_CONE_DTYPE
from .view import FieldOfView

_BIG = 1e9
#: :attr:`ConeTracker.events` that mean bad or missing input (a node's health WARNs when one grows);
#: ``merged`` (duplicate tracks joined) is normal work. Frames not fused for their stamp
#: (``stamp_backwards`` / ``stamp_repeated``) are counted by the nodes as dropped frames as well.
INPUT_EVENTS = ("stamp_backwards", "stamp_repeated", "gap", "odom_stale", "twist_nan", "twist_stamp",
                "registration_failed", "bad_cone")


@dataclass
class TrackerConfig:
    """Tuning of :class:`ConeTracker` (units in the names)."""

    gate_chi2: float = 13.8  # Mahalanobis^2 gate, 2 dof (99.9 %)
    meas_var_floor_m2: float = 0.05**2  # least variance of a measured position (systematic errors)
    init_var_floor_m2: float = 0.1**2
    process_std_m: float = 0.05  # per frame, position noise of a static cone (forgets old, biased far measurements)
    motion_std_frac: float = 0.02  # ego-motion translation error, fraction of the distance travelled
    motion_std_rad: float = 0.003  # ego-motion yaw error per frame
    class_weight: float = 2.0  # cost of a class mismatch: -class_weight * log p(track has the class)
    certainty_prior: float = 0.3  # before the first detection
    score_neutral: float = 0.45  # a detection with this score leaves the certainty as it is (Bayes odds)
    miss_likelihood_ratio: float = 0.5  # odds *= this per frame visible and not seen
    certainty_max: float = 0.98  # so that a few misses in view can still remove a track
    gap_tau_s: float = 1.0  # certainty *= exp(-gap / tau) over a gap above max_gap_s
    delete_below: float = 0.1
    behind_m: float = 3.0  # delete when x < -behind_m
    # a track out of the field of view and not seen keeps its certainty (nothing says it is gone), but only with at
    # least this many hits: one sighting (a far cone at the image's edge placed by a wrong first attitude) is not
    # kept out of view, where no miss could ever remove it; 0 = every track kept (docs/tracking.md, "Out of view")
    out_of_view_min_hits: int = 2
    min_hits: int = 1  # published from this many hits on (and publish_min_certainty)
    publish_min_certainty: float = 0.5
    max_gap_s: float = 0.5
    class_floor: float = 0.02  # no class probability below this (a wrong first class can recover)
    register: bool = True  # estimate ego-motion from the cones when no odometry is given
    register_min_inliers: int = 3
    prior_std_m: float = 0.02  # constant-velocity prior of the registration: translation per frame
    prior_std_rad: float = 0.005  # and yaw per frame
    search_m: float = 1.5  # registration: a detection's correspondence candidates lie this near its predicted track
    search_gap_m: float = 3.0  # the same after a gap (max_gap_s): the prior motion is less sure
    registration_failed_std_m: float = 0.1  # extra position std of every track when the registration failed
    gap_std_m: float = 0.1  # extra position std of every track after a gap: gap_std_m + gap_std_m_per_s * (dt - max_gap_s)
    gap_std_m_per_s: float = 0.5
    max_range_m: float = float("inf")  # detections farther are not used; inf: the calibration's max_range_m (the field
    # of view's) is the only range, so /cones/tracked reaches as far as /cones (docs/tracking.md, "Far cones")
    spawn_chi2: float = 50.0  # an unassigned detection this near (Mahalanobis^2) to a track starts no new one
    spawn_max_m: float = 2.0  # ... unless it is farther than this (m) from that track: far cones' covariance
    # is metres long along the ray, so the next cone of a row 4-5 m behind would otherwise never get a track;
    # two tracks farther apart than this are not merged either
    merge_chi2: float = 6.0  # two tracks this near (and of one class) are merged into the older one
    # the attitude part of the cones' covariance (given the frame's Attitude) is one error common to the frame,
    # correlated over attitude_tau_s, not independent noise (docs/tracking.md, "Attitude"); False: as before
    attitude_common: bool = True
    attitude_tau_s: float = 0.5  # correlation time of that error; 1 and 2 s were worse on the tuning drives (benchmarks.md)
    register_attitude: bool = True  # the registration estimates that error alongside the motion
    robust_chi2: float = 0.0  # > 0: a matched cone farther than this (Mahalanobis^2) from its track is fused with its
    # covariance times d2 / robust_chi2 (an outlier pulls less); off: no gain on the tuning drives (docs/benchmarks.md)
    # weak detections (docs/tracking.md, "Weak detections"): a detection scored below strong_score (the /cones threshold,
    # score 0..1) is weak. It is not used for the ego-motion registration; on a track it counts as a hit that multiplies
    # the certainty odds by weak_likelihood_ratio (whatever its score: a low score is not evidence against the cone);
    # on no track it starts one (weak_spawn) that is published only once its certainty reaches publish_min_certainty:
    # from certainty_prior 0.3, ratio 1.35 takes 3 weak hits in a row (a miss in view halves the odds).
    strong_score: float = 0.0  # 0: every detection is strong (as before weak detections existed)
    weak_likelihood_ratio: float = 1.35  # odds factor per weak hit (dimensionless, > 1)
    weak_spawn: bool = True  # a weak detection on no track starts a (yet unpublished) track


@dataclass
class FrameInfo:
    """What one :meth:`ConeTracker.update` did."""

    stamp_ns: int
    motion: Motion2D
    motion_source: str  # "odometry", "registration", "prior" (registration failed / off), "none" (first frame)
    matched: int = 0
    new: int = 0
    deleted: int = 0
    inliers: int = 0


@dataclass
class ConeTracker:
    """The track set. :meth:`update` once per frame; :meth:`output` for the published tracks."""

    config: TrackerConfig = field(default_factory=TrackerConfig)
    fov: FieldOfView | None = None
    events: Counter = field(default_factory=Counter)

    def __post_init__(self):
        self._assign = _linear_sum_assignment()
        self.next_id = 1
        self.last_stamp_ns: int | None = None
        self.velocity: tuple[float, float, float] | None = None  # last body twist (constant-velocity prior)
        self._resize(0)

    def _resize(self, n: int) -> None:
        self.ids = np.zeros(n, np.uint32)
        self.xy = np.zeros((n, 2))
        self.P = np.zeros((n, 2, 2))
        self.class_p = np.zeros((n, NUM_CLASSES))
        self.hits = np.zeros(n, np.int64)
        self.misses = np.zeros(n, np.int64)
        self.age = np.zeros(n, np.int64)
        self.certainty = np.zeros(n)
        self.C = np.zeros((n, 2, 2))  # cross-covariance of each track's error with the attitude error, m * deg

    @property
    def max_range_m(self) -> float:
        """The range of the detections used: :attr:`TrackerConfig.max_range_m` within the field of view's."""
        return min(self.config.max_range_m, self.fov.max_range_m if self.fov is not None else float("inf"))

    def __len__(self) -> int:
        return len(self.ids)

    def _keep(self, keep: np.ndarray) -> None:
        for name in ("ids", "xy", "P", "class_p", "hits", "misses", "age", "certainty", "C"):
            setattr(self, name, getattr(self, name)[keep])

    # ---- motion -------------------------------------------------------------------------------
    def _prior(self, dt_s: float, gap: bool) -> Motion2D:
        if self.velocity is None or gap:
            return Motion2D()
        return from_twist(*self.velocity, dt_s)

    def predict(self, motion: Motion2D, dt_s: float, extra_std_m: float = 0.0) -> None:
        """Move the tracks into the current frame and grow their covariance by the motion's uncertainty."""
        if len(self) == 0:
            return
        cfg = self.config
        R = motion.rotation()
        self.xy = motion.to_current(self.xy)
        Rt = R.T  # rotation of vectors from the previous into the current frame
        self.P = Rt[None] @ self.P @ R[None]
        # the attitude error of this frame is correlated with the last one's by exp(-dt / tau)
        self.C = Rt[None] @ self.C * (np.exp(-dt_s / cfg.attitude_tau_s) if cfg.attitude_tau_s > 0 else 0.0)
        q = cfg.process_std_m**2 + (cfg.motion_std_frac * motion.translation_m) ** 2 + extra_std_m**2
        perp = np.stack([-self.xy[:, 1], self.xy[:, 0]], axis=1)  # yaw error moves a point along its normal
        self.P += q * np.eye(2)[None] + cfg.motion_std_rad**2 * perp[:, :, None] * perp[:, None, :]

    # ---- one frame ----------------------------------------------------------------------------
    def update(self, stamp_ns: int, cones: np.ndarray, motion: Motion2D | None = None,
               attitude_jacobian=None, attitude_cov_deg2: np.ndarray | None = None) -> FrameInfo:
        """Fuse one frame's ``CONE_DTYPE`` records (``rear_axle``, this frame) taken at ``stamp_ns``.

        ``motion``: the car's motion since the last fused frame (odometry), or None to estimate it.
        ``attitude_jacobian`` ((N, 2) m -> (N, 2, 2) m/deg, d(x, y)/d(pitch, roll) of a mapped cone) and
        ``attitude_cov_deg2`` ((2, 2) deg^2, the covariance of the attitude the frame was mapped with): the
        part ``J cov J^T`` of each cone's covariance is one error common to the whole frame and correlated
        from frame to frame (:attr:`TrackerConfig.attitude_tau_s`), not independent noise; the Kalman
        update then treats it so (a Schmidt "consider" filter: each track keeps its error's
        cross-covariance with the attitude error), instead of averaging it away as if independent.
        Raises :class:`FrameError` for a stamp not after the last fused frame (nothing changes).
        """
        cfg = self.config
        if self.last_stamp_ns is not None and stamp_ns <= self.last_stamp_ns:
            reason = "stamp_repeated" if stamp_ns == self.last_stamp_ns else "stamp_backwards"
            self.events[reason] += 1
            raise FrameError(reason, f"frame stamp {stamp_ns} ns is not after the last fused frame {self.last_stamp_ns} ns")
        cones = _valid_cones(cones, self.events)
        cones = cones[np.hypot(cones["x"], cones["y"]) <= self.max_range_m]
        weak = cones["score"] < cfg.strong_score  # (n_z,) bool: below the /cones threshold, for confirmation only
        strong = ~weak
        z = np.empty((len(cones), 2))
        z[:, 0], z[:, 1] = cones["x"], cones["y"]
        Rz = np.empty((len(cones), 2, 2))
        Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1] = cones["cov_xx"], cones["cov_xy"], cones["cov_xy"], cones["cov_yy"]
        Rz = _floor_cov(Rz, cfg.meas_var_floor_m2)
        zc = cones["class_id"].astype(np.intp)
        Jz, Sa = np.zeros((len(z), 2, 2)), np.zeros((2, 2))
        if attitude_jacobian is not None and attitude_cov_deg2 is not None and len(z) and np.any(attitude_cov_deg2):
            Jz, Sa = attitude_jacobian(z), np.asarray(attitude_cov_deg2, np.float64)
        Ra = Jz @ Sa @ np.transpose(Jz, (0, 2, 1))  # (n_z, 2, 2) the frame-common part of Rz
        if np.any(Sa):  # the rest, independent, at least the floor (the mapping took its J at the foot pixel)
            w, V = np.linalg.eigh(Rz - Ra)
            Rz = Ra + (V * np.maximum(w, cfg.meas_var_floor_m2)[:, None, :]) @ np.transpose(V, (0, 2, 1))

        first = self.last_stamp_ns is None
        dt = 0.0 if first else (stamp_ns - self.last_stamp_ns) / 1e9
        gap = not first and dt > cfg.max_gap_s
        if gap:
            self.events["gap"] += 1
        info = FrameInfo(stamp_ns, Motion2D(), "none")
        if not first:
            extra = 0.0
            if motion is not None:
                info.motion_source = "odometry"
            else:
                prior = self._prior(dt, gap)
                motion, info.motion_source = prior, "prior"
                if cfg.register and len(self) and strong.any():
                    prior_std = None if gap or self.velocity is None else (cfg.prior_std_m, cfg.prior_std_rad)
                    joint = cfg.register_attitude and np.any(Sa)
                    reg = register_cones(z[strong], zc[strong], self.xy, self._classes(), prior,
                                         (Rz - Ra if joint else Rz)[strong], self.P, prior_std,
                                         search_m=cfg.search_gap_m if gap else cfg.search_m,
                                         min_inliers=cfg.register_min_inliers,
                                         det_att_jac=Jz[strong] if joint else None, att_cov_deg2=Sa if joint else None)
                    info.inliers = reg.inliers
                    if reg.ok:
                        motion, info.motion_source = reg.motion, "registration"
                    else:
                        self.events["registration_failed"] += 1
                        extra = cfg.registration_failed_std_m  # the prior may be off
                elif cfg.register and len(self):
                    self.events["registration_failed"] += 1
            if gap:
                extra = max(extra, cfg.gap_std_m_per_s * (dt - cfg.max_gap_s) + cfg.gap_std_m)
                self.certainty *= np.exp(-dt / cfg.gap_tau_s)
            self.predict(motion, dt, extra)
            if dt > 0 and (not gap or info.motion_source in ("odometry", "registration")):
                self.velocity = motion.twist(dt)
        info.motion = motion if motion is not None else Motion2D()
        self.last_stamp_ns = int(stamp_ns)
        self.age += 1

        # ---- association ----
        n_t, n_z = len(self), len(z)
        rows = cols = np.zeros(0, dtype=np.intp)
        gated_any = np.zeros(n_z, dtype=bool)
        if n_t and n_z:
            if np.any(Sa):  # the common attitude error moves detection and track together: S = P + R - C J^T - J C^T
                d2 = _mahalanobis2(z, Rz, self.xy, self.P, Jz, self.C)  # (n_z, n_t)
            else:
                d2 = _mahalanobis2(z, Rz, self.xy, self.P)  # (n_z, n_t)
            gated = d2 <= cfg.gate_chi2
            near = d2 <= cfg.spawn_chi2
            if np.isfinite(cfg.spawn_max_m):  # and within spawn_max_m metres (far cones: wide covariance along the ray)
                dist = np.hypot(z[:, None, 0] - self.xy[None, :, 0], z[:, None, 1] - self.xy[None, :, 1])
                near &= dist <= cfg.spawn_max_m
            gated_any = near.any(axis=1)
            pc = self.class_p[:, zc].T  # (n_z, n_t): p(track is the detected class)
            unknown = zc == UNKNOWN
            pc[unknown] = 1.0
            cost = d2 - cfg.class_weight * np.log(np.maximum(pc, cfg.class_floor))
            cost[~gated] = _BIG
            rows, cols = self._assign(cost)
            ok = cost[rows, cols] < _BIG
            rows, cols = rows[ok], cols[ok]
        info.matched = len(rows)

        # ---- Kalman update of the matched tracks ----
        if len(rows):
            Rm = Rz[rows]
            if cfg.robust_chi2 > 0:
                Rm = Rm * np.maximum(d2[rows, cols] / cfg.robust_chi2, 1.0)[:, None, None]
            # z = x + J a + e (a: the frame's attitude error, cov Sa; C = cov(track error, a))
            P, C, J = self.P[cols], self.C[cols], Jz[rows]
            Jt = np.transpose(J, (0, 2, 1))
            CJt = C @ Jt
            Rind = Rm - Ra[rows]  # (robust scaling included)
            S = _symmetrise(P + Ra[rows] - CJt - np.transpose(CJt, (0, 2, 1)) + Rind)
            K = (P - CJt) @ inv2(S)
            innov = z[rows] - self.xy[cols]
            self.xy[cols] += np.einsum("nij,nj->ni", K, innov)
            IK = np.eye(2)[None] - K
            KJ = K @ J
            cross = IK @ CJt @ np.transpose(K, (0, 2, 1))
            self.P[cols] = _symmetrise(IK @ P @ np.transpose(IK, (0, 2, 1)) + K @ (Ra[rows] + Rind) @ np.transpose(K, (0, 2, 1))
                                       + cross + np.transpose(cross, (0, 2, 1)))
            self.C[cols] = IK @ C + KJ @ Sa[None]
            self.class_p[cols] = _fuse_class(self.class_p[cols], zc[rows], cones["score"][rows], cfg.class_floor)
            self.hits[cols] += 1
            self.misses[cols] = 0
            c_new = self._hit(self.certainty[cols], cones["score"][rows])
            wk = weak[rows]
            if wk.any():
                c_new[wk] = np.minimum(_bayes(self.certainty[cols[wk]], cfg.weak_likelihood_ratio), cfg.certainty_max)
                self.events["weak_hit"] += int(wk.sum())
            self.certainty[cols] = c_new

        # ---- misses: certainty decays only where the cone should have been seen ----
        missed = np.ones(n_t, dtype=bool)
        missed[cols] = False
        unseen_out = np.zeros(n_t, dtype=bool)  # missed, out of view, too few hits to be kept there
        if missed.any():
            if self.fov is not None:  # in view; within its sides (or beyond its far end)
                vis, sides = self.fov.view(self.xy[missed])
            else:
                vis, sides = np.ones(int(missed.sum()), bool), np.ones(int(missed.sum()), bool)
            vis &= np.hypot(self.xy[missed, 0], self.xy[missed, 1]) <= self.max_range_m
            idx = np.flatnonzero(missed)[vis]
            self.misses[idx] += 1
            self.certainty[idx] = _bayes(self.certainty[idx], cfg.miss_likelihood_ratio)
            out = np.flatnonzero(missed)[~sides]  # off the view's sides or below it (passed)
            unseen_out[out] = self.hits[out] < cfg.out_of_view_min_hits
            self.events["out_of_view_dropped"] += int(unseen_out.sum())

        # ---- deletion (and duplicates merged into the older track) ----
        keep = (self.certainty >= cfg.delete_below) & (self.xy[:, 0] >= -cfg.behind_m) & ~unseen_out
        if n_t > 1 and cfg.merge_chi2 > 0:
            keep &= ~self._duplicates()
        info.deleted = int((~keep).sum())
        if info.deleted:
            self._keep(keep)

        # ---- new tracks from detections no track could take ----
        assigned = np.zeros(n_z, dtype=bool)
        assigned[rows] = True
        new = np.flatnonzero(~assigned & ~gated_any)
        if not cfg.weak_spawn:
            new = new[~weak[new]]
        if len(new):
            self._spawn(z[new], Rz[new], zc[new], cones["score"][new], Jz[new] @ Sa[None], weak[new])
            if weak[new].any():
                self.events["weak_spawn"] += int(weak[new].sum())
        info.new = len(new)
        return info

    def _duplicates(self) -> np.ndarray:
        """(n,) bool: tracks that duplicate an older track (one class, within :attr:`TrackerConfig.merge_chi2`);
        the older one keeps its id and takes the younger one's hits."""
        d2 = _mahalanobis2(self.xy, self.P, self.xy, self.P)
        cls = self._classes()
        close = (d2 <= self.config.merge_chi2) & (cls[:, None] == cls[None, :])
        if np.isfinite(self.config.spawn_max_m):  # farther apart than spawn_max_m: two cones, as at spawning
            close &= np.hypot(self.xy[:, None, 0] - self.xy[None, :, 0], self.xy[:, None, 1] - self.xy[None, :, 1]) \
                <= self.config.spawn_max_m
        np.fill_diagonal(close, False)
        dup = np.zeros(len(self), dtype=bool)
        if not close.any():
            return dup
        for i, j in zip(*np.nonzero(np.triu(close))):
            young, old = (i, j) if self.ids[i] > self.ids[j] else (j, i)
            if dup[old] or dup[young]:
                continue
            dup[young] = True
            self.hits[old] = max(self.hits[old], self.hits[young])
            self.certainty[old] = max(self.certainty[old], self.certainty[young])
        self.events["merged"] += int(dup.sum())
        return dup

    def _spawn(self, z: np.ndarray, Rz: np.ndarray, zc: np.ndarray, score: np.ndarray, C: np.ndarray | None = None,
               weak: np.ndarray | None = None) -> None:
        cfg, n = self.config, len(z)
        ids = np.arange(self.next_id, self.next_id + n, dtype=np.uint64)
        if ids[-1] > np.iinfo(np.uint32).max:
            raise OverflowError("track ids exhausted (uint32)")  # 4e9 cones: not in one run
        self.next_id += n
        uniform = np.full((n, NUM_CLASSES), 1.0 / NUM_CLASSES)
        self.ids = np.concatenate([self.ids, ids.astype(np.uint32)])
        self.xy = np.concatenate([self.xy, z])
        self.P = np.concatenate([self.P, _floor_cov(Rz, cfg.init_var_floor_m2)])
        self.C = np.concatenate([self.C, np.zeros((n, 2, 2)) if C is None else C])
        self.class_p = np.concatenate([self.class_p, _fuse_class(uniform, zc, score, cfg.class_floor)])
        self.hits = np.concatenate([self.hits, np.ones(n, np.int64)])
        self.misses = np.concatenate([self.misses, np.zeros(n, np.int64)])
        self.age = np.concatenate([self.age, np.ones(n, np.int64)])
        c = self._hit(np.full(n, cfg.certainty_prior), score)
        if weak is not None and weak.any():
            c[weak] = _bayes(np.full(int(weak.sum()), cfg.certainty_prior), cfg.weak_likelihood_ratio)
        self.certainty = np.concatenate([self.certainty, c])

    def _hit(self, c: np.ndarray, score: np.ndarray) -> np.ndarray:
        """Certainty after a detection of confidence ``score``: odds times ``odds(score) / odds(score_neutral)``."""
        s = np.clip(np.asarray(score, np.float64), 0.05, 0.95)
        s0 = self.config.score_neutral
        return np.minimum(_bayes(c, (s / (1 - s)) / (s0 / (1 - s0))), self.config.certainty_max)

    def _classes(self) -> np.ndarray:
        return np.argmax(self.class_p, axis=1) if len(self) else np.zeros(0, np.intp)

    def output(self) -> np.ndarray:
        """The published tracks: :data:`TRACKED_CONE_DTYPE` records (``score`` = certainty)."""
        cfg = self.config
        sel = (self.hits >= cfg.min_hits) & (self.certainty >= cfg.publish_min_certainty)
        out = np.zeros(int(sel.sum()), dtype=TRACKED_CONE_DTYPE)
        out["x"], out["y"] = self.xy[sel, 0], self.xy[sel, 1]
        out["class_id"] = self._classes()[sel]
        out["score"] = self.certainty[sel]
        out["cov_xx"], out["cov_xy"], out["cov_yy"] = self.P[sel, 0, 0], self.P[sel, 0, 1], self.P[sel, 1, 1]
        out["track_id"] = self.ids[sel]
        return out


def _linear_sum_assignment():
    """``scipy.optimize.linear_sum_assignment``, imported when a tracker is made: scipy.optimize takes 0.5 s to
    import, which a node that does not track (the pipeline node's default) does not pay at its start."""
    from scipy.optimize import linear_sum_assignment  # heavy (0.5 s): only where a tracker runs

    return linear_sum_assignment


def _bayes(p: np.ndarray, likelihood_ratio) -> np.ndarray:
    """Probability ``p`` after evidence with the given likelihood ratio (odds multiplied)."""
    return p * likelihood_ratio / (p * likelihood_ratio + (1.0 - p))


# ---- small vectorised 2x2 helpers ------------------------------------------------------------
def _symmetrise(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + np.transpose(P, (0, 2, 1)))


def _floor_cov(C: np.ndarray, var_floor: float) -> np.ndarray:
    """Add ``var_floor`` on the diagonal (a measured cone is never surer than that)."""
    return C + var_floor * np.eye(2)[None]


def _mahalanobis2(z: np.ndarray, Rz: np.ndarray, xy: np.ndarray, P: np.ndarray, Jz: np.ndarray | None = None,
                  C: np.ndarray | None = None) -> np.ndarray:
    """(n_z, n_t) squared Mahalanobis distance of each detection to each track, S = P + R (minus
    ``C J^T + J C^T`` with the detections' attitude Jacobians ``Jz`` (n_z, 2, 2) and the tracks' cross-covariances ``C``)."""
    a = P[None, :, 0, 0] + Rz[:, None, 0, 0]
    b = P[None, :, 0, 1] + Rz[:, None, 0, 1]
    c = P[None, :, 1, 1] + Rz[:, None, 1, 1]
    if Jz is not None and C is not None:
        CJt = np.einsum("tik,zjk->ztij", C, Jz)  # (n_z, n_t, 2, 2): C_t J_z^T
        a = a - 2 * CJt[..., 0, 0]
        b = b - CJt[..., 0, 1] - CJt[..., 1, 0]
        c = c - 2 * CJt[..., 1, 1]
    dx = z[:, None, 0] - xy[None, :, 0]
    dy = z[:, None, 1] - xy[None, :, 1]
    return (c * dx * dx - 2 * b * dx * dy + a * dy * dy) / (a * c - b * b)


def _fuse_class(p: np.ndarray, cls: np.ndarray, score: np.ndarray, floor: float) -> np.ndarray:
    """Bayes update of class probabilities (n, K) with detections of class ``cls`` and confidence ``score``:
    likelihood ``s`` for the detected class, ``(1 - s) / (K - 1)`` for each other one (``unknown``: no information)."""
    s = np.clip(np.asarray(score, np.float64), 0.3, 0.95)[:, None]
    like = np.repeat((1.0 - s) / (NUM_CLASSES - 1), NUM_CLASSES, axis=1)
    like[np.arange(len(cls)), cls] = s[:, 0]
    like[cls == UNKNOWN] = 1.0
    q = p * like
    q /= q.sum(axis=1, keepdims=True)
    q = np.maximum(q, floor)
    return q / q.sum(axis=1, keepdims=True)


def _valid_cones(cones: np.ndarray, events: Counter) -> np.ndarray:
    """The frame's cones with finite position and covariance and a known class; others counted and left out."""
    cones = np.asarray(cones)
    if cones.dtype != CONE_DTYPE:
        cones = cones.astype(CONE_DTYPE)
    ok = np.ones(len(cones), dtype=bool)
    for name in ("x", "y", "cov_xx", "cov_xy", "cov_yy"):
        ok &= np.isfinite(cones[name])
    ok = ok & (cones["class_id"] < NUM_CLASSES) & (cones["cov_xx"] >= 0) & (cones["cov_yy"] >= 0)
    if not ok.all():
        events["bad_cone"] += int((~ok).sum())
        cones = cones[ok]
    return cones
