"""The attitude offset fitted per frame from the cone boxes (:class:`ImageAttitude`).

Cones are objects of known size standing on the ground: the foot point of a box gives its range
through the ground plane (which depends on the attitude), its height gives the range independently
of the ground. For an attitude hypothesis the foot point is mapped to the ground, the cone's tip is
placed above it and projected; the residual is predicted minus observed top row of the box (px). A
robust (Cauchy) weighted least-squares fit of (pitch, roll) with a weak prior around zero, started
from the weighted median of single-cone pitch estimates, then a Kalman filter across frames (random
walk decaying to zero): frames with too few usable cones hold the last estimate, decaying to zero; a
fit beyond :data:`~cone_perception.attitude.model.MAX_ABS_DEG`, or whose residuals are larger than
its cone model explains, is rejected and counted; a frame whose estimate is too uncertain to beat the
calibrated H is mapped with the calibration (counted). With a measured box model of the detector
(:mod:`.boxes`) the boxes are first corrected to the labelled cones' (the far strip's boxes of a model of its
own through that model's: :attr:`ImageAttitudeConfig.far_reading`), and the filter reads each box with its
cone's height averaged over the frames it was followed (:mod:`.sizes`, ``size_frames``). ROS-free.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..classes import CONE_SIZE_M, NUM_CLASSES
from ..geometry.camera import MountPose
from ..geometry.homography import undistort_pixels
from ..geometry.linalg import inv2
from .boxes import BoxModel, BoxReading, box_top_extra_px, range_cuts, read_boxes
from .model import MAX_ABS_DEG, Attitude, AttitudeCounts, FrameClock, RunningBias, attitude_rotation
from .sizes import SizeTrackConfig, SizeTracks
from .still import StillTest


@dataclass
class ImageAttitudeConfig:
    """Tuning of :class:`ImageAttitude` (degrees, px, frames)."""

    min_cones: int = 3  # usable cones for a fit
    min_height_px: float = 8.0  # boxes shorter than this tell little and are often wrong
    max_range_m: float = 20.0  # cones farther (by their size) are left out
    far_max_range_m: float | None = 25.0  # the far strip's boxes' (full resolution: 12 px at 25 m); None: max_range_m
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
    #: the frame interval (s) the settings "per frame" and "frames" are given for: other stamps scale each update by
    #: their own interval (process variance, decay, the still test's and bias's windows); 0 = per frame at any rate
    frame_s: float = 0.05
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
    still_min_frames: float = 10.0  # fits before the test judges (until then: moving, or see still_start_sigmas)
    #: until the test judges, a fit within this many of its own sigmas of zero (pitch and roll) is taken as a still
    #: body (the calibration's zero), fully moving one sigma further; 0 = off (moving)
    still_start_sigmas: float = 1.0
    still_ratio: float = 1.3
    still_ramp: float = 0.4
    #: ... and only while the fits' mean stays within this (degrees, pitch and roll; ramp of half of it):
    #: a body standing still on a slope keeps its estimate
    still_max_mean_deg: float = 0.5
    #: the detector's boxes against the labelled cones (:class:`~cone_perception.attitude.boxes.BoxModel`,
    #: measured on real frames, stored beside the model file): boxes are corrected to the labels' before the
    #: fit, and ``top_bias_extra_px`` (the rendered drives' table) is not applied. None: the synthetic case
    box_model: BoxModel | None = None
    #: how the far strip's boxes are read where its network is not the band's (``far_model``, issue 26f:
    #: :class:`~cone_perception.attitude.boxes.BoxReading`); None: as the band's (``box_model`` / the table)
    far_reading: BoxReading | None = None
    #: per frame, the image attitude is used only where it beats the calibrated H (:meth:`ImageAttitude.trusted`):
    #: at least ``trust_min_cones`` cones in the fit, the fit's residuals no more than ``trust_max_scale``
    #: times their expected size (1.4826 times the median absolute normalised residual), and the estimate's
    #: 1-sigma below ``trust_max_sigma_deg``; otherwise the frame is mapped with the calibration's H (counted)
    trust_min_cones: int = 3
    trust_max_scale: float = 2.5
    trust_max_sigma_deg: float = 1.0
    #: each cone's box height averaged over the frames it is followed (:mod:`.sizes`; :meth:`ImageAttitude.update`
    #: only), with a measured ``box_model`` only: the rendered table's boxes have no scatter to average
    size_frames: bool = True
    size_rendered: bool = False  # average the rendered table's boxes too (measured worse: docs/benchmarks.md)
    size_tracks: SizeTrackConfig = SizeTrackConfig()
    #: cut by the feet too where the boxes are cut by their size (no averaging): a box whose foot maps (with the
    #: filter's prediction) beyond this x its range cut is left out whatever its height says; 0 = off
    feet_cut_factor: float = 1.5


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
        self.sizes = SizeTracks(self.p0[:2], self.cfg.size_tracks)
        self.reset()

    def reset(self) -> None:
        """Forget the filter state (a new drive)."""
        self.x = np.zeros(2)
        self.P = np.eye(2) * self.cfg.prior_sigma_deg**2
        # the fit's slowly varying bias (degrees), see ImageAttitudeConfig.bias_tau_frames
        self.bias_mean = RunningBias(self.cfg.bias_prior_frames, self.cfg.bias_tau_frames, np.zeros(2))
        self.still = StillTest(self.cfg)  # the still test on the fits
        self.clock = FrameClock(self.cfg.frame_s)  # this frame's length in frame_s (the updates scale by it)
        self.sizes.reset()

    def motion_weight(self, z: np.ndarray | None, Rz: np.ndarray | None, start_from_fit: bool = True) -> float:
        """Fold one fit into the still test; 1 = the body moves (use the estimate), 0 = still (use zero).
        ``start_from_fit``: before the test judges, the fit's own distance from zero decides
        (``still_start_sigmas``; False: moving, as ``fused`` wants it, whose IMU sees the body anyway)."""
        c = self.cfg
        if c.still_frames <= 0:
            return 1.0
        if z is not None:
            self.still.fold(z, np.diag(Rz), self.clock.k)
        if not self.still.judged:
            if c.still_start_sigmas <= 0 or z is None or not start_from_fit:
                return 1.0
            # not judged yet: this fit's own evidence that the body is off zero (a ramp of one sigma)
            return float(np.clip(np.max(np.abs(z) / np.sqrt(np.maximum(np.diag(Rz), 1e-12))) - c.still_start_sigmas, 0.0, 1.0))
        return self.still.verdict()

    def still_sigma(self, sd: np.ndarray, wm: float) -> np.ndarray:
        """(2,) 1-sigma (degrees) of the attitude used: the estimate's ``sd`` while the body moves; while it is
        still (``wm`` 0) how far from zero the recent fits say it may be (their mean and spread)."""
        if wm >= 1.0:
            return sd
        m1, m2 = self.still.m1, self.still.m2
        still = np.sqrt(m1**2 + np.maximum(m2 - m1**2, 0.0))
        return wm * sd + (1.0 - wm) * np.minimum(still, sd)

    def debias(self, z: np.ndarray) -> np.ndarray:
        """Fold one accepted fit ``z`` (2,) degrees into the bias estimate; return the fit less the bias."""
        if self.bias_mean.tau <= 0:
            return z
        self.bias_mean.fold(z, self.clock.k)
        if not self.cfg.bias_pitch:
            self.bias_mean.value[0] = 0.0
        return z - self.bias

    @property
    def bias(self) -> np.ndarray:
        """(2,) the fit's bias now (degrees; :meth:`debias`)."""
        return self.bias_mean.value

    # -- model ------------------------------------------------------------------------------------
    def _select(self, boxes: np.ndarray, class_ids: np.ndarray, by_size: bool = True, far: np.ndarray | None = None):
        """(N,) bool: standing, whole cones of a known size (``by_size``: within :func:`.range_cuts` by their height)."""
        c = self.cfg
        b = boxes
        known = (class_ids >= 0) & (class_ids < NUM_CLASSES)
        cls = np.where(known, class_ids, 0)
        hm = self._height_m[cls]
        w = np.maximum(b[:, 2] - b[:, 0], 1e-6)
        h = np.maximum(b[:, 3] - b[:, 1], 1e-6)
        aspect_ok = np.abs(np.log(w / h * (hm / self._base_m[cls]))) <= c.aspect_tol  # NaN (unknown size): False
        near = self.K[1, 1] * hm <= range_cuts(len(b), far, c.max_range_m, c.far_max_range_m) * h if by_size else True
        m = c.edge_margin_px
        inside = (b[:, 0] > m) & (b[:, 2] < self.W - m) & (b[:, 1] > self.band[0] + m) & (b[:, 3] < self.band[1] - m)
        return known & aspect_ok & (h >= c.min_height_px) & inside & near

    def _read(self, boxes: np.ndarray, far: np.ndarray | None):
        """Each box through its network's reading (:func:`~cone_perception.attitude.boxes.read_boxes`)."""
        c = self.cfg
        band = BoxReading(c.box_model, c.top_bias_extra_px if c.box_model is None else ())
        return read_boxes(boxes, far, band, c.far_reading, c.sigma_rel, self.counts)

    def _prepare(self, boxes: np.ndarray, class_ids: np.ndarray, top_extra: np.ndarray | None = None):
        """``top_extra``: (N,) px each box top stands above its cone's (:meth:`_read`); None: the band's reading."""
        u = 0.5 * (boxes[:, 0] + boxes[:, 2]) - 0.5  # pixel-edge -> pixel-centre coordinates
        foot = np.column_stack([u, boxes[:, 3] - 0.5])
        if top_extra is None:
            top_extra = box_top_extra_px(boxes[:, 3] - boxes[:, 1], () if self.cfg.box_model else self.cfg.top_bias_extra_px)
        top = np.column_stack([u, boxes[:, 1] - 0.5 + self.cfg.top_bias_px + top_extra])
        if self.dist is not None:
            foot = undistort_pixels(foot, self.K, self.dist)
            top = undistort_pixels(top, self.K, self.dist)
        rays = np.column_stack([foot, np.ones(len(foot))]) @ self.Kinv.T  # (N, 3) optical frame
        return rays, top[:, 1], class_ids

    def _feet_batch(self, thetas_deg: np.ndarray, rays: np.ndarray):
        """(k, 2) attitudes -> the camera's rotation (k, 3, 3) and position (k, 3) in rear_axle, each foot ray's
        ground point minus the camera's position (k, N, 2) and whether the ray hits the ground (k, N)."""
        R_att = np.stack([attitude_rotation(t[0], t[1]) for t in thetas_deg])  # (k, 3, 3)
        R_F_C = R_att @ self.R_F_C0
        p = R_att @ self.p0  # (k, 3)
        d = rays @ R_F_C.transpose(0, 2, 1)  # (k, N, 3) in rear_axle
        dz = d[:, :, 2]
        hits = dz < -1e-9
        t = -p[:, 2:3] / np.where(hits, dz, -1.0)
        return R_F_C, p, t[:, :, None] * d[:, :, :2], hits

    def model_heights(self, xy_m: np.ndarray, cls: np.ndarray) -> np.ndarray:
        """(N,) undistorted px from the foot row up to the tip's row of cones of classes ``cls`` (N,) whose centres
        stand at rear_axle ``xy_m`` (N, 2) m (:meth:`centres`), at zero attitude (the fit's cone model); NaN behind
        the camera."""
        away = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2) - self.p0[:2]
        dist = np.maximum(np.hypot(away[:, 0], away[:, 1]), 1e-6)
        foot = away * ((dist - self.off[cls]) / dist)[:, None]
        tip = away * ((dist + self._tip_r_m[cls]) / dist)[:, None]
        P = np.stack([np.column_stack([foot, np.full(len(foot), -self.p0[2])]),
                      np.column_stack([tip, self._height_m[cls] - self.p0[2]])])  # (2, N, 3) minus camera
        Pc = P @ self.R_F_C0  # optical frame
        with np.errstate(invalid="ignore", divide="ignore"):
            v = self.K[1, 1] * Pc[:, :, 1] / Pc[:, :, 2]
        return np.where(np.all(Pc[:, :, 2] > 1e-6, axis=0), v[0] - v[1], np.nan)

    def centres(self, feet_m: np.ndarray, cls: np.ndarray) -> np.ndarray:
        """(..., N, 2) rear_axle ground points of the cones' feet -> their centres (m): each moved away from the
        camera by its class's foot offset, as the fit's cone model (and the mapping) places them. A box's foot is
        the cone's nearest edge, which turns with the cone's bearing as the car passes; the centre stands still."""
        away = np.asarray(feet_m, dtype=np.float64) - self.p0[:2]
        dist = np.maximum(np.hypot(away[..., 0], away[..., 1]), 1e-6)
        return self.p0[:2] + away * ((dist + self.off[cls]) / dist)[..., None]

    def ground_feet(self, thetas_deg: np.ndarray, rays: np.ndarray) -> np.ndarray:
        """(k, 2) attitudes (degrees) -> (k, N, 2) rear_axle ground points (m) of the foot rays (N, 3); NaN
        where a ray misses the ground."""
        _, p, away, hits = self._feet_batch(np.asarray(thetas_deg, dtype=np.float64).reshape(-1, 2), rays)
        return np.where(hits[:, :, None], away + p[:, None, :2], np.nan)

    def residuals(self, theta_deg: np.ndarray, rays: np.ndarray, v_top: np.ndarray, cls: np.ndarray) -> np.ndarray:
        """(N,) predicted minus observed top row (px) of each cone for attitude (pitch, roll) in degrees.

        NaN where the foot ray misses the ground under that attitude.
        """
        return self._residuals_batch(np.asarray(theta_deg, dtype=np.float64).reshape(1, 2), rays, v_top, cls)[0]

    def _residuals_batch(self, thetas_deg: np.ndarray, rays: np.ndarray, v_top: np.ndarray, cls: np.ndarray) -> np.ndarray:
        """(k, 2) attitudes -> (k, N) residuals, all in one vectorised pass."""
        R_F_C, p, away, hits = self._feet_batch(thetas_deg, rays)  # away: ground point minus camera, (k, N, 2)
        dist = np.sqrt(np.sum(away * away, axis=2, keepdims=True))
        reach = dist + (self.off[cls] + self._tip_r_m[cls])[None, :, None]
        top = away * (reach / dist)  # tip (xy) minus camera
        P = np.concatenate([top, (self._height_m[cls][None, :] - p[:, 2:3])[:, :, None]], axis=2)
        Pc = P @ R_F_C  # (k, N, 3) optical frame
        v = self.K[1, 1] * Pc[:, :, 1] / Pc[:, :, 2] + self.K[1, 2]
        return np.where(hits, v - v_top, np.nan)

    # -- fit --------------------------------------------------------------------------------------
    def fit(self, boxes: np.ndarray, class_ids: np.ndarray, start_deg: np.ndarray | None = None,
            sizes: SizeTracks | None = None, start_cov_deg2: np.ndarray | None = None,
            far: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int] | None:
        """One frame's robust fit: ``(theta (2,) deg, covariance (2, 2) deg^2, cones used)``, or None
        with fewer than ``min_cones`` usable cones. ``boxes`` (N, 4) full-image px (pixel edges);
        ``start_deg``: where to linearise first (the filter's prediction; default zero). ``sizes``: the cones
        followed over frames (:class:`~cone_perception.attitude.sizes.SizeTracks`; None: this frame's boxes
        alone, and so without a measured box model unless ``size_rendered``): the cones, mapped with ``start_deg``
        (``start_cov_deg2`` (2, 2): how far off it may be; None: the prior's) and cut at ``max_range_m`` by their
        feet, are followed from the frame before (:meth:`_average_sizes`), then each box is read with its cone's
        averaged height. ``far``: (N,) bool, the boxes of the far strip's network (read through
        :attr:`ImageAttitudeConfig.far_reading`; None: none)."""
        c = self.cfg
        boxes, top_extra, rel, scatter, read = self._read(np.asarray(boxes, dtype=np.float64).reshape(-1, 4), far)
        class_ids = np.asarray(class_ids, dtype=np.intp).ravel()
        self.last_scale = np.inf
        # the rendered table (no box model): boxes within tenths of a pixel, no scatter to average over frames
        measured = c.box_model is not None or (c.far_reading is not None and c.far_reading.box_model is not None)
        averaging = sizes is not None and (measured or c.size_rendered)
        theta = np.zeros(2) if start_deg is None else np.clip(np.asarray(start_deg, dtype=np.float64), -2.0, 2.0)
        # averaging: cones cut at their range by the feet, not the scattered heights (those that came out tall would start tall)
        sel = self._select(boxes, class_ids, by_size=not averaging, far=far) & read  # unmeasured sizes: out
        feet_factor = 1.0 if averaging else c.feet_cut_factor
        if feet_factor > 0 and int(sel.sum()) >= c.min_cones:
            rays, _, _ = self._prepare(boxes[sel], class_ids[sel])
            away = self.ground_feet(theta, rays)[0] - self.p0[:2]
            cut = range_cuts(len(boxes), far, c.max_range_m, c.far_max_range_m)[sel] * feet_factor
            with np.errstate(invalid="ignore"):
                sel[sel] = np.hypot(away[:, 0], away[:, 1]) <= cut  # NaN (misses the ground): out
        if int(sel.sum()) < c.min_cones:
            if averaging:
                sizes.miss()
            return None
        rays, v_top, cls = self._prepare(boxes[sel], class_ids[sel], top_extra[sel])
        h = boxes[sel, 3] - boxes[sel, 1]
        sigma = np.sqrt(2.0 * c.sigma_px**2 + (rel[sel] * h) ** 2)
        if not averaging:
            return self._solve(rays, v_top, cls, sigma, theta)
        # the box model's spread averages over frames, the cone model's own (sigma_rel) not
        v_top, sigma = self._average_sizes(sizes, theta, rays, v_top, cls, scatter[sel], start_cov_deg2)
        res = self._solve(rays, v_top, cls, sigma, theta)
        if res is not None:  # the followed cones' places, with this frame's attitude
            sizes.relocate(self.centres(self.ground_feet(res[0], rays)[0], cls))
        return res

    def _solve(self, rays: np.ndarray, v_top: np.ndarray, cls: np.ndarray, sigma: np.ndarray, theta: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, int] | None:
        """The robust fit of :meth:`fit` on prepared cones (foot rays, top rows, classes, 1-sigma px), linearised
        first at ``theta``; sets :attr:`last_scale`."""
        c = self.cfg
        self.last_scale = np.inf
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
        # the residuals' robust spread in sigmas (1: as the cone model expects; all cones, outliers too): trusted()
        self.last_scale = 1.4826 * float(np.median(np.abs(e)))
        return theta, inv2(A) * scale, n_used

    def _average_sizes(self, sizes: SizeTracks, theta: np.ndarray, rays: np.ndarray, v_top: np.ndarray,
                       cls: np.ndarray, rel, cov_deg2: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The usable cones' top rows (N,) px as their averaged sizes say (:class:`SizeTracks`) and their 1-sigma
        (N,) px: the foot row's, the averaged size's and the cone model's own (``sigma_rel``, not averaged).
        ``theta``: the predicted attitude, ``cov_deg2`` its covariance (None: the prior's); ``rel``: a box
        height's relative scatter from frame to frame (1-sigma; the box model's of the network that drew it: (N,),
        or one for all)."""
        c = self.cfg
        v_foot = self.K[1, 1] * rays[:, 1] / rays[:, 2] + self.K[1, 2]
        hu = np.maximum(v_foot - v_top, 1e-3)  # undistorted height, box model applied
        log_h = np.log(hu)
        var = rel**2 + (c.sigma_px / hu) ** 2  # the top row's scatter, relative
        eps = 0.1
        cov = np.eye(2) * c.prior_sigma_deg**2 if cov_deg2 is None else np.asarray(cov_deg2, dtype=np.float64)
        for k in range(2):  # the cones mapped with the prediction, then with the frame's common pitch error taken off
            g = self.centres(self.ground_feet(np.array([theta, theta + (eps, 0.0), theta + (0.0, eps)]), rays), cls)
            jac = np.nan_to_num(np.stack([g[1] - g[0], g[2] - g[0]], axis=2) / eps)  # (N, 2, 2) m/deg
            off = sizes.pitch_offset(g[0], cls, jac[:, :, 0], cov) if k == 0 else 0.0
            if off == 0.0:
                break
            theta = theta - (off, 0.0)  # pitch_offset: the cones as they would lie at theta - off
        before = sizes.matched
        avg, var_avg = sizes.average(g[0], cls, log_h, var, self.model_heights, jac, cov)
        self.counts.size_cones += len(cls)
        self.counts.size_followed += sizes.matched - before
        h = np.exp(avg)
        return v_foot - h, np.sqrt(c.sigma_px**2 + h**2 * (var_avg + c.sigma_rel**2))

    def trusted(self, n_cones: int, sd_deg: np.ndarray) -> bool:
        """Whether this frame's image attitude (from a fit of ``n_cones`` cones whose residual scale is
        :attr:`last_scale`; estimate 1-sigma ``sd_deg``) beats the calibrated H (config ``trust_*``)."""
        c = self.cfg
        return (n_cones >= c.trust_min_cones and self.last_scale <= c.trust_max_scale
                and float(np.max(sd_deg)) <= c.trust_max_sigma_deg)

    def calibration_fallback(self, n_cones: int = 0) -> Attitude:
        """The calibration's H for a frame whose image attitude is not trusted (counted); its 1-sigma the
        prior's (the body's attitude is unknown that frame)."""
        self.counts.calibration += 1
        s0 = self.cfg.prior_sigma_deg
        return Attitude(0.0, 0.0, s0, s0, "calibration", n_cones)

    def single_frame(self, boxes: np.ndarray, class_ids: np.ndarray, far: np.ndarray | None = None) -> Attitude:
        """The attitude of one frame on its own (no history): the fit with its covariance, or the
        calibration's H (zero, the prior's uncertainty) when the fit has too few cones, is rejected or
        is not trusted (:meth:`trusted`; all counted). ``far``: as :meth:`fit`."""
        res = self.fit(boxes, class_ids, far=far)
        if res is None:
            self.counts.too_few += 1
            return self.calibration_fallback()
        if np.any(np.abs(res[0]) > self.cfg.max_abs_deg):
            self.counts.rejected += 1
            return self.calibration_fallback()
        self.counts.fitted += 1
        sd = np.sqrt(np.diag(res[1]))
        if not self.trusted(res[2], sd):
            return self.calibration_fallback(res[2])
        return Attitude(float(res[0][0]), float(res[0][1]), float(sd[0]), float(sd[1]), "image", res[2])

    def update(self, boxes: np.ndarray, class_ids: np.ndarray, far: np.ndarray | None = None, *,
               stamp_ns: int | None = None) -> Attitude:
        """Fit this frame, fold it into the filter, return the attitude to map this frame with.

        A fit whose residuals or cones fail :meth:`trusted` (its own 1-sigma aside: the filter averages
        fits) is not folded in (counted as ``rejected``); a frame whose filtered estimate's 1-sigma exceeds
        ``trust_max_sigma_deg`` is mapped with the calibration's H (counted as ``used_calibration``); ``far``: :meth:`fit`;
        ``stamp_ns``: the frame's stamp (:class:`~.model.FrameClock`)."""
        c, k = self.cfg, self.clock.step(stamp_ns)
        self.x = self.x * c.decay**k  # predict: random walk decaying to zero
        self.P = self.P * c.decay ** (2 * k) + np.eye(2) * c.process_sigma_deg**2 * k
        res = self.fit(boxes, class_ids, self.x + self.bias, self.sizes if c.size_frames else None, self.P, far=far)
        source, n = "hold", 0
        if res is None:
            self.counts.too_few += 1
            wm = self.motion_weight(None, None)
        elif np.any(np.abs(res[0]) > c.max_abs_deg) or not self.trusted(res[2], np.zeros(2)):
            self.counts.rejected += 1
            wm = self.motion_weight(None, None)
        else:
            z, Rz, n = res
            wm = self.motion_weight(z, Rz)
            z = self.debias(z)
            G = self.P @ inv2(self.P + Rz)
            self.x = self.x + G @ (z - self.x)
            self.P = (np.eye(2) - G) @ self.P
            self.counts.fitted += 1
            source = "image"
        sd = self.still_sigma(np.sqrt(np.diag(self.P)), wm)
        if float(np.max(sd)) > c.trust_max_sigma_deg:
            return self.calibration_fallback(n)
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


def _weighted_median(x: np.ndarray, w: np.ndarray) -> float:
    order = np.argsort(x)
    cw = np.cumsum(w[order])
    return float(x[order][np.searchsorted(cw, 0.5 * cw[-1])])
