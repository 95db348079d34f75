"""Camera attitude per frame: the calibration's ``H_F_B`` recomposed for a body pitch / roll
offset, and the offset estimated from the frame's cone boxes.

Attitude offset: the sprung body (and the camera on it) rotates about the rear-axle origin by
``R_att = R_y(pitch) @ R_x(roll)`` (pitch positive = nose DOWN, roll positive = right side
DOWN, degrees), the convention of :class:`~cone_perception.camera.MountPose` and of the
synthetic scenes' body jitter. The camera's pose in ``rear_axle`` becomes
``R_F_C' = R_att @ R_F_C``, position ``R_att @ p``.

:class:`AttitudeModel` keeps the calibrated ``H_F_B`` exact at zero offset and applies the
offset as a pixel-to-pixel correction derived from the mount pose:
``H_F_B(att) = H_F_B @ H_B_F_pose(0) @ H_F_B_pose(att)``.

:class:`ImageAttitude` fits the offset per frame. Cones are objects of known size standing on
the ground: the foot point of a box gives its range through the ground plane (which depends on
the attitude), its height gives the range independently of the ground. For an attitude
hypothesis the foot point is mapped to the ground, the cone's tip is placed above it and
projected; the residual is predicted minus observed top row of the box (px). A robust
(Cauchy) weighted least-squares fit of (pitch, roll) with a weak prior around zero, started
from the weighted median of single-cone pitch estimates, then a Kalman filter across frames
(random walk decaying to zero): frames with too few usable cones hold the last estimate,
decaying to zero; a fit beyond :data:`MAX_ABS_DEG` is rejected and counted.

:class:`ImuAttitude` reads an IMU's orientation relative to its rest attitude;
:class:`FusedAttitude` adds to it the ground offset the image fits see (the road ahead's grade),
through a :class:`GroundGate`. ROS-free.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from .camera import MountPose, PinholeCamera
from .classes import CONE_SIZE_M, NUM_CLASSES
from .geometry import apply_homography, fix_homography_sign, undistort_pixels

#: Attitude sources: ``fixed`` (the calibration's H_F_B), ``image`` (cone boxes), ``imu``, ``fused``.
ATTITUDE_MODES = ("fixed", "image", "imu", "fused")
#: Image fits farther than this from zero (degrees, pitch or roll) are rejected and counted.
MAX_ABS_DEG = 5.0
#: A mount pose may disagree with the calibration's own H_F_B by at most this fraction of range at 10 m.
MOUNT_POSE_TOLERANCE = 0.01
MOUNT_POSE_CHECK_RANGE_M = 10.0


def attitude_rotation(pitch_deg: float, roll_deg: float) -> np.ndarray:
    """3x3 body rotation ``R_y(pitch) @ R_x(roll)`` (degrees; pitch + = nose down, roll + = right down)."""
    p, r = math.radians(pitch_deg), math.radians(roll_deg)
    cp, sp, cr, sr = math.cos(p), math.sin(p), math.cos(r), math.sin(r)
    return np.array([[cp, sp * sr, sp * cr], [0.0, cr, -sr], [-sp, cp * sr, cp * cr]])


def pose_H_B_F(K: np.ndarray, pose: MountPose, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
    """Homography ground (x, y of ``rear_axle``) -> undistorted px of a camera at ``pose`` on a body
    tilted by (pitch, roll) about the rear-axle origin."""
    R_att = attitude_rotation(pitch_deg, roll_deg)
    R_C_F = (R_att @ pose.R_F_C()).T
    t = -R_C_F @ (R_att @ pose.position_F())
    return np.asarray(K, dtype=np.float64) @ np.column_stack([R_C_F[:, 0], R_C_F[:, 1], t])


def mount_pose_disagreement(H_F_B: np.ndarray, K: np.ndarray, pose: MountPose, width: int, height: int,
                            range_m: float = MOUNT_POSE_CHECK_RANGE_M) -> float:
    """Largest position error, as a fraction of range, between ``pose`` (with K) and ``H_F_B`` for
    ground points ``range_m`` from the camera that the image sees (17 bearings across the view).

    Returns ``inf`` when the pose's camera sees no ground at that range inside the image.
    """
    cam = PinholeCamera(np.asarray(K, dtype=np.float64), width, height, pose)
    bearings = np.radians(np.linspace(-80.0, 80.0, 17)) + np.radians(pose.yaw_deg)
    g = np.column_stack([pose.x_m + range_m * np.cos(bearings), pose.y_m + range_m * np.sin(bearings)])
    uv, w = apply_homography(cam.H_B_F(), g)
    inside = (w > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= height - 1)
    if not np.any(inside):
        return float("inf")
    xy, w2 = apply_homography(H_F_B, uv[inside])
    if np.any(w2 <= 0):
        return float("inf")
    return float(np.max(np.hypot(*(xy - g[inside]).T)) / range_m)


class AttitudeModel:
    """The calibration's ``H_F_B`` for any body attitude offset (pitch, roll in degrees)."""

    def __init__(self, H_F_B: np.ndarray, K: np.ndarray, pose: MountPose, ground_px: tuple[float, float]):
        self.H0 = np.asarray(H_F_B, dtype=np.float64)
        self.K = np.asarray(K, dtype=np.float64)
        self.pose = pose
        self.ground_px = ground_px
        self._H_B_F_rest = pose_H_B_F(self.K, pose)
        self._R_F_C, self._p = pose.R_F_C(), pose.position_F()
        self._H0_rest = self.H0 @ self._H_B_F_rest

    def H_F_B(self, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
        """3x3 undistorted px -> ground (m) with the body tilted by (pitch, roll); the calibrated H at 0."""
        if pitch_deg == 0.0 and roll_deg == 0.0:
            return self.H0
        R_att = attitude_rotation(pitch_deg, roll_deg)  # pose_H_B_F with the pose's rotation cached
        R_C_F = (R_att @ self._R_F_C).T
        t = -R_C_F @ (R_att @ self._p)
        H_B_F = self.K @ np.column_stack([R_C_F[:, 0], R_C_F[:, 1], t])
        return fix_homography_sign(self._H0_rest @ _inv3(H_B_F), self.ground_px)


@dataclass(frozen=True)
class Attitude:
    """The attitude offset used for one frame (degrees) with its 1-sigma, and where it came from.

    ``source``: ``fixed``, ``image`` (this frame's fit), ``hold`` (no usable fit this frame: the
    filter's prediction, decaying to zero), ``imu``, ``fused``. ``n_cones``: cones the fit used.
    """

    pitch_deg: float = 0.0
    roll_deg: float = 0.0
    sigma_pitch_deg: float = 0.0
    sigma_roll_deg: float = 0.0
    source: str = "fixed"
    n_cones: int = 0

    @property
    def is_zero(self) -> bool:
        return self.pitch_deg == 0.0 and self.roll_deg == 0.0

    def covariance_deg2(self) -> np.ndarray:
        """2x2 covariance of (pitch, roll) in degrees^2 (independent)."""
        return np.diag([self.sigma_pitch_deg**2, self.sigma_roll_deg**2])


FIXED = Attitude()


def attitude_vector(att: Attitude) -> tuple[float, float, float]:
    """(x, y, z) of the published ``geometry_msgs/Vector3Stamped``: rotation of the body about the
    ``rear_axle`` axes in RADIANS (REP 103): x = roll (+ right side down), y = pitch (+ nose down), z = 0."""
    return math.radians(att.roll_deg), math.radians(att.pitch_deg), 0.0


def box_top_extra_px(height_px: np.ndarray, table) -> np.ndarray:
    """(N,) px the detector's box tops stand above the cones' (``table``: (box height px, px) pairs,
    interpolated, ends held; empty = zero) for boxes (N,) px high."""
    h = np.asarray(height_px, dtype=np.float64)
    if not table:
        return np.zeros(h.shape)
    return np.interp(h, [a for a, _ in table], [b for _, b in table])


@dataclass
class ImageAttitudeConfig:
    """Tuning of :class:`ImageAttitude` (degrees, px, frames)."""

    min_cones: int = 3  # usable cones for a fit
    min_height_px: float = 8.0  # boxes shorter than this tell little and are often wrong
    max_range_m: float = 20.0  # cones farther (by their size) are left out
    edge_margin_px: float = 2.0  # boxes this close to the image / band edge are cut: left out
    aspect_tol: float = 0.45  # |log(w/h / expected)| above this: knocked over, merged or wrong
    sigma_px: float = 1.5  # box edge 1-sigma (foot and top)
    #: a box's top edge lies this far above the cone's projected tip (a box covers every pixel the cone
    #: touches); tests/test_attitude.py::test_box_top_bias_on_rendered_cones checks it
    top_bias_px: float = 1.0
    #: plus this much by box height (px -> px, interpolated): the shipped detector's boxes, half the median
    #: top-row residual at the true attitude on tuning drives (docs/benchmarks.md, "Bias of the image fit")
    top_bias_extra_px: tuple = ((15.0, 0.29), (22.0, 0.20), (33.0, 0.06), (50.0, 0.10), (75.0, 0.05), (120.0, 0.05))
    sigma_rel: float = 0.03  # plus this fraction of the box height (cone build, orientation)
    cauchy_c: float = 1.5  # robust scale in sigmas
    outer_iterations: int = 1  # linearisations per fit (the second only after a step of more than 0.3 degree)
    prior_sigma_deg: float = 2.0  # per-frame prior around zero
    process_sigma_deg: float = 0.6  # random walk per frame (body motion at 20 fps)
    decay: float = 0.95  # per frame, towards zero
    max_abs_deg: float = MAX_ABS_DEG
    #: the fit's own slowly varying bias (box edges of this detector on this drive's cones): the long-run
    #: mean of the fits, since the car's mean attitude over a lap is the calibration's (zero). A running
    #: mean shrunk towards zero by ``bias_prior_frames`` pseudo-frames, an exponential mean of
    #: ``bias_tau_frames`` (about a lap at 20 fps) once that many fits are in; 0 = off. Roll only
    #: (``bias_pitch`` False): a grade or a braking phase longer than the bag moves the mean pitch.
    bias_tau_frames: float = 1200.0
    bias_prior_frames: float = 100.0
    bias_pitch: bool = False
    #: still body: the spread of the fits over ``still_frames`` frames against their own sigma; below
    #: ``still_ratio`` (pitch and roll) the body is taken as still and the estimate returns to zero,
    #: fully at ``still_ratio - still_ramp``; 0 frames = off
    still_frames: float = 40.0
    still_min_frames: float = 10.0  # fits before the test judges (until then: moving)
    still_ratio: float = 1.3
    still_ramp: float = 0.4
    #: ... and only while the fits' mean stays within this (degrees, pitch and roll; ramp of half of it):
    #: a body standing still on a slope keeps its estimate
    still_max_mean_deg: float = 0.5


@dataclass
class AttitudeCounts:
    """Frames by outcome of the image fit."""

    fitted: int = 0
    too_few: int = 0
    rejected: int = 0

    def as_dict(self) -> dict[str, int]:
        return {"fitted": self.fitted, "too_few_cones": self.too_few, "rejected_beyond_limit": self.rejected}


class ImageAttitude:
    """Per-frame attitude offset from the cone boxes, smoothed across frames.

    ``K``/``dist``: lens model; ``pose``: the calibration's mount pose; ``foot_offset_m``: per class
    (as the mapping uses); ``image_size``/``band_rows``: boxes touching these edges are cut.
    """

    def __init__(
        self,
        K: np.ndarray,
        pose: MountPose,
        foot_offset_m: np.ndarray,
        image_size: tuple[int, int],
        band_rows: tuple[float, float] | None = None,
        dist: np.ndarray | None = None,
        config: ImageAttitudeConfig | None = None,
    ):
        self.K = np.asarray(K, dtype=np.float64)
        self.Kinv = np.linalg.inv(self.K)
        self.dist = None if dist is None or not np.any(dist) else np.asarray(dist, dtype=np.float64)
        self.pose = pose
        self.R_F_C0 = pose.R_F_C()
        self.p0 = pose.position_F()
        self.off = np.asarray(foot_offset_m, dtype=np.float64)
        self.W, self.H = image_size
        self.band = band_rows if band_rows is not None else (0.0, float(self.H))
        self.cfg = config or ImageAttitudeConfig()
        size = np.array([CONE_SIZE_M.get(c, (np.nan, np.nan, np.nan)) for c in range(NUM_CLASSES)])
        self._height_m, self._base_m, self._tip_r_m = size[:, 0], size[:, 1], size[:, 2]
        self.counts = AttitudeCounts()
        self.reset()

    def reset(self) -> None:
        """Forget the filter state (a new drive)."""
        self.x = np.zeros(2)
        self.P = np.eye(2) * self.cfg.prior_sigma_deg**2
        self.bias = np.zeros(2)  # the fit's slowly varying bias (degrees), see ImageAttitudeConfig.bias_tau_frames
        self.n_bias = 0
        self._m1 = np.zeros(2)  # exponential means of the fits, their squares and their variances (still test)
        self._m2 = np.zeros(2)
        self._mv = np.zeros(2)
        self._n_still = 0

    def motion_weight(self, z: np.ndarray | None, Rz: np.ndarray | None) -> float:
        """Fold one fit into the still test; 1 = the body moves (use the estimate), 0 = still (use zero)."""
        c = self.cfg
        if c.still_frames <= 0:
            return 1.0
        if z is not None:
            self._n_still += 1
            a = 1.0 / min(self._n_still, c.still_frames)
            self._m1 += a * (z - self._m1)
            self._m2 += a * (z * z - self._m2)
            self._mv += a * (np.diag(Rz) - self._mv)
        if self._n_still < c.still_min_frames:
            return 1.0
        spread = np.sqrt(np.maximum(self._m2 - self._m1**2, 0.0) / np.maximum(self._mv, 1e-12))
        moving = (np.max(spread) - (c.still_ratio - c.still_ramp)) / c.still_ramp
        sloped = (np.max(np.abs(self._m1)) - c.still_max_mean_deg) / (0.5 * c.still_max_mean_deg)
        return float(np.clip(max(moving, sloped), 0.0, 1.0))

    def still_sigma(self, sd: np.ndarray, wm: float) -> np.ndarray:
        """(2,) 1-sigma (degrees) of the attitude used: the estimate's ``sd`` while the body moves; while it is
        still (``wm`` 0) how far from zero the recent fits say it may be (their mean and spread)."""
        if wm >= 1.0:
            return sd
        still = np.sqrt(self._m1**2 + np.maximum(self._m2 - self._m1**2, 0.0))
        return wm * sd + (1.0 - wm) * np.minimum(still, sd)

    def debias(self, z: np.ndarray) -> np.ndarray:
        """Fold one accepted fit ``z`` (2,) degrees into the bias estimate; return the fit less the bias."""
        c = self.cfg
        if c.bias_tau_frames <= 0:
            return z
        self.n_bias += 1
        self.bias = self.bias + (z - self.bias) / min(self.n_bias + c.bias_prior_frames, c.bias_tau_frames)
        if not c.bias_pitch:
            self.bias[0] = 0.0
        return z - self.bias

    # -- model ------------------------------------------------------------------------------------
    def _select(self, boxes: np.ndarray, class_ids: np.ndarray) -> np.ndarray:
        """(N,) bool: boxes that may be standing, whole cones of a known size."""
        c = self.cfg
        b = boxes
        known = (class_ids >= 0) & (class_ids < NUM_CLASSES)
        cls = np.where(known, class_ids, 0)
        hm = self._height_m[cls]
        w = np.maximum(b[:, 2] - b[:, 0], 1e-6)
        h = np.maximum(b[:, 3] - b[:, 1], 1e-6)
        aspect_ok = np.abs(np.log(w / h * (hm / self._base_m[cls]))) <= c.aspect_tol  # NaN (unknown size): False
        near = self.K[1, 1] * hm <= c.max_range_m * h
        m = c.edge_margin_px
        inside = (b[:, 0] > m) & (b[:, 2] < self.W - m) & (b[:, 1] > self.band[0] + m) & (b[:, 3] < self.band[1] - m)
        return known & aspect_ok & (h >= c.min_height_px) & inside & near

    def _prepare(self, boxes: np.ndarray, class_ids: np.ndarray):
        u = 0.5 * (boxes[:, 0] + boxes[:, 2]) - 0.5  # pixel-edge -> pixel-centre coordinates
        foot = np.column_stack([u, boxes[:, 3] - 0.5])
        top = np.column_stack([u, boxes[:, 1] - 0.5 + self.cfg.top_bias_px
                               + box_top_extra_px(boxes[:, 3] - boxes[:, 1], self.cfg.top_bias_extra_px)])
        if self.dist is not None:
            foot = undistort_pixels(foot, self.K, self.dist)
            top = undistort_pixels(top, self.K, self.dist)
        rays = np.column_stack([foot, np.ones(len(foot))]) @ self.Kinv.T  # (N, 3) optical frame
        return rays, top[:, 1], class_ids

    def residuals(self, theta_deg: np.ndarray, rays: np.ndarray, v_top: np.ndarray, cls: np.ndarray) -> np.ndarray:
        """(N,) predicted minus observed top row (px) of each cone for attitude (pitch, roll) in degrees.

        NaN where the foot ray misses the ground under that attitude.
        """
        return self._residuals_batch(np.asarray(theta_deg, dtype=np.float64).reshape(1, 2), rays, v_top, cls)[0]

    def _residuals_batch(self, thetas_deg: np.ndarray, rays: np.ndarray, v_top: np.ndarray, cls: np.ndarray) -> np.ndarray:
        """(k, 2) attitudes -> (k, N) residuals, all in one vectorised pass."""
        R_att = np.stack([attitude_rotation(t[0], t[1]) for t in thetas_deg])  # (k, 3, 3)
        R_F_C = R_att @ self.R_F_C0
        p = R_att @ self.p0  # (k, 3)
        d = rays @ R_F_C.transpose(0, 2, 1)  # (k, N, 3) in rear_axle
        dz = d[:, :, 2]
        hits = dz < -1e-9
        t = -p[:, 2:3] / np.where(hits, dz, -1.0)
        away = t[:, :, None] * d[:, :, :2]  # ground point minus camera, (k, N, 2)
        dist = np.sqrt(np.sum(away * away, axis=2, keepdims=True))
        reach = dist + (self.off[cls] + self._tip_r_m[cls])[None, :, None]
        top = away * (reach / dist)  # tip (xy) minus camera
        P = np.concatenate([top, (self._height_m[cls][None, :] - p[:, 2:3])[:, :, None]], axis=2)
        Pc = P @ R_F_C  # (k, N, 3) optical frame
        v = self.K[1, 1] * Pc[:, :, 1] / Pc[:, :, 2] + self.K[1, 2]
        return np.where(hits, v - v_top, np.nan)

    # -- fit --------------------------------------------------------------------------------------
    def fit(self, boxes: np.ndarray, class_ids: np.ndarray, start_deg: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray, int] | None:
        """One frame's robust fit: ``(theta (2,) deg, covariance (2, 2) deg^2, cones used)``, or None
        with fewer than ``min_cones`` usable cones. ``boxes`` (N, 4) full-image px (pixel edges);
        ``start_deg``: where to linearise first (the filter's prediction; default zero)."""
        c = self.cfg
        boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        class_ids = np.asarray(class_ids, dtype=np.intp).ravel()
        sel = self._select(boxes, class_ids)
        if int(sel.sum()) < c.min_cones:
            return None
        rays, v_top, cls = self._prepare(boxes[sel], class_ids[sel])
        h = boxes[sel, 3] - boxes[sel, 1]
        sigma = np.sqrt(2.0 * c.sigma_px**2 + (c.sigma_rel * h) ** 2)
        theta = np.zeros(2) if start_deg is None else np.clip(np.asarray(start_deg, dtype=np.float64), -2.0, 2.0)
        eps = 0.05
        lam = np.eye(2) / c.prior_sigma_deg**2
        for outer in range(self.cfg.outer_iterations):
            rr = self._residuals_batch(theta + np.array([[0.0, 0.0], [eps, 0.0], [0.0, eps]]), rays, v_top, cls)
            r0 = rr[0]
            J = ((rr[1:] - r0) / eps).T
            ok = np.isfinite(r0) & np.all(np.isfinite(J), axis=1)
            if int(ok.sum()) < c.min_cones:
                return None
            r0o, Jo, so = r0[ok], J[ok], sigma[ok]
            if outer == 0:  # robust start: weighted median of single-cone pitch estimates
                jp = Jo[:, 0]
                fin = np.abs(jp) > 1e-9
                single = -r0o[fin] / jp[fin]
                wts = (jp[fin] / so[fin]) ** 2
                if not np.any(fin):
                    return None
                delta = np.array([_weighted_median(single, wts), 0.0])
            else:
                delta = np.zeros(2)
            delta = _irls(r0o, Jo[:, 0].copy(), Jo[:, 1].copy(), 1.0 / so, delta, theta, 1.0 / c.prior_sigma_deg**2,
                          1.0 / c.cauchy_c)
            theta = theta + delta
            if np.max(np.abs(delta)) < 0.3:  # small step: the linearisation holds (error ~1e-3 deg)
                break
        e = (r0o + Jo @ delta) / so
        w = 1.0 / (1.0 + (e / c.cauchy_c) ** 2)
        inl = np.abs(e) <= 3.0 * c.cauchy_c
        n_used = int(inl.sum())
        if n_used < c.min_cones:
            return None
        A = Jo.T @ ((w / so**2)[:, None] * Jo) + lam
        scale = max(1.0, float(np.sum(w[inl] * e[inl] ** 2) / max(n_used - 2, 1)))
        return theta, _inv2(A) * scale, n_used

    def single_frame(self, boxes: np.ndarray, class_ids: np.ndarray) -> Attitude:
        """The attitude of one frame on its own (no history): the fit with its covariance, or zero with
        the prior's uncertainty when the fit has too few cones or is rejected (both counted)."""
        res = self.fit(boxes, class_ids)
        s0 = self.cfg.prior_sigma_deg
        if res is None:
            self.counts.too_few += 1
            return Attitude(0.0, 0.0, s0, s0, "hold", 0)
        if np.any(np.abs(res[0]) > self.cfg.max_abs_deg):
            self.counts.rejected += 1
            return Attitude(0.0, 0.0, s0, s0, "hold", 0)
        self.counts.fitted += 1
        sd = np.sqrt(np.diag(res[1]))
        return Attitude(float(res[0][0]), float(res[0][1]), float(sd[0]), float(sd[1]), "image", res[2])

    def update(self, boxes: np.ndarray, class_ids: np.ndarray) -> Attitude:
        """Fit this frame, fold it into the filter, return the attitude to map this frame with."""
        c = self.cfg
        self.x = self.x * c.decay  # predict: random walk decaying to zero
        self.P = self.P * c.decay**2 + np.eye(2) * c.process_sigma_deg**2
        res = self.fit(boxes, class_ids, self.x + self.bias)
        source, n = "hold", 0
        if res is None:
            self.counts.too_few += 1
            wm = self.motion_weight(None, None)
        elif np.any(np.abs(res[0]) > c.max_abs_deg):
            self.counts.rejected += 1
            wm = self.motion_weight(None, None)
        else:
            z, Rz, n = res
            wm = self.motion_weight(z, Rz)
            z = self.debias(z)
            G = self.P @ _inv2(self.P + Rz)
            self.x = self.x + G @ (z - self.x)
            self.P = (np.eye(2) - G) @ self.P
            self.counts.fitted += 1
            source = "image"
        sd = self.still_sigma(np.sqrt(np.diag(self.P)), wm)
        x = self.x * wm
        return Attitude(float(x[0]), float(x[1]), float(sd[0]), float(sd[1]), source, n)


def _irls(r0: np.ndarray, j0: np.ndarray, j1: np.ndarray, inv_s: np.ndarray, delta: np.ndarray, theta: np.ndarray,
          lam: float, inv_c: float, iterations: int = 4) -> np.ndarray:
    """Cauchy-weighted least squares of the linearised residuals ``r0 + j0 d0 + j1 d1`` (px, 1/sigma
    ``inv_s``) with the prior ``lam (theta + d)^2`` around zero; returns the step ``d`` (2,) degrees."""
    d0, d1 = float(delta[0]), float(delta[1])
    t0, t1 = float(theta[0]), float(theta[1])
    inv_s2 = inv_s * inv_s
    for _ in range(iterations):
        e = (r0 + j0 * d0 + j1 * d1) * inv_s * inv_c
        w = inv_s2 / (1.0 + e * e)
        wj0, wj1 = w * j0, w * j1
        a00, a01, a11 = float(wj0 @ j0) + lam, float(wj0 @ j1), float(wj1 @ j1) + lam
        b0, b1 = -float(wj0 @ r0) - lam * t0, -float(wj1 @ r0) - lam * t1
        det = a00 * a11 - a01 * a01
        d0, d1 = (a11 * b0 - a01 * b1) / det, (a00 * b1 - a01 * b0) / det
    return np.array([d0, d1])


def _inv3(A: np.ndarray) -> np.ndarray:
    """Inverse of a 3x3 matrix (adjugate over determinant) without LAPACK's call overhead."""
    (a, b, c), (d, e, f), (g, h, i) = A.tolist()
    adj = np.array([[e * i - f * h, c * h - b * i, b * f - c * e],
                    [f * g - d * i, a * i - c * g, c * d - a * f],
                    [d * h - e * g, b * g - a * h, a * e - b * d]])
    return adj / (a * adj[0, 0] + b * adj[1, 0] + c * adj[2, 0])


def _inv2(A: np.ndarray) -> np.ndarray:
    """Inverse of a 2x2 matrix without LAPACK's call overhead."""
    a, b, c, d = A.ravel().tolist()
    det = a * d - b * c
    return np.array([[d, -b], [-c, a]]) / det


def _weighted_median(x: np.ndarray, w: np.ndarray) -> float:
    order = np.argsort(x)
    cw = np.cumsum(w[order])
    return float(x[order][np.searchsorted(cw, 0.5 * cw[-1])])


def attitude_estimator(mapper, mode: str | None, imu: "ImuAttitude | None" = None):
    """``(mode, estimator)`` for a :class:`~cone_perception.mapping.ConeMapper`, a requested mode
    (None or "" = the default of :func:`default_attitude_mode`) and an IMU source (or None); the
    estimator is None for ``fixed``, an :class:`ImageAttitude` for ``image``, a :class:`FusedAttitude`
    for ``imu`` and ``fused``.

    Raises :class:`ConfigError` for an unknown mode, ``image``/``fused`` without a mount pose, or
    ``imu``/``fused`` without an IMU source.
    """
    from .errors import ConfigError

    calib = mapper.calib
    mode = mode or default_attitude_mode(calib.has_attitude_model, imu is not None)
    if mode not in ATTITUDE_MODES:
        raise ConfigError("attitude", None, f"unknown attitude mode {mode!r}; known: {', '.join(ATTITUDE_MODES)}")
    if mode == "fixed":
        return mode, None
    if not calib.has_attitude_model:
        raise ConfigError(calib.source, "mount_pose" if calib.mount_pose is None else "camera_matrix",
                          f"attitude {mode!r} needs mount_pose and camera_matrix in the calibration")
    if mode == "image":
        return mode, mapper.image_attitude()
    if imu is None:
        raise ConfigError("attitude", None, f"{mode!r} needs an IMU (none given: no /imu topic in the bag?)")
    return mode, FusedAttitude(mapper.image_attitude(), imu, use_image=(mode == "fused"))


def attitude_for_boxes(estimator, records: np.ndarray, stamp_ns: int | None = None) -> Attitude:
    """The attitude to map one frame's ``BOX_DTYPE`` records with (:data:`FIXED` without an estimator);
    ``stamp_ns``: the frame's capture stamp (for the IMU)."""
    if estimator is None:
        return FIXED
    b = np.column_stack([records["u1"], records["v1"], records["u2"], records["v2"]]).astype(np.float64)
    if isinstance(estimator, FusedAttitude):
        return estimator.update(b, records["class_id"].astype(np.intp), stamp_ns)
    return estimator.update(b, records["class_id"].astype(np.intp))


def default_attitude_mode(has_mount_pose: bool, has_imu: bool = False) -> str:
    """The issue's default: ``fused`` with an IMU, else ``image`` with a mount pose, else ``fixed``."""
    if has_imu and has_mount_pose:
        return "fused"
    if has_imu:
        return "imu"
    return "image" if has_mount_pose else "fixed"


@dataclass
class AttitudeReport:
    """How good the attitude of a replay was: per frame the attitude used against the true one (where
    the bag has it), and per distance group whether the cones' covariance (attitude uncertainty
    included) matches their actual error."""

    err_pitch: list = None  # per frame with truth, degrees (estimate - truth)
    err_roll: list = None
    sources: dict = None
    pair_range: list = None  # per matched cone: true range (m), error (m), predicted 1-sigma (m)
    pair_err: list = None
    pair_sigma: list = None

    def __post_init__(self):
        for k in ("err_pitch", "err_roll", "pair_range", "pair_err", "pair_sigma"):
            setattr(self, k, [])
        self.sources = {}

    def add_frame(self, att: Attitude, truth_deg: tuple[float, float] | None, cones: np.ndarray,
                  truth: np.ndarray | None = None, pairs: list | None = None) -> None:
        """``truth_deg`` (pitch, roll) or None; ``pairs`` from :meth:`LocalisationReport.add_frame`."""
        self.sources[att.source] = self.sources.get(att.source, 0) + 1
        if truth_deg is not None:
            self.err_pitch.append(att.pitch_deg - truth_deg[0])
            self.err_roll.append(att.roll_deg - truth_deg[1])
        for i, j, d in pairs or ():
            c = cones[i]
            cov = np.array([[c["cov_xx"], c["cov_xy"]], [c["cov_xy"], c["cov_yy"]]], dtype=np.float64)
            self.pair_range.append(float(np.hypot(truth["x"][j], truth["y"][j])))
            self.pair_err.append(float(d))
            self.pair_sigma.append(float(np.sqrt(max(np.trace(cov), 0.0))))

    def summary(self) -> dict:
        from .evaluation import DISTANCE_GROUPS, distance_group

        out: dict = {"frames_by_source": dict(self.sources)}
        if self.err_pitch:
            ep, er = np.abs(self.err_pitch), np.abs(self.err_roll)
            out.update(frames_with_truth=len(ep), median_abs_err_pitch_deg=float(np.median(ep)),
                       median_abs_err_roll_deg=float(np.median(er)), p90_abs_err_pitch_deg=float(np.percentile(ep, 90)),
                       p90_abs_err_roll_deg=float(np.percentile(er, 90)))
        groups = {}
        if self.pair_range:
            g = distance_group(np.array(self.pair_range))
            e, s = np.array(self.pair_err), np.array(self.pair_sigma)
            for k, (name, _, _) in enumerate(DISTANCE_GROUPS):
                sel = g == k
                if sel.any():
                    groups[name] = {"n": int(sel.sum()), "median_err_m": float(np.median(e[sel])),
                                    "median_sigma_m": float(np.median(s[sel])),
                                    "within_2sigma": float(np.mean(e[sel] <= 2 * s[sel]))}
        out["groups"] = groups
        return out


def format_attitude_report(summary: dict) -> str:
    """Plain text of :meth:`AttitudeReport.summary`."""
    lines = ["attitude: frames by source " + ", ".join(f"{k} {v}" for k, v in sorted(summary["frames_by_source"].items()))]
    if "median_abs_err_pitch_deg" in summary:
        lines.append(f"attitude error vs truth ({summary['frames_with_truth']} frames): median |pitch| "
                     f"{summary['median_abs_err_pitch_deg']:.3f} deg (p90 {summary['p90_abs_err_pitch_deg']:.3f}), "
                     f"median |roll| {summary['median_abs_err_roll_deg']:.3f} deg (p90 {summary['p90_abs_err_roll_deg']:.3f})")
    if summary["groups"]:
        lines.append(f"{'group':<16}{'matched':>8}{'med err':>9}{'med 1-sigma':>12}{'err<=2sigma':>12}  (sigma: sqrt trace of the cone covariance, attitude included)")
        for name, s in summary["groups"].items():
            lines.append(f"{name:<16}{s['n']:>8}{s['median_err_m']:>9.3f}{s['median_sigma_m']:>12.3f}{s['within_2sigma']:>12.2f}")
    return "\n".join(lines)



# -- IMU --------------------------------------------------------------------------------------------
#: An IMU quaternion whose norm is farther than this from 1 is dropped.
QUAT_NORM_TOL = 0.01
#: An IMU sample older than this at a frame's stamp is not used for that frame.
IMU_MAX_AGE_NS = 100_000_000


def rpy_from_quaternion(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """(roll, pitch, yaw) radians of a unit quaternion, R = Rz(yaw) Ry(pitch) Rx(roll) (REP 103)."""
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


@dataclass
class ImuCounts:
    """IMU messages used and dropped by cause, and frames without a fresh IMU sample."""

    used: int = 0
    dropped_nan: int = 0
    dropped_quaternion_norm: int = 0
    dropped_out_of_order: int = 0
    stale_at_frame: int = 0

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


class ImuAttitude:
    """Body attitude from an IMU's orientation, relative to the rest attitude (the IMU's reading on
    the level ground of the calibration, ``rest_deg`` = (pitch, roll)), interpolated to frame stamps.

    The IMU frame's axes are the ``rear_axle`` axes (mount it so, or rotate before).
    """

    def __init__(self, rest_deg: tuple[float, float] = (0.0, 0.0), max_age_ns: int = IMU_MAX_AGE_NS,
                 sigma_deg: float = 0.1, keep: int = 200):
        self.rest = np.asarray(rest_deg, dtype=np.float64)
        self.max_age_ns = int(max_age_ns)
        self.sigma_deg = float(sigma_deg)
        self.keep = keep
        self.stamps: list[int] = []
        self.values: list[np.ndarray] = []  # (pitch, roll) degrees relative to rest
        self.counts = ImuCounts()

    def add(self, stamp_ns: int, quat_xyzw) -> bool:
        """Add one IMU orientation; returns False (and counts why) for a NaN, a quaternion far from unit
        length, or a stamp older than the last one."""
        q = np.asarray(quat_xyzw, dtype=np.float64)
        if q.shape != (4,) or not np.all(np.isfinite(q)):
            self.counts.dropped_nan += 1
            return False
        if abs(float(np.linalg.norm(q)) - 1.0) > QUAT_NORM_TOL:
            self.counts.dropped_quaternion_norm += 1
            return False
        if self.stamps and stamp_ns < self.stamps[-1]:
            self.counts.dropped_out_of_order += 1
            return False
        roll, pitch, _ = rpy_from_quaternion(*(q / np.linalg.norm(q)))
        self.stamps.append(int(stamp_ns))
        self.values.append(np.degrees([pitch, roll]) - self.rest)
        if len(self.stamps) > self.keep:
            del self.stamps[: -self.keep], self.values[: -self.keep]
        self.counts.used += 1
        return True

    def at(self, stamp_ns: int | None) -> np.ndarray | None:
        """(pitch, roll) degrees at ``stamp_ns``: interpolated between the samples around it, else the
        newest one before it; None (counted) without a sample within ``max_age_ns``."""
        if stamp_ns is None or not self.stamps:
            self.counts.stale_at_frame += 1
            return None
        i = bisect.bisect_right(self.stamps, stamp_ns)  # first sample after the stamp
        if i == 0:  # every sample is newer than the frame
            if self.stamps[0] - stamp_ns <= self.max_age_ns:
                return self.values[0].copy()
            self.counts.stale_at_frame += 1
            return None
        t0, v0 = self.stamps[i - 1], self.values[i - 1]
        if i < len(self.stamps):
            t1, v1 = self.stamps[i], self.values[i]
            if t1 - t0 <= 2 * self.max_age_ns and t1 > t0:
                return v0 + (v1 - v0) * ((stamp_ns - t0) / (t1 - t0))
        if stamp_ns - t0 > self.max_age_ns:
            self.counts.stale_at_frame += 1
            return None
        return v0.copy()


#: Rest capture (``cone-perception imu-rest``): at least this many usable samples, and a car that stands
#: still: angular rate and acceleration (each axis) and the pitch / roll readings scatter at most this much
#: (1-sigma over the window; an IMU's noise is a few tenths of a degree/s and a few cm/s^2).
IMU_REST_MIN_SAMPLES = 20
IMU_REST_MAX_RATE_SD_DPS = 0.5
IMU_REST_MAX_ACCEL_SD = 0.2
IMU_REST_MAX_ANGLE_SD_DEG = 0.1


@dataclass
class ImuRest:
    """The IMU's pitch and roll (degrees) with the car at rest: the ``imu_rest_deg`` of the nodes."""

    pitch_deg: float
    roll_deg: float
    sd_pitch_deg: float
    sd_roll_deg: float
    n: int  # samples used
    seconds: float  # the window they span
    rate_sd_dps: float  # largest 1-sigma of the angular rate over the three axes (NaN without rates)
    accel_sd: float  # m/s^2, likewise
    dropped: dict  # IMU messages dropped by cause (NaN, quaternion norm, out of order)


def imu_rest(stamps_ns, quats_xyzw, rates_rad_s=None, accels=None, source: str = "imu") -> ImuRest:
    """The rest attitude from IMU samples of a car standing still: ``stamps_ns`` (N,), ``quats_xyzw``
    (N, 4), optional ``rates_rad_s`` (N, 3) and ``accels`` (N, 3) m/s^2. Samples with NaN or a quaternion
    off unit length are dropped (as :meth:`ImuAttitude.add`, counted).

    Raises :class:`ConfigError` (naming ``source``) with too few samples or when the car moved.
    """
    from .errors import ConfigError

    acc = ImuAttitude(keep=1 << 30)
    ok = np.array([acc.add(int(t), q) for t, q in zip(stamps_ns, quats_xyzw)], dtype=bool)
    dropped = {k.removeprefix("dropped_"): v for k, v in acc.counts.as_dict().items() if k.startswith("dropped_") and v}
    why = f" (dropped: {', '.join(f'{k} {v}' for k, v in dropped.items())})" if dropped else ""
    n = int(ok.sum())
    if n < IMU_REST_MIN_SAMPLES:
        raise ConfigError(source, None, f"only {n} usable IMU samples in the window, need >= {IMU_REST_MIN_SAMPLES}{why}")
    v = np.asarray(acc.values)
    sd = v.std(axis=0)

    def _sd(x, scale=1.0):
        if x is None:
            return float("nan")
        x = np.asarray(x, dtype=np.float64)[ok] * scale
        x = x[np.all(np.isfinite(x), axis=1)]
        return float(np.max(x.std(axis=0))) if len(x) > 1 else float("nan")

    rate_sd, accel_sd = _sd(rates_rad_s, 180.0 / math.pi), _sd(accels)
    moved = []
    if rate_sd > IMU_REST_MAX_RATE_SD_DPS:
        moved.append(f"angular rate scatters {rate_sd:.2f} deg/s (limit {IMU_REST_MAX_RATE_SD_DPS})")
    if accel_sd > IMU_REST_MAX_ACCEL_SD:
        moved.append(f"acceleration scatters {accel_sd:.3f} m/s^2 (limit {IMU_REST_MAX_ACCEL_SD})")
    if np.max(sd) > IMU_REST_MAX_ANGLE_SD_DEG:
        moved.append(f"pitch / roll scatter {sd[0]:.3f} / {sd[1]:.3f} deg (limit {IMU_REST_MAX_ANGLE_SD_DEG})")
    if moved:
        raise ConfigError(source, None, "the car moved in the window: " + "; ".join(moved)
                          + " (1-sigma over the window; choose a still part with --start / --seconds)")
    m = v.mean(axis=0)
    return ImuRest(float(m[0]), float(m[1]), float(sd[0]), float(sd[1]), n,
                   (acc.stamps[-1] - acc.stamps[0]) / 1e9, rate_sd, accel_sd, dropped)


@dataclass(frozen=True)
class GroundGate:
    """When ``fused`` applies the image's ground offset (the road ahead against the IMU): only as far as
    the image fits show it, per axis (pitch, roll). Two hypotheses: the road ahead has the calibration
    ground's grade (offset exactly zero, prior probability ``p_flat``) or it changes grade (offset
    spread ``grade_deg``); the offset estimate's error is the filter's plus the fits' slowly varying
    part (``slow_deg``, which the filter cannot average away). The evidence is the offset's mean over
    ``evidence_frames`` (the fits' error comes in excursions of a second or two; a grade change lasts
    longer), or the current offset where it alone is overwhelming (prior ``p_flat_instant``). The offset
    used is the filter's times the probability of a grade change. Once the fits have shown one, the
    gate stays open (a latch decaying over ``hold_frames``): a road that changes grade passes zero
    offset now and then. With the IMU's rest attitude captured, ``fused`` so keeps the IMU's accuracy
    on flat ground (docs/benchmarks.md, "Fused attitude with the ground gate")."""

    slow_deg: tuple[float, float] = (0.03, 0.03)
    grade_deg: tuple[float, float] = (0.5, 0.6)
    p_flat: float = 0.5
    evidence_frames: float = 20.0
    p_flat_instant: float = 0.99
    hold_frames: float = 1000.0


def _log_odds(p_flat: float) -> float:
    return math.log((1.0 - p_flat) / p_flat)


class FusedAttitude:
    """Attitude from the IMU (``imu``), or the IMU plus a slowly varying ground offset estimated from
    the image fits (``fused``: the IMU feels the body against gravity, not a grade change of the road
    ahead, which the image sees). Without a fresh IMU sample a frame gets the image estimate (counted
    in :attr:`ImuAttitude.counts`).

    The image fit's roll bias is learnt against the IMU: the long-run mean of (roll fit minus IMU
    roll) is the fit's bias (less the IMU's own), since the road's cross grade averages out over a
    lap; a running mean shrunk towards zero by ``roll_bias_prior_frames`` pseudo-frames, an
    exponential mean of the image config's ``bias_tau_frames`` once that many fits are in (tau 0:
    off). The IMU takes the body's own roll (cornering) out of that mean, which the
    image-only bias state (the mean of the raw fits) cannot do, so it may learn faster.

    The ground offset is applied through ``gate`` (:class:`GroundGate`; None: always in full)."""

    def __init__(self, image: ImageAttitude, imu: ImuAttitude, use_image: bool = True,
                 offset_process_sigma_deg: float = 0.05, roll_bias_prior_frames: float = 30.0,
                 gate: "GroundGate | None" = GroundGate()):
        self.image, self.imu, self.use_image = image, imu, use_image
        self.gate = gate  # None: the image's ground offset always applied in full
        self.g_mean, self.gate_latch = np.zeros(2), np.zeros(2)
        if gate is not None:  # its constants: squared spreads, prior log-odds (mean, instant), latch decay, mean length
            self._gate_k = (np.square(gate.slow_deg), np.square(gate.grade_deg), _log_odds(gate.p_flat),
                            _log_odds(gate.p_flat_instant), 1.0 - 1.0 / gate.hold_frames, max(gate.evidence_frames, 1.0))
        self.q = offset_process_sigma_deg**2
        self.g = np.zeros(2)  # ground offset (total attitude minus IMU), degrees
        self.Pg = np.eye(2) * image.cfg.prior_sigma_deg**2
        self.roll_bias_prior = float(roll_bias_prior_frames)
        self.roll_bias = 0.0  # the image fit's roll bias against the IMU, degrees
        self.n_roll_bias = 0

    @property
    def counts(self) -> AttitudeCounts:
        return self.image.counts

    def debias_roll(self, d_roll: float) -> np.ndarray:
        """Fold one accepted fit's roll minus the IMU's (degrees) into the roll bias; return the bias
        (pitch, roll) to take off the fit."""
        tau = self.image.cfg.bias_tau_frames
        if tau > 0:
            self.n_roll_bias += 1
            self.roll_bias += (d_roll - self.roll_bias) / min(self.n_roll_bias + self.roll_bias_prior, tau)
        return np.array([0.0, self.roll_bias])

    def step_ground_gate(self) -> tuple[np.ndarray, np.ndarray]:
        """One frame's step of the ground gate: the ground offset to add to the IMU's attitude and its
        variance, per axis (degrees). Call once per frame (the evidence mean and the latch step per call)."""
        var = np.diag(self.Pg).copy()
        if self.gate is None:
            return self.g.copy(), var
        slow2, grade2, lo_mean, lo_now, decay, n_mean = self._gate_k
        s2 = var + slow2  # the offset's error: the filter's and the fits' slow one
        t2 = grade2 + s2  # its spread where the road does change grade
        self.g_mean += (self.g - self.g_mean) / n_mean

        def log_bf(g):  # grade change : flat, per axis
            return 0.5 * np.log(s2 / t2) + 0.5 * g**2 * (1.0 / s2 - 1.0 / t2)

        def prob(log_odds):
            return 1.0 / (1.0 + np.exp(-np.clip(log_odds, -50.0, 50.0)))

        b_mean, b_now = log_bf(self.g_mean), log_bf(self.g)
        w_mean, w_now = prob(lo_mean + b_mean), prob(lo_now + b_now)
        w = np.maximum(w_mean, w_now)
        shown = np.where(w_now > w_mean, b_now, b_mean) > 0  # the evidence favours a grade change
        self.gate_latch = np.maximum(self.gate_latch * decay, np.where(shown, w, 0.0))
        w = np.maximum(w, self.gate_latch)
        return w * self.g, w * var + w * (1.0 - w) * self.g**2  # the mixture's mean and variance

    def update(self, boxes: np.ndarray, class_ids: np.ndarray, stamp_ns: int | None) -> Attitude:
        body = self.imu.at(stamp_ns)
        if body is None:
            return self.image.update(boxes, class_ids)
        s_imu = self.imu.sigma_deg
        if not self.use_image:
            return Attitude(float(body[0]), float(body[1]), s_imu, s_imu, "imu", 0)
        self.Pg = self.Pg + np.eye(2) * self.q
        bias = np.array([0.0, self.roll_bias])
        res = self.image.fit(boxes, class_ids, body + self.g + bias)
        n, wm = 0, None
        if res is None:
            self.image.counts.too_few += 1
        elif np.any(np.abs(res[0]) > self.image.cfg.max_abs_deg):
            self.image.counts.rejected += 1
        else:
            z, Rz, n = res
            wm = self.image.motion_weight(z, Rz)
            z = z - self.debias_roll(float(z[1] - body[1]))
            S = self.Pg + Rz + np.eye(2) * s_imu**2
            G = self.Pg @ _inv2(S)
            self.g = self.g + G @ (z - body - self.g)
            self.Pg = (np.eye(2) - G) @ self.Pg
            self.image.counts.fitted += 1
        if wm is None:
            wm = self.image.motion_weight(None, None)
        g, var_g = self.step_ground_gate()
        att = (body + g) * wm  # still body and ground (the image's still test): the calibration's zero
        self.image.x = att.copy()  # keeps the image filter warm for frames without IMU
        sd = self.image.still_sigma(np.sqrt(var_g + s_imu**2), wm)
        return Attitude(float(att[0]), float(att[1]), float(sd[0]), float(sd[1]), "fused", n)


def attitude_plot(path, stamps_ns: list[int], used: list[Attitude], truth: dict[int, tuple[float, float]] | None = None,
                  title: str = ""):
    """PNG of the attitude used per frame (pitch and roll, degrees, with its 1-sigma band) against
    time, and the true attitude where known (``stamp -> (pitch, roll)``). Returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t0 = stamps_ns[0] if stamps_ns else 0
    t = (np.asarray(stamps_ns, dtype=np.float64) - t0) / 1e9
    fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    for ax, k, name in ((axes[0], 0, "pitch (+ nose down)"), (axes[1], 1, "roll (+ right side down)")):
        v = np.array([(a.pitch_deg, a.roll_deg)[k] for a in used])
        sd = np.array([(a.sigma_pitch_deg, a.sigma_roll_deg)[k] for a in used])
        ax.fill_between(t, v - sd, v + sd, color="tab:blue", alpha=0.2, lw=0, label="used +- 1 sigma")
        ax.plot(t, v, color="tab:blue", lw=1.2, label="used")
        if truth:
            tt = [(s - t0) / 1e9 for s in stamps_ns if s in truth]
            ax.plot(tt, [truth[s][k] for s in stamps_ns if s in truth], color="k", lw=1, ls="--", label="true")
        hold = np.array([a.source == "hold" for a in used])
        if hold.any():
            ax.plot(t[hold], v[hold], "x", color="tab:red", ms=4, label="held (no fit)")
        ax.set_ylabel(f"{name}, deg")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[1].set_xlabel("time, s")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
