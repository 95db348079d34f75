"""The IMU plus the image's ground offset (:class:`FusedAttitude`), applied through a
:class:`GroundGate`; and the estimator a mode asks for (:func:`attitude_estimator`). ROS-free.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ..geometry.linalg import inv2
from ..records import BoxColumns
from .image import ImageAttitude
from .imu import ImuAttitude
from .model import ATTITUDE_MODES, FIXED, Attitude, AttitudeCounts, RunningBias, default_attitude_mode
from .still import StillTest


def attitude_estimator(mapper, mode: str | None, imu: "ImuAttitude | None" = None, config=None):
    """``(mode, estimator)`` for a :class:`~cone_perception.mapping.ConeMapper`, a requested mode
    (None or "" = the default of :func:`default_attitude_mode`) and an IMU source (or None); the
    estimator is None for ``fixed``, an :class:`ImageAttitude` for ``image``, a :class:`FusedAttitude`
    for ``imu`` and ``fused``. ``config``: the image fit's :class:`~cone_perception.attitude.ImageAttitudeConfig`
    (None: the defaults; e.g. with the detector's ``box_model``).

    Raises :class:`ConfigError` for an unknown mode, ``image``/``fused`` without a mount pose, or
    ``imu``/``fused`` without an IMU source.
    """
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
        return mode, mapper.image_attitude(config)
    if imu is None:
        raise ConfigError("attitude", None, f"{mode!r} needs an IMU (none given: no /imu topic in the bag?)")
    return mode, FusedAttitude(mapper.image_attitude(config), imu, use_image=(mode == "fused"))


def attitude_for_boxes(estimator, boxes: BoxColumns | np.ndarray, stamp_ns: int | None = None,
                       far: np.ndarray | None = None) -> Attitude:
    """The attitude to map one frame's boxes with (:class:`~cone_perception.records.BoxColumns`, or ``BOX_DTYPE``
    records made columns here; :data:`FIXED` without an estimator); ``stamp_ns``: the frame's capture stamp (for the
    IMU); ``far``: (N,) bool, the boxes the far strip's network drew (read through its own box model,
    :attr:`~cone_perception.attitude.ImageAttitudeConfig.far_reading`)."""
    if estimator is None:
        return FIXED
    cols = BoxColumns.of(boxes)
    b = cols.xyxy.astype(np.float64)
    if isinstance(estimator, FusedAttitude):
        return estimator.update(b, cols.class_id.astype(np.intp), stamp_ns, far)
    return estimator.update(b, cols.class_id.astype(np.intp), far, stamp_ns=stamp_ns)


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


class ImuStillTest(StillTest):
    """The image's still test (``ImageAttitudeConfig`` ``still_frames``, ``still_min_frames``, ``still_ratio``,
    ``still_ramp``, ``still_max_mean_deg``) run on the IMU's readings against the IMU's own 1-sigma: in ``fused`` a
    body is still only where its IMU says so too. The image fits alone cannot tell a body that jitters by less than
    their own 1-sigma (0.2-0.4° in roll on a small wide camera) from a still one, and the attitude returned to zero
    there threw the IMU's reading away (docs/attitude.md, "still test")."""

    def weight(self, body: np.ndarray, sigma_deg: float, k: float = 1.0) -> float:
        """Fold one reading (pitch, roll; degrees) in; 1 = the IMU sees the body move or lean (keep the estimate),
        0 = still (as far as the IMU can tell); 1 until ``still_min_frames`` readings are in (``k``: this frame's
        length in ``frame_s``, :class:`~.model.FrameClock`; the windows count in those)."""
        if self.cfg.still_frames <= 0:
            return 1.0
        self.fold(body, np.full(2, sigma_deg**2), k)
        return self.verdict() if self.judged else 1.0


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

    In pitch it is the other way round: the fits are the better reference (1-sigma 0.1-0.2 degree a
    frame, their bias a few hundredths on most cameras), and the IMU's reading keeps what its rest
    capture left of its bias (the rendered IMU: 0.05 degree 1-sigma a drive), which the ground gate
    takes for flat ground below about 0.15 degree. So the IMU's pitch bias is learnt as the long-run
    mean of (pitch fit minus IMU pitch), shrunk by ``pitch_bias_prior_frames`` pseudo-frames, the same
    exponential mean, and added to the IMU's pitch (None: the IMU's pitch taken as exact); a grade
    that lasts is taken up by it too, as the road ahead the camera sees.

    The ground offset is applied through ``gate`` (:class:`GroundGate`; None: always in full)."""

    def __init__(self, image: ImageAttitude, imu: ImuAttitude, use_image: bool = True,
                 offset_process_sigma_deg: float = 0.05, roll_bias_prior_frames: float = 30.0,
                 gate: "GroundGate | None" = GroundGate(), *, pitch_bias_prior_frames: float | None = 30.0):
        self.image, self.imu, self.use_image = image, imu, use_image
        self.gate = gate  # None: the image's ground offset always applied in full
        self.g_mean, self.gate_latch = np.zeros(2), np.zeros(2)
        if gate is not None:  # its constants: squared spreads, prior log-odds (mean, instant), latch decay, mean length
            self._gate_k = (np.square(gate.slow_deg), np.square(gate.grade_deg), _log_odds(gate.p_flat),
                            _log_odds(gate.p_flat_instant), 1.0 - 1.0 / gate.hold_frames, max(gate.evidence_frames, 1.0))
        self.q = offset_process_sigma_deg**2
        self.g = np.zeros(2)  # ground offset (total attitude minus IMU), degrees
        self.Pg = np.eye(2) * image.cfg.prior_sigma_deg**2
        tau = image.cfg.bias_tau_frames
        self.roll_mean = RunningBias(roll_bias_prior_frames, tau)  # the image fit's roll bias against the IMU
        # the IMU's pitch bias against the ground the fits see; None: the IMU's pitch taken as exact
        self.pitch_mean = RunningBias(pitch_bias_prior_frames, tau) if pitch_bias_prior_frames is not None else None
        self.imu_still = ImuStillTest(image.cfg)  # still only where the IMU says so too

    @property
    def counts(self) -> AttitudeCounts:
        return self.image.counts

    @property
    def roll_bias(self) -> float:
        """The image fit's roll bias against the IMU now (degrees)."""
        return self.roll_mean.value

    def debias_roll(self, d_roll: float) -> np.ndarray:
        """Fold one accepted fit's roll minus the IMU's (degrees) into the roll bias; return the bias
        (pitch, roll) to take off the fit."""
        return np.array([0.0, self.roll_mean.fold(d_roll, self.image.clock.k)])

    @property
    def pitch_bias(self) -> float:
        """The IMU's pitch bias against the ground the fits see now (degrees; 0 where not learnt)."""
        return self.pitch_mean.value if self.pitch_mean is not None else 0.0

    def step_ground_gate(self) -> tuple[np.ndarray, np.ndarray]:
        """One frame's step of the ground gate: the ground offset to add to the IMU's attitude and its
        variance, per axis (degrees). Call once per frame (the evidence mean and the latch step per call)."""
        var = np.diag(self.Pg).copy()
        if self.gate is None:
            return self.g.copy(), var
        slow2, grade2, lo_mean, lo_now, decay, n_mean = self._gate_k
        k = self.image.clock.k  # this frame in frames of frame_s: the mean's and the latch's steps
        s2 = var + slow2  # the offset's error: the filter's and the fits' slow one
        t2 = grade2 + s2  # its spread where the road does change grade
        self.g_mean += (self.g - self.g_mean) * min(k / n_mean, 1.0)

        def log_bf(g):  # grade change : flat, per axis
            return 0.5 * np.log(s2 / t2) + 0.5 * g**2 * (1.0 / s2 - 1.0 / t2)

        def prob(log_odds):
            return 1.0 / (1.0 + np.exp(-np.clip(log_odds, -50.0, 50.0)))

        b_mean, b_now = log_bf(self.g_mean), log_bf(self.g)
        w_mean, w_now = prob(lo_mean + b_mean), prob(lo_now + b_now)
        w = np.maximum(w_mean, w_now)
        shown = np.where(w_now > w_mean, b_now, b_mean) > 0  # the evidence favours a grade change
        self.gate_latch = np.maximum(self.gate_latch * decay**k, np.where(shown, w, 0.0))
        w = np.maximum(w, self.gate_latch)
        return w * self.g, w * var + w * (1.0 - w) * self.g**2  # the mixture's mean and variance

    def update(self, boxes: np.ndarray, class_ids: np.ndarray, stamp_ns: int | None,
               far: np.ndarray | None = None) -> Attitude:
        """``far``: (N,) bool, the far strip's network's boxes (:meth:`ImageAttitude.fit`)."""
        raw = self.imu.at(stamp_ns)
        if raw is None:
            return self.image.update(boxes, class_ids, far, stamp_ns=stamp_ns)
        self.image.clock.step(stamp_ns)  # the image's still test counts in its frame_s
        s_imu = self.imu.sigma_deg
        if not self.use_image:
            return Attitude(float(raw[0]), float(raw[1]), s_imu, s_imu, "imu", 0)
        body = raw + np.array([self.pitch_bias, 0.0])
        self.Pg = self.Pg + np.eye(2) * self.q * self.image.clock.k
        bias = np.array([0.0, self.roll_bias])
        res = self.image.fit(boxes, class_ids, body + self.g + bias, far=far)
        n, wm = 0, None
        if res is None:
            self.image.counts.too_few += 1
        elif np.any(np.abs(res[0]) > self.image.cfg.max_abs_deg):
            self.image.counts.rejected += 1
        else:
            z, Rz, n = res
            wm = self.image.motion_weight(z, Rz, start_from_fit=False)
            z = z - self.debias_roll(float(z[1] - body[1]))
            if self.pitch_mean is not None:
                self.pitch_mean.fold(float(z[0] - raw[0]), self.image.clock.k)
            S = self.Pg + Rz + np.eye(2) * s_imu**2
            G = self.Pg @ inv2(S)
            self.g = self.g + G @ (z - body - self.g)
            self.Pg = (np.eye(2) - G) @ self.Pg
            self.image.counts.fitted += 1
        if wm is None:
            wm = self.image.motion_weight(None, None)
        wm = max(wm, self.imu_still.weight(raw, s_imu, self.image.clock.k))
        g, var_g = self.step_ground_gate()
        att = (body + g) * wm  # still body and ground (the image's still test): the calibration's zero
        self.image.x = att.copy()  # keeps the image filter warm for frames without IMU
        sd = self.image.still_sigma(np.sqrt(var_g + s_imu**2), wm)
        return Attitude(float(att[0]), float(att[1]), float(sd[0]), float(sd[1]), "fused", n)
