"""The car's planar motion between camera frames: from odometry twists, or from the cones themselves.

A :class:`Motion2D` is the pose of the current ``rear_axle`` frame in the previous one
(``p_prev = R(dyaw) @ p_cur + (dx, dy)``): driving 0.4 m straight ahead is ``Motion2D(0.4, 0, 0)``
and moves every static cone by -0.4 m in x. ROS-free.

* :class:`TwistBuffer`: body twists (``nav_msgs/Odometry`` ``twist.twist`` or
  ``geometry_msgs/TwistStamped``, assumed in axes parallel to ``rear_axle``) integrated over the
  interval between two frames. A twist with a NaN is refused (counted by the caller); odometry
  older than :attr:`TwistBuffer.max_age_s` at a frame is not used for it.
* :func:`register_cones`: a robust 2D rigid registration of a frame's cones against the tracks
  predicted by a prior motion (constant velocity): RANSAC over pairs of class-compatible
  correspondences when the prior explains too few cones, then Gauss-Newton least squares with each
  pair's covariance and Cauchy weights on the nearest pairs, re-associated once; the prior joins as
  a measurement when the cones agree with it. Given the detections' attitude Jacobians, the frame's
  common attitude error is estimated alongside (and dropped), so it is not taken for motion.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass

import numpy as np

from ..classes import UNKNOWN


@dataclass(frozen=True)
class Motion2D:
    """Pose of the current frame in the previous one: (m, m, rad)."""

    dx: float = 0.0
    dy: float = 0.0
    dyaw: float = 0.0

    @property
    def translation_m(self) -> float:
        return float(np.hypot(self.dx, self.dy))

    def rotation(self) -> np.ndarray:
        c, s = np.cos(self.dyaw), np.sin(self.dyaw)
        return np.array([[c, -s], [s, c]])

    def to_current(self, xy_prev: np.ndarray) -> np.ndarray:
        """(N, 2) points in the previous frame (m) -> (N, 2) in the current frame (m)."""
        p = np.asarray(xy_prev, dtype=np.float64).reshape(-1, 2)
        return (p - (self.dx, self.dy)) @ self.rotation()

    def to_previous(self, xy_cur: np.ndarray) -> np.ndarray:
        """(N, 2) points in the current frame (m) -> (N, 2) in the previous frame (m)."""
        p = np.asarray(xy_cur, dtype=np.float64).reshape(-1, 2)
        return p @ self.rotation().T + (self.dx, self.dy)

    def twist(self, dt_s: float) -> tuple[float, float, float]:
        """The constant body twist (m/s, m/s, rad/s) that moves the car by this motion in ``dt_s`` (inverse
        of :func:`from_twist`)."""
        th = self.dyaw
        if abs(th) < 1e-9:
            return self.dx / dt_s, self.dy / dt_s, th / dt_s
        a, b = np.sin(th) / th, (1.0 - np.cos(th)) / th  # chord = dt [[a, -b], [b, a]] v
        n = a * a + b * b
        return (float((a * self.dx + b * self.dy) / (n * dt_s)), float((-b * self.dx + a * self.dy) / (n * dt_s)), th / dt_s)

    def compose(self, other: "Motion2D") -> "Motion2D":
        """This motion followed by ``other`` (both relative, result prev -> after other)."""
        t = self.rotation() @ (other.dx, other.dy) + (self.dx, self.dy)
        return Motion2D(float(t[0]), float(t[1]), float(_wrap(self.dyaw + other.dyaw)))


def _wrap(a: float) -> float:
    return (a + np.pi) % (2 * np.pi) - np.pi


def from_twist(vx: float, vy: float, wz: float, dt: float) -> Motion2D:
    """Constant body twist (m/s, m/s, rad/s) held for ``dt`` s -> :class:`Motion2D` (exact arc)."""
    th = wz * dt
    if abs(th) < 1e-9:
        return Motion2D(vx * dt, vy * dt, th)
    a, b = np.sin(th) / th, (1.0 - np.cos(th)) / th
    return Motion2D(float((a * vx - b * vy) * dt), float((b * vx + a * vy) * dt), float(th))


class TwistBuffer:
    """Recent body twists by stamp; :meth:`motion` integrates them between two frame stamps.

    Each twist holds from its stamp to the next one (zero-order hold). :meth:`add` refuses a
    twist with a non-finite value (returns ``"twist_nan"``) or a stamp not after the last one
    (``"twist_stamp"``); the caller counts the cause.
    """

    def __init__(self, max_age_s: float = 0.1, keep_s: float = 2.0):
        self.max_age_s = float(max_age_s)
        self.keep_s = float(keep_s)
        self.stamps: list[int] = []  # ns
        self.twists: list[tuple[float, float, float]] = []

    def add(self, stamp_ns: int, vx: float, vy: float, wz: float) -> str | None:
        """Store one twist (m/s, m/s, rad/s, body axes). Returns the cause when refused, else None."""
        if not all(np.isfinite((vx, vy, wz))):
            return "twist_nan"
        if self.stamps and stamp_ns <= self.stamps[-1]:
            return "twist_stamp"
        self.stamps.append(int(stamp_ns))
        self.twists.append((float(vx), float(vy), float(wz)))
        cut = bisect_right(self.stamps, stamp_ns - int(self.keep_s * 1e9))
        if cut > 1:
            del self.stamps[: cut - 1], self.twists[: cut - 1]
        return None

    def fresh_at(self, stamp_ns: int) -> bool:
        """True when the newest twist at or before ``stamp_ns`` is at most :attr:`max_age_s` old."""
        i = bisect_right(self.stamps, stamp_ns) - 1
        return i >= 0 and (stamp_ns - self.stamps[i]) <= self.max_age_s * 1e9

    def motion(self, t0_ns: int, t1_ns: int) -> Motion2D | None:
        """Motion from frame ``t0`` to frame ``t1``; None without a fresh twist at ``t1`` or any twist before it."""
        if not self.stamps or t1_ns <= t0_ns or not self.fresh_at(t1_ns):
            return None
        i = max(bisect_right(self.stamps, t0_ns) - 1, 0)
        out, t = Motion2D(), t0_ns
        while t < t1_ns:
            end = min(self.stamps[i + 1] if i + 1 < len(self.stamps) else t1_ns, t1_ns)
            if end > t:
                out = out.compose(from_twist(*self.twists[i], (end - t) / 1e9))
                t = end
            i += 1
            if i >= len(self.stamps):
                i = len(self.stamps) - 1
        return out


@dataclass
class Registration:
    """Result of :func:`register_cones`: the motion, its inlier count and whether it is trusted."""

    motion: Motion2D
    inliers: int
    ok: bool
    det_index: np.ndarray  # (K,) int: inlier detections
    trk_index: np.ndarray  # (K,) int: their tracks


def _gauss_newton(src, dst, c_src, c_dst, start: Motion2D, prior: Motion2D, prior_std, iterations: int = 3,
                  cauchy_m: float = 0.05, src_att_jac=None, att_cov_deg2=None) -> Motion2D:
    """Motion with ``dst ~= R src + t`` minimising Mahalanobis residuals (Cauchy-weighted), plus the prior.

    With ``src_att_jac`` ((n, 2, 2) m/deg) and ``att_cov_deg2`` ((2, 2)): the detections share one
    attitude error ``a`` (prior N(0, att_cov)), ``dst ~= R (src - J a) + t``; ``a`` is estimated with the
    motion and thrown away, so a frame-common attitude error is not taken for motion."""
    att = src_att_jac is not None and att_cov_deg2 is not None and np.any(att_cov_deg2)
    m = 5 if att else 3
    x = np.zeros(m)
    x[:3] = start.dx, start.dy, start.dyaw
    w_prior = np.zeros((m, m))
    x_prior = np.zeros(m)
    if prior_std is not None:
        w_prior[:3, :3] = np.diag([1 / prior_std[0] ** 2, 1 / prior_std[0] ** 2, 1 / prior_std[1] ** 2])
        x_prior[:3] = prior.dx, prior.dy, prior.dyaw
    if att:
        w_prior[3:, 3:] = np.linalg.inv(np.asarray(att_cov_deg2, np.float64) + np.eye(2) * 1e-9)
    n = len(src)
    J = np.zeros((n, 2, m))
    J[:, 0, 0] = J[:, 1, 1] = 1.0
    for _ in range(iterations):
        c, s = np.cos(x[2]), np.sin(x[2])
        R = np.array([[c, -s], [s, c]])
        src_a = src - np.einsum("nij,j->ni", src_att_jac, x[3:]) if att else src
        rs = src_a @ R.T
        r = rs + x[:2] - dst  # (n, 2)
        cov = R @ c_src @ R.T + c_dst
        a, b, d = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
        det = a * d - b * b
        W = np.empty((n, 2, 2))
        W[:, 0, 0], W[:, 0, 1], W[:, 1, 0], W[:, 1, 1] = d / det, -b / det, -b / det, a / det  # inverse covariances
        m2 = W[:, 0, 0] * r[:, 0] ** 2 + 2 * W[:, 0, 1] * r[:, 0] * r[:, 1] + W[:, 1, 1] * r[:, 1] ** 2
        # Cauchy: weight 1 / (1 + m2 / k^2), with k the Mahalanobis size of cauchy_m (at least 1)
        k2 = np.maximum(cauchy_m**2 / np.maximum((a + d) / 2, 1e-6), 1.0)
        W *= (1.0 / (1.0 + m2 / k2))[:, None, None]
        J[:, 0, 2], J[:, 1, 2] = -rs[:, 1], rs[:, 0]  # d(R src)/d yaw
        if att:
            J[:, :, 3:] = -R[None] @ src_att_jac  # d(R (src - J a))/d a
        JtW = np.transpose(J, (0, 2, 1)) @ W
        A = (JtW @ J).sum(0)
        g = (JtW @ r[:, :, None]).sum(0)[:, 0]
        if prior_std is not None or att:
            dp = x - x_prior
            dp[2] = _wrap(dp[2])
            A = A + w_prior
            g = g + w_prior @ dp
        x = x - np.linalg.solve(A, g)
    return Motion2D(float(x[0]), float(x[1]), float(_wrap(x[2])))


def register_cones(
    det_xy: np.ndarray,
    det_cls: np.ndarray,
    trk_xy: np.ndarray,
    trk_cls: np.ndarray,
    prior: Motion2D,
    det_cov: np.ndarray | None = None,
    trk_cov: np.ndarray | None = None,
    prior_std: tuple[float, float] | None = None,
    search_m: float = 1.5,
    inlier_m: float = 0.3,
    min_inliers: int = 3,
    iterations: int = 40,
    prior_gate: float = 3.0,
    rng: np.random.Generator | None = None,
    det_att_jac: np.ndarray | None = None,
    att_cov_deg2: np.ndarray | None = None,
) -> Registration:
    """Motion of the car from cones: the current frame's cones against the tracks of the previous frame.

    ``det_xy`` (N, 2) m, current frame; ``trk_xy`` (M, 2) m, previous frame; ``det_cls`` / ``trk_cls``
    class ids (``unknown`` pairs with any class); ``prior`` the expected motion (constant velocity).
    Correspondence candidates are class-compatible pairs within ``search_m`` after the prior; RANSAC on
    two candidates at a time (the prior itself is a hypothesis too) keeps the motion with most inliers
    (residual <= ``inlier_m``, each detection once), refined by Gauss-Newton least squares with each
    pair's covariance ``R det_cov R^T + trk_cov`` ((N, 2, 2) / (M, 2, 2) m^2, default identity) and
    Cauchy weights against outliers; with ``det_att_jac`` ((N, 2, 2) m/deg) and ``att_cov_deg2`` ((2, 2)
    deg^2) the detections' common attitude error is estimated alongside (``det_cov`` then holds only the
    independent part of their covariance). With ``prior_std`` (translation m, yaw rad) the prior then joins as
    one more measurement, if the cones' motion lies within ``prior_gate`` sigma of it. ``ok`` is False with fewer than ``min_inliers``; the motion is
    then the prior.
    """
    det_xy = np.asarray(det_xy, dtype=np.float64).reshape(-1, 2)
    trk_xy = np.asarray(trk_xy, dtype=np.float64).reshape(-1, 2)
    empty = np.zeros(0, dtype=np.intp)
    fail = Registration(prior, 0, False, empty, empty)
    n_det = len(det_xy)
    if n_det < min_inliers or len(trk_xy) < min_inliers:
        return fail
    det_cov = np.broadcast_to(np.eye(2) * 0.01, (n_det, 2, 2)) if det_cov is None else np.asarray(det_cov, np.float64)
    trk_cov = np.broadcast_to(np.eye(2) * 0.01, (len(trk_xy), 2, 2)) if trk_cov is None else np.asarray(trk_cov, np.float64)
    dc, tc = np.asarray(det_cls)[:, None], np.asarray(trk_cls)[None, :]
    incompatible = (dc != tc) & (dc != UNKNOWN) & (tc != UNKNOWN)

    def nearest(motion: Motion2D) -> tuple[np.ndarray, np.ndarray]:
        """(N,) nearest compatible track of each detection under ``motion`` and its distance (m)."""
        p = motion.to_previous(det_xy)
        d2 = (p[:, None, 0] - trk_xy[None, :, 0]) ** 2 + (p[:, None, 1] - trk_xy[None, :, 1]) ** 2
        d2[incompatible] = np.inf
        j = np.argmin(d2, axis=1)
        return j, np.sqrt(d2[np.arange(n_det), j])

    motion = prior
    j, dmin = nearest(prior)
    if np.count_nonzero(dmin <= inlier_m) < max(min_inliers, n_det // 2):
        # the prior explains too few cones: RANSAC over pairs of candidate correspondences
        p = prior.to_previous(det_xy)
        d = np.hypot(p[:, None, 0] - trk_xy[None, :, 0], p[:, None, 1] - trk_xy[None, :, 1])
        cand_i, cand_j = np.nonzero((d <= search_m) & ~incompatible)
        if len(cand_i) < min_inliers:
            return fail
        src, dst = det_xy[cand_i], trk_xy[cand_j]  # dst ~= R src + t for the true motion
        rng = rng if rng is not None else np.random.default_rng(0)
        k = len(cand_i)
        a, b = rng.integers(0, k, iterations), rng.integers(0, k, iterations)
        good = (cand_i[a] != cand_i[b]) & (cand_j[a] != cand_j[b])
        a, b = a[good], b[good]
        vs, vd = src[b] - src[a], dst[b] - dst[a]
        ok_len = np.abs(np.hypot(vs[:, 0], vs[:, 1]) - np.hypot(vd[:, 0], vd[:, 1])) <= 2 * inlier_m
        a, b, vs, vd = a[ok_len], b[ok_len], vs[ok_len], vd[ok_len]
        th = np.arctan2(vd[:, 1], vd[:, 0]) - np.arctan2(vs[:, 1], vs[:, 0])
        mid_s, mid_d = (src[a] + src[b]) / 2, (dst[a] + dst[b]) / 2
        c, s = np.cos(th), np.sin(th)
        tx = np.concatenate([[prior.dx], mid_d[:, 0] - (c * mid_s[:, 0] - s * mid_s[:, 1])])
        ty = np.concatenate([[prior.dy], mid_d[:, 1] - (s * mid_s[:, 0] + c * mid_s[:, 1])])
        th = np.concatenate([[prior.dyaw], th])
        c, s = np.cos(th)[:, None], np.sin(th)[:, None]
        px = c * src[None, :, 0] - s * src[None, :, 1] + tx[:, None]
        py = s * src[None, :, 0] + c * src[None, :, 1] + ty[:, None]
        hh, kk = np.nonzero(np.hypot(px - dst[None, :, 0], py - dst[None, :, 1]) <= inlier_m)  # (H, K) inliers
        hit = np.zeros((len(th), n_det), dtype=bool)
        hit[hh, cand_i[kk]] = True  # each detection counted once
        score = hit.sum(axis=1)
        best = int(np.argmax(score))
        if score[best] < min_inliers:
            return fail
        motion = Motion2D(float(tx[best]), float(ty[best]), float(th[best]))
        j, dmin = nearest(motion)
    # refine: nearest compatible track per detection (one detection per track), then Gauss-Newton
    di = tj = empty
    for it in range(2):
        if it:
            j, dmin = nearest(motion)
        order = np.argsort(dmin)
        order = order[dmin[order] <= inlier_m]
        _, first = np.unique(j[order], return_index=True)  # the nearest detection of each track
        di = np.sort(order[first])
        tj = j[di]
        if len(di) < min_inliers:
            break
        motion = _gauss_newton(det_xy[di], trk_xy[tj], det_cov[di], trk_cov[tj], motion, prior, None, iterations=2,
                               src_att_jac=None if det_att_jac is None else det_att_jac[di], att_cov_deg2=att_cov_deg2)
    if prior_std is not None and len(di) >= min_inliers:
        # the prior joins only when the cones agree with it (a wrong prior must not hold the estimate)
        off = np.hypot(motion.dx - prior.dx, motion.dy - prior.dy)
        if off <= prior_gate * np.hypot(prior_std[0], 0.03) and abs(_wrap(motion.dyaw - prior.dyaw)) <= prior_gate * np.hypot(prior_std[1], 0.005):
            motion = _gauss_newton(det_xy[di], trk_xy[tj], det_cov[di], trk_cov[tj], motion, prior, prior_std, iterations=1,
                                   src_att_jac=None if det_att_jac is None else det_att_jac[di], att_cov_deg2=att_cov_deg2)
    if len(di) < min_inliers:
        return Registration(prior, int(len(di)), False, di, tj)
    return Registration(motion, int(len(di)), True, di, tj)
