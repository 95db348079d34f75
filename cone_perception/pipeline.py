"""The three stages in one call: raw frame -> cropped band -> boxes -> cones.

Used by the fused ``pipeline`` node, the offline ``replay``, ``detect`` on bags and
``bench``, so every path runs the very same code. ROS-free.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from .adapter import DriverAdapter
from .attitude import FIXED, Attitude, attitude_estimator, attitude_for_boxes
from .detector.farband import FarBand, drawn_by_far, drop_cut_boxes, merge_boxes
from .detector.parallel import PairRunner
from .geometry.calib import Calibration
from .mapping import ConeMapper, one_box_per_cone
from .records import BOX_DTYPE, BoxColumns
from .params import DEFAULT_IOU, DEFAULT_MIN_HEIGHT_RATIO, DEFAULT_ONE_RAY_RANGE_M

STAGES = ("adapter", "preprocess", "forward", "postprocess", "far_forward", "far_band", "far_wait", "attitude", "mapping")


@dataclass
class FrameResult:
    """Output of one frame: boxes (``BOX_DTYPE``, full-image px), cones (``CONE_DTYPE``, m), stage ms,
    and the band (for the debug image)."""

    boxes: np.ndarray
    cones: np.ndarray
    timing_ms: dict[str, float] = field(default_factory=dict)
    attitude: Attitude = FIXED  # the body attitude offset the cones were mapped with
    band: np.ndarray | None = None  # (H, W, 3) uint8 BGR: the cropped band the detector saw
    weak_cones: np.ndarray | None = None  # CONE_DTYPE below cones_conf, for the tracker only (None: no split)


class Pipeline:
    """Driver adapter + detector + mapper of one calibrated camera.

    ``detector`` is a :class:`cone_perception.detector.Detector` (anything with
    ``detect(bgr_cropped, crop) -> BOX_DTYPE`` and a ``timing`` dict of ms).
    ``attitude``: ``fixed``, ``image``, ``imu`` or ``fused`` (see :mod:`cone_perception.attitude`);
    None picks the default (``fused`` with ``imu`` and a mount pose, ``image`` with a mount pose, else
    ``fixed``). ``imu``: an :class:`~cone_perception.attitude.ImuAttitude` the caller feeds; each
    ``process_*`` call takes the frame's capture stamp (``stamp_ns``), at which the IMU is read. ``far``: a
    :class:`~cone_perception.detector.farband.FarBand` (full-resolution rows near the horizon, a second
    forward; its boxes merge with the band's), or None; a calibrated strip moves each frame with the
    attitude of the frame before, and with an IMU also with what it turned since, read at this frame's stamp
    (:attr:`strip_counts` counts the frames where it was clamped to the image).
    ``attitude_config``: the image fit's :class:`~cone_perception.attitude.ImageAttitudeConfig` (e.g. with the
    detector's measured ``box_model``); None: the defaults (the rendered drives' box table).
    ``cones_conf``: with a detector run at a lower threshold (the tracker's confirmation threshold), the
    score that splits its boxes: those at or above it are the frame's boxes and ``/cones`` (and fit the
    attitude), those below are mapped with the same attitude into :attr:`FrameResult.weak_cones`, for the
    tracker only (docs/tracking.md, "Weak detections"). None: no split.
    ``min_height_ratio``: boxes lower than this x a cone's height where their foot maps are dropped as marks on the
    ground (:class:`~cone_perception.mapping.ConeMapper`; 0: off); ``one_ray_range_m``: two cones nearly on one
    viewing ray, the better-scored nearer than this, are one cone (the mapper's; 0: off); :attr:`mapper`
    ``.dropped`` counts every dropped box by cause.
    ``concurrent``: with ``far``, run the band's and the strip's detect at the same time, the strip on a
    worker thread (:mod:`cone_perception.detector.parallel`; :class:`~cone_perception.detector.parallel.ForwardPlan`
    says when, and with how many threads each detector is loaded); the same boxes as one after the other.
    :meth:`close` joins the worker. Stage times with ``far``: ``far_forward`` (the strip's forward),
    ``far_band`` (its detect and the merge, on whichever thread), ``far_wait`` (what it adds to the frame:
    ``far_band`` when sequential, the wait for it after the band's detect plus the merge when concurrent).
    ``far_every``: with ``far``, the strip runs on every this-many-th frame only (the first frame, then every
    ``far_every``-th; 1: every frame), the frames between run the band alone (no strip cut): a far cone is seen
    up to ``far_every - 1`` frames late, the tracker carries it meanwhile (docs/detector.md, "Far band").
    ``far_tiles``: with ``far_every`` > 1, a :class:`~cone_perception.detector.fartiles.FarTiles`: on the frames
    between, the strip's windows around the last frames' boxes whole in the strip's rows run as one mosaic, as
    narrow as they allow (the whole strip where they do not fit it; the band alone where there are none); None:
    the band alone between.
    """

    def __init__(self, calib: Calibration, detector, attitude: str | None = None, imu=None, far: FarBand | None = None,
                 cones_conf: float | None = None, attitude_config=None, concurrent: bool = False,
                 min_height_ratio: float = DEFAULT_MIN_HEIGHT_RATIO, far_every: int = 1, far_tiles=None,
                 one_ray_range_m: float = DEFAULT_ONE_RAY_RANGE_M):
        self.calib = calib
        if isinstance(far_every, bool) or not isinstance(far_every, (int, np.integer)) or far_every < 1:
            raise ValueError(f"far_every must be a whole number of frames >= 1, got {far_every!r}")
        self.far_every = int(far_every)
        self._frame_n = 0  # frames processed: the strip runs where frame_n % far_every == 0
        self.far_tiles = far_tiles if far is not None and self.far_every > 1 else None
        # the last frames' boxes whole in their strip's rows (far_tiles.memory frames): where the tiles look
        self._far_seen: deque[np.ndarray] = deque(maxlen=far_tiles.memory if self.far_tiles is not None else 1)
        self._frame_rows: tuple[int, int] | None = None  # this frame's strip rows (also where it does not run)
        if far is not None:
            far.check_classes(detector)  # a far model of other classes: refused before the first frame
        self._pair = PairRunner(concurrent and far is not None)  # the band's and the strip's detect
        self.far = far  # the far band (full-resolution rows near the horizon, detector/farband.py), or None
        self.adapter = DriverAdapter(calib.crop, calib.image_width, calib.image_height, far.crop if far else None)
        self._band_adapter = replace(self.adapter, far=None)  # a frame far_every skips: the band alone is cut
        self.detector = detector
        self.mapper = ConeMapper(calib, min_height_ratio, one_ray_range_m)  # its ``dropped``: the boxes dropped, by cause
        self.imu = imu  # an ImuAttitude the caller feeds (modes imu, fused), or None
        self.attitude_mode, self.attitude = attitude_estimator(self.mapper, attitude, imu, attitude_config)
        self.cones_conf = cones_conf
        #: frames with the far strip, and those where the attitude would have moved it out of the image
        #: (clamped to it): the replay summary and the node's /diagnostics report them (``skipped``: frames
        #: without it by ``far_every``, only where that is above 1; ``verifier_dropped``: the boxes in the strip's
        #: rows its verifier dropped, with one)
        self.strip_counts = {"frames": 0, "clamped": 0}
        if far is not None and self.far_every > 1:
            self.strip_counts["skipped"] = 0
            if self.far_tiles is not None:  # frames run as tiles, and those whose tiles did not fit (the whole strip)
                self.strip_counts.update(tiles=0, tiles_full=0)
        if far is not None and far.verifier is not None:  # boxes its second look dropped
            self.strip_counts["verifier_dropped"] = 0
        self.strip_rows: tuple[int, int] | None = None  # the last frame's strip rows (V0, V1)
        self._strip_attitude = np.zeros(2)  # (pitch, roll) the strip follows: the previous frame's attitude
        self._strip_body: np.ndarray | None = None  # the IMU's reading at the previous frame's stamp

    def _far_crop(self, stamp_ns: int | None):
        """(this frame's strip crop, clamped, tile windows), or (None, False, None) without a far band or on a
        frame ``far_every`` skips without tiles (windows: None for the whole strip); the strip is moved with the
        previous frame's attitude, plus what the IMU (modes imu, fused) turned since then, read at this frame's
        stamp (read on a skipped frame too: the next strip adds only what it turned since)."""
        if self.far is None:
            return None, False, None
        due = self._frame_n % self.far_every == 0
        self._frame_n += 1
        att = self._strip_attitude
        if self.imu is not None and self.far.plan is not None:
            # not counted here: the attitude estimator reads the IMU at this stamp too, and counts it there
            body = self.imu.at(stamp_ns, count=False)
            if body is not None and self._strip_body is not None:
                att = att + (body - self._strip_body)
            self._strip_body = body
        crop, clamped = self.far.crop_for(float(att[0]), float(att[1]))
        self._frame_rows = (crop.v0, crop.v1)
        if due:
            return crop, clamped, None
        self.strip_counts["skipped"] += 1
        if self.far_tiles is None:
            return None, False, None
        seen = np.concatenate(self._far_seen) if self._far_seen else np.zeros(0, BOX_DTYPE)
        windows = self.far_tiles.windows(seen, self.calib.image_width)
        if windows is None:  # too many far cones for the mosaic: the whole strip
            self.strip_counts["tiles_full"] += 1
            return crop, clamped, None
        if not windows:  # no far cone to look for: the band alone
            return None, False, None
        self.strip_counts["tiles"] += 1
        return crop, clamped, windows

    def _run(self, cut_band, t_adapter_s: float, cut_strip, stamp_ns: int | None,
             far_crop=None, clamped: bool = False, windows=None) -> FrameResult:
        """One frame from its validated image: ``cut_band`` / ``cut_strip`` (None: no strip this frame) cut and convert
        the band and the strip when called (:meth:`DriverAdapter.cutters_raw`), each on the thread of its detector;
        ``t_adapter_s``: the validation (or decoding) before; the band's cut adds to the ``adapter`` stage, the
        strip's to ``far_band``."""
        timing = {"adapter": t_adapter_s * 1e3}
        cut: dict = {}  # the band and the strip as cut (the debug image shows the band, the verifier reads the strip)

        def band_boxes() -> np.ndarray:
            t0 = time.perf_counter()
            cut["band"] = cut_band()
            timing["adapter"] += (time.perf_counter() - t0) * 1e3
            return self.detector.detect(cut["band"], self.calib.crop)

        far_boxes = None  # the far strip's boxes: the image attitude reads those kept through the far model's box model
        if self.far is not None and cut_strip is not None:  # two forwards, at once with a concurrent plan
            if windows is None:
                def second():
                    cut["strip"] = cut_strip()
                    return self.far.detect(cut["strip"], far_crop)
            else:  # the tiles: the strip's windows around the last frames' far cones, one mosaic
                def second():
                    cut["strip"] = cut_strip()
                    return self.far_tiles.detect(cut["strip"], far_crop, windows, self.calib.image_width)
            boxes, far_boxes, t = self._pair.run(band_boxes, second)
            far_det = self.far.detector if windows is None else self.far_tiles.detector  # the network that ran
            t0 = time.perf_counter()
            boxes = merge_boxes(boxes, far_boxes, getattr(self.far.detector, "iou", DEFAULT_IOU))
            t_merge = (time.perf_counter() - t0) * 1e3
            if self.far.verifier is not None:  # its second look (tile frames too: the whole strip is cut)
                t0 = time.perf_counter()
                boxes = self.far.verify(boxes, cut["strip"], far_crop)
                timing["verifier"] = (time.perf_counter() - t0) * 1e3
                t_merge += timing["verifier"]
            timing.update({k.removesuffix("_ms"): v for k, v in self.detector.timing.items()})
            if "forward_ms" in getattr(far_det, "timing", {}):
                timing["far_forward"] = far_det.timing["forward_ms"]
            timing["far_band"] = t["second"] + t_merge  # the strip's own time, on whichever thread
            timing["far_wait"] = t["wall"] - t["first"] + t_merge  # what it adds to the frame
            self.strip_counts["frames"] += int(windows is None)
            if "verifier_dropped" in self.strip_counts:
                self.strip_counts["verifier_dropped"] = self.far.verifier.counts["dropped"]
            self.strip_counts["clamped"] += int(clamped)
            self.strip_rows = (far_crop.v0, far_crop.v1) if far_crop is not None else None
        else:
            boxes = band_boxes()
            timing.update({k.removesuffix("_ms"): v for k, v in self.detector.timing.items()})
        # the mapping stage: the frame's boxes as columns, made once; every step below takes them
        cols = BoxColumns.of(boxes)
        kept = one_box_per_cone(cols)  # a second box of one cone (two classes, or twice small) goes
        self.mapper.dropped["second_box"] += len(cols) - len(kept)
        cols = kept
        if self.far_tiles is not None:  # where the next frame's tiles look: this frame's cones whole in its strip's rows
            self._far_seen.append(drop_cut_boxes(cols.records, replace(self.far.crop, v0=self._frame_rows[0],
                                                                       v1=self._frame_rows[1])))
        weak = None
        if self.cones_conf is not None:
            strong = cols.score >= self.cones_conf
            cols, weak = cols.take(strong), cols.take(~strong)
        att = FIXED
        if self.attitude is not None:
            t0 = time.perf_counter()
            far = drawn_by_far(cols.records, far_boxes) if far_boxes is not None else None  # of the boxes kept, the strip's
            att = attitude_for_boxes(self.attitude, cols, stamp_ns, far)
            timing["attitude"] = (time.perf_counter() - t0) * 1e3
        t0 = time.perf_counter()
        self._strip_attitude = np.array([att.pitch_deg, att.roll_deg])
        cones = self.mapper.map_boxes(cols, att)
        weak_cones = self.mapper.map_boxes(weak, att) if weak is not None else None
        timing["mapping"] = (time.perf_counter() - t0) * 1e3
        return FrameResult(cols.records, cones, timing, att, cut["band"], weak_cones)

    @property
    def concurrent(self) -> bool:
        """Whether the band's and the far strip's forwards run at the same time (a worker thread)."""
        return self._pair.concurrent

    def close(self) -> None:
        """Join the far strip's worker thread, if one runs (idempotent; a later frame starts a new one)."""
        self._pair.close()

    def __enter__(self) -> "Pipeline":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _check_stamp(self, stamp_ns: int | None) -> None:
        if stamp_ns is None and self.imu is not None:
            raise ValueError(f"attitude {self.attitude_mode!r} reads the IMU at the frame's capture stamp: "
                             "pass stamp_ns to process_raw / process_compressed")

    def process_raw(self, encoding: str, width: int, height: int, step: int, data,
                    stamp_ns: int | None = None) -> FrameResult:
        """sensor_msgs/Image fields -> :class:`FrameResult`. ``stamp_ns``: the frame's capture stamp (ns),
        needed with an IMU (attitude ``imu`` / ``fused``; a ``ValueError`` without it). Raises
        ``FrameError`` for a bad frame."""
        self._check_stamp(stamp_ns)
        t0 = time.perf_counter()
        far, clamped, windows = self._far_crop(stamp_ns)
        adapter = self.adapter if far is not None else self._band_adapter
        band, strip = adapter.cutters_raw(encoding, width, height, step, data, far)
        return self._run(band, time.perf_counter() - t0, strip, stamp_ns, far, clamped, windows)

    def process_compressed(self, data, stamp_ns: int | None = None) -> FrameResult:
        """sensor_msgs/CompressedImage data (JPEG/PNG) -> :class:`FrameResult`; ``stamp_ns`` as
        :meth:`process_raw`."""
        self._check_stamp(stamp_ns)
        t0 = time.perf_counter()
        far, clamped, windows = self._far_crop(stamp_ns)
        adapter = self.adapter if far is not None else self._band_adapter
        band, strip = adapter.cutters_compressed(data, far)
        return self._run(band, time.perf_counter() - t0, strip, stamp_ns, far, clamped, windows)
