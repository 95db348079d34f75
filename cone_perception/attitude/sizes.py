"""Each cone's box height averaged over frames (:class:`SizeTracks`), for the image fit (issue 27).

A box's height says its cone's range, but on real detectors only to about 7 % per box, drawn anew each
frame; its foot row says the range precisely, given the attitude. The image fit (:mod:`.image`) weighs the
two against each other, so a frame's pitch carries the scatter of its dozen box heights (0.15-0.2 degree).
A cone stands still on the ground: followed from frame to frame, its box heights of all frames are one
measurement, moved by the car's motion in between. :class:`SizeTracks` keeps, per cone seen, its ground
position (its centre, in the last frame's ``rear_axle``), the log of its averaged box height and that
average's variance. Each frame the fit (:meth:`~cone_perception.attitude.image.ImageAttitude._average_sizes`)
maps its cones' centres with the predicted attitude, asks :meth:`SizeTracks.pitch_offset` for the frame's
common pitch error (a search: under which offset most cones lie near a kept one moved by the last motion)
and maps them again with it taken off; then :meth:`SizeTracks.average`

1. registers them against the kept cones (:func:`~cone_perception.geometry.motion.register_cones`: the
   car's planar motion and which cone is which; the frame's remaining common attitude error is estimated
   alongside and dropped, with the attitude Jacobians of the cones);
2. moves each kept cone's log height with the car: the ratio of the cone model's heights (``height_of``)
   after and before the motion, at the distance its averaged height says (``place_by_size``; at its foot
   the attitude's error would feed back into the heights), its variance growing as the cone comes nearer
   (the distances' ratio, squared) and by the motion's error (``motion_sigma_m`` over the distance);
3. folds in this frame's box height (inverse variances; a pair more than ``gate_sigmas`` apart is two
   cones) and returns each cone's average and its variance (at least the per-box variance over
   ``max_frames``). The caller adds what does not average out (the cone's own build, the cone model's
   error).

ROS-free, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..classes import UNKNOWN
from ..geometry.motion import Motion2D, register_cones


@dataclass(frozen=True)
class SizeTrackConfig:
    """Tuning of :class:`SizeTracks` (m, frames)."""

    motion_sigma_m: float = 0.03  # 1-sigma of the registered motion per frame (translation)
    max_frames: float = 30.0  # at most this many frames' worth of boxes in a cone's average (forgetting)
    #: forgetting as the cone's height changes: the average's variance grows by exp(|change of log height| /
    #: this) per frame, so boxes of a cone seen at another range weigh less (a detector's box bias changes with
    #: the box's size); 0 = off
    forget_log_h: float = 0.0
    max_missed: int = 2  # frames a cone may be missed before it is forgotten
    #: a pair whose box height differs from the kept cone's moved average by more than this many sigmas is two
    #: cones (the box starts a new average); 0 = off
    gate_sigmas: float = 3.0
    #: moving a cone's height with the car: from the distance its averaged height says (True) or from its foot
    #: mapped with the fitted attitude (False)
    place_by_size: bool = True
    inlier_m: float = 0.5  # registration: a cone within this of its predicted place is the same cone
    search_m: float = 1.5  # registration: candidate pairs within this after the prior motion
    #: before registering (:meth:`SizeTracks.pitch_offset`): the frame's common pitch error searched within
    #: +-``pitch_search_sigmas`` of the prediction's 1-sigma (at most ``pitch_search_max_deg``) in
    #: ``pitch_search_steps`` steps, the one under which most cones lie near a kept cone moved by the prior motion
    #: (a Gaussian score of ``inlier_m``), then 11 steps around it (half the kernel); 0 steps = off
    pitch_search_sigmas: float = 3.0
    pitch_search_max_deg: float = 1.5
    pitch_search_steps: int = 31


class SizeTracks:
    """The followed cones of an image fit (module doc); ``camera_xy``: the camera's ground position in
    ``rear_axle`` (m), from which ranges are measured. :attr:`matched` / :attr:`cones` count the cones that
    were followed from an earlier frame / all cones given (since the last :meth:`reset`)."""

    def __init__(self, camera_xy: np.ndarray, config: SizeTrackConfig | None = None):
        self.cam = np.asarray(camera_xy, dtype=np.float64).reshape(2)
        self.cfg = config or SizeTrackConfig()
        self.reset()

    def reset(self) -> None:
        """Forget every cone and the motion (a new drive)."""
        self.xy = np.zeros((0, 2))  # ground positions (centres) of the cones kept, in the last frame's rear_axle (m)
        self.cls = np.zeros(0, dtype=np.intp)
        self.log_h = np.zeros(0)  # averaged log box height (log px, undistorted), at ``xy``
        self.var = np.zeros(0)  # its variance (the averaged part only)
        self.missed = np.zeros(0, dtype=np.intp)
        self._fin = np.zeros(0, dtype=bool)
        self.motion = Motion2D()  # the last frame's motion: the next one's prior (constant velocity)
        self.matched = 0
        self.cones = 0
        self.frames = 0

    def _dist(self, xy: np.ndarray) -> np.ndarray:
        return np.maximum(np.hypot(xy[:, 0] - self.cam[0], xy[:, 1] - self.cam[1]), 1e-3)

    def average(self, xy: np.ndarray, cls: np.ndarray, log_h: np.ndarray, var: np.ndarray,
                height_of, att_jac: np.ndarray | None = None, att_cov_deg2: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
        """One frame's cones: ground positions ``xy`` (N, 2) m (centres, mapped with the frame's best attitude guess;
        a NaN row: its foot ray misses the ground), classes ``cls`` (N,), log box heights ``log_h`` (N,) (px, the box
        model applied) and their per-box variances ``var`` (N,); ``height_of(xy, cls)``: the box height (px) of cones
        of classes ``cls`` standing at ``xy`` (the fit's cone model); ``att_jac`` (N, 2, 2) m/deg and
        ``att_cov_deg2`` (2, 2): how the positions move with the attitude and how uncertain the guess is. Returns
        each cone's averaged log height and its variance (N,). The state moves to this frame: call once per
        frame."""
        c = self.cfg
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        log_h, var = np.asarray(log_h, np.float64).copy(), np.asarray(var, np.float64).copy()
        n = len(xy)
        fin = np.all(np.isfinite(xy), axis=1)
        self.frames += 1
        self.cones += n
        # 1. the motion since the last frame and which kept cone each of this frame's is
        motion, pairs = self.motion, (np.zeros(0, np.intp), np.zeros(0, np.intp))
        idx = np.flatnonzero(fin)
        if len(self.xy) and len(idx):
            reg = register_cones(xy[idx], cls[idx], self.xy, self.cls, self.motion, search_m=c.search_m,
                                 inlier_m=c.inlier_m, det_att_jac=None if att_jac is None else att_jac[idx],
                                 att_cov_deg2=att_cov_deg2)
            if reg.ok:
                motion, pairs = reg.motion, (idx[reg.det_index], reg.trk_index)
        # 2. the kept cones moved to this frame, their heights with them. Each is placed at the distance its
        #    averaged height says (along its foot's bearing; a height goes as one over the distance), not at its
        #    foot: the feet carry the attitude's error, which would feed back into the heights. A height's
        #    relative error grows as the cone comes nearer (the distance's ratio).
        moved = motion.to_current(self.xy)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            scale = height_of(self.xy, self.cls) / np.exp(self.log_h)
            scale = np.where(np.isfinite(scale) & (scale > 0) & c.place_by_size, scale, 1.0)
            p_s = self.cam + (self.xy - self.cam) * scale[:, None]
            m_s = motion.to_current(p_s)
            ratio = height_of(m_s, self.cls) / height_of(p_s, self.cls)
        d0, d1 = self._dist(p_s), self._dist(m_s)
        ratio = np.where(np.isfinite(ratio) & (ratio > 0), ratio, d0 / d1)
        prev_log = self.log_h + np.log(ratio)
        prev_var = self.var * ((d0 / d1) ** 2 if c.place_by_size else 1.0) + (c.motion_sigma_m / d1) ** 2
        if c.forget_log_h > 0:
            prev_var = prev_var * np.exp(np.abs(np.log(ratio)) / c.forget_log_h)
        # 3. fold this frame's boxes in
        di, tj = pairs
        if c.gate_sigmas > 0 and len(di):
            same = (log_h[di] - prev_log[tj]) ** 2 <= c.gate_sigmas**2 * (prev_var[tj] + var[di])
            di, tj = di[same], tj[same]
        per_box = var.copy()
        if len(di):
            w0, w1 = 1.0 / prev_var[tj], 1.0 / var[di]
            log_h[di] = (w0 * prev_log[tj] + w1 * log_h[di]) / (w0 + w1)
            var[di] = np.maximum(1.0 / (w0 + w1), per_box[di] / c.max_frames)
        self.matched += len(di)
        # keep: this frame's cones (with a foot on the ground) and the unmatched kept ones not missed too long
        keep_old = np.ones(len(self.xy), dtype=bool)
        keep_old[tj] = False
        keep_old &= self.missed < c.max_missed
        self.xy = np.concatenate([xy[fin], moved[keep_old]])
        self.cls = np.concatenate([np.asarray(cls, np.intp)[fin], self.cls[keep_old]])
        self.log_h = np.concatenate([log_h[fin], prev_log[keep_old]])
        self.var = np.concatenate([var[fin], prev_var[keep_old]])
        self.missed = np.concatenate([np.zeros(int(fin.sum()), np.intp), self.missed[keep_old] + 1])
        self._fin = fin
        self.motion = motion
        return log_h, var

    def pitch_offset(self, xy: np.ndarray, cls: np.ndarray, jac_pitch: np.ndarray, cov_deg2: np.ndarray) -> float:
        """The frame's common pitch error (degrees) under which its cones ``xy`` (N, 2) (moving by ``jac_pitch``
        (N, 2) m/deg; NaN rows ignored), classes ``cls``, best meet the kept cones moved by the prior motion (config
        ``pitch_search_*``; ``cov_deg2``: the prediction's covariance): the caller maps them again with it before
        :meth:`average` (the registration then starts near the truth; a linear correction was not enough for far
        cones). 0 without kept cones."""
        c = self.cfg
        fin = np.all(np.isfinite(xy), axis=1)
        if not len(self.xy) or not fin.any():
            return 0.0
        xy, cls, jac_pitch = xy[fin], np.asarray(cls)[fin], jac_pitch[fin]
        span = min(c.pitch_search_sigmas * float(np.sqrt(max(cov_deg2[0, 0], 0.0))), c.pitch_search_max_deg)
        if span <= 0 or c.pitch_search_steps < 2:
            return 0.0
        pred = self.motion.to_current(self.xy)
        dc, tc = cls[:, None], self.cls[None, :]
        other = (dc != tc) & (dc != UNKNOWN) & (tc != UNKNOWN)
        centre, step, kernel = 0.0, 2.0 * span / (c.pitch_search_steps - 1), c.inlier_m
        for offs in (np.linspace(-span, span, c.pitch_search_steps), None):
            if offs is None:  # then finer around the best, with a narrower kernel
                offs, kernel = centre + np.linspace(-step, step, 11), 0.5 * c.inlier_m
            p = xy[None, :, :] - offs[:, None, None] * jac_pitch[None]  # (S, N, 2)
            d2 = np.sum((p[:, :, None, :] - pred[None, None, :, :]) ** 2, axis=3)  # (S, N, M)
            d2[:, other] = np.inf
            score = np.exp(-0.5 * np.min(d2, axis=2) / kernel**2).sum(axis=1)
            best = np.flatnonzero(score >= score.max() - 1e-9)
            centre = float(offs[best[np.argmin(np.abs(offs[best] - centre))]])  # ties: the one nearest the last
        return centre

    def miss(self) -> None:
        """A frame without cones to follow: the kept ones move by the prior motion and count as missed."""
        self.frames += 1
        moved = self.motion.to_current(self.xy)
        keep = self.missed < self.cfg.max_missed
        self.log_h = self.log_h[keep] + np.log(self._dist(self.xy[keep]) / self._dist(moved[keep]))
        self.var = self.var[keep] + (self.cfg.motion_sigma_m / self._dist(moved[keep])) ** 2
        self.xy, self.cls, self.missed = moved[keep], self.cls[keep], self.missed[keep] + 1
        self._fin = np.zeros(0, dtype=bool)

    def relocate(self, xy: np.ndarray) -> None:
        """Replace the ground positions of the cones :meth:`average` was last given (N, 2 m; NaN rows kept
        where they were) with better ones (mapped with the frame's fitted attitude)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)[self._fin]
        ok = np.all(np.isfinite(xy), axis=1)
        k = len(xy)
        self.xy[:k][ok] = xy[ok]
