"""How a detector's boxes relate to the labelled cones (:class:`BoxModel`), so the image fit reads its
box tops and bottoms as the cones' (issue 27).

A detector's box is not the labelled cone's: on real frames the shipped detector's boxes are shorter
than the labels (tops low, bottoms high), while on rendered drives they are within tenths of a pixel
(:data:`~cone_perception.attitude.image.ImageAttitudeConfig.top_bias_extra_px`, the synthetic case). A
box model holds, per box height bucket (px at the model input), the median of

- ``height_ratio``: detected height / labelled height,
- ``top_low``: (detected top - labelled top) / labelled height (positive: the box top lies below the label's),
- ``bottom_high``: (labelled bottom - detected bottom) / labelled height (positive: the box bottom lies above),

measured on labelled frames (``cone-perception eval --box-model-out``,
:func:`cone_perception.evaluation.boxfit.measure_box_model`) and stored beside the model file
(:func:`cone_perception.attitude.box_files.read_box_model`). :meth:`BoxModel.correct` turns detected
boxes into the label-like boxes the fit's cone model expects. :data:`DEFAULT_BOX_MODEL` (no shift, a wide
per-cone spread) is the conservative stand-in for a model without one.

Each network's boxes are read through that network's own :class:`BoxReading` (issue 26f): the band's model's,
and, where the far strip runs a model of its own (``far_model``), that model's for the strip's boxes. On
rendered drives a reading is a box-top table instead (:data:`RENDERED_TABLES`). ROS-free, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Lower edges of the height buckets (px at the model input); the last is open.
BOX_MODEL_BUCKETS_PX = (8.0, 12.0, 24.0, 48.0)


@dataclass(frozen=True)
class BoxModel:
    """Per height bucket (lower edges ``buckets_px`` at the model input, the last open): the medians of
    ``height_ratio``, ``top_low`` and ``bottom_high`` (module doc), the matched cones ``counts``;
    ``sigma_rel``: the spread (1.4826 MAD) of the top offset, the fit's per-cone uncertainty as a
    fraction of the box height (labelling noise included); ``input_scale``: model input px per full-image px the detector ran at (buckets are
    looked up at ``box height * input_scale``); ``source``: ``measured`` (with ``note`` saying on what)
    or ``default``."""

    buckets_px: tuple = BOX_MODEL_BUCKETS_PX
    height_ratio: tuple = (1.0, 1.0, 1.0, 1.0)
    top_low: tuple = (0.0, 0.0, 0.0, 0.0)
    bottom_high: tuple = (0.0, 0.0, 0.0, 0.0)
    counts: tuple = (0, 0, 0, 0)
    sigma_rel: float = 0.08
    input_scale: float = 0.5
    source: str = "default"
    note: str = ""
    by_class: dict | None = None  # class name -> {"height_ratio", "top_low", "bottom_high", "count"} (report only)

    def measured(self, height_px: np.ndarray, input_scale: float | None = None) -> np.ndarray:
        """(N,) bool: boxes (N,) full-image px high whose height at the model input (``input_scale``, default the
        model's) falls in a bucket with measured cones (``counts`` > 0; below the first edge: the first bucket). A
        box in a bucket without measurements is unknown, not exact (issue 41): :func:`read_boxes` reads it through
        another measured model or leaves it out of the fit. A model with no measured bucket at all (the default
        stand-in) measures every size the same, by design: all True."""
        s = self.input_scale if input_scale is None else float(input_scale)
        h = np.asarray(height_px, dtype=np.float64).ravel() * s
        have = np.asarray(self.counts) > 0
        if not have.any():
            return np.ones(h.shape, dtype=bool)
        bucket = np.clip(np.searchsorted(np.asarray(self.buckets_px, dtype=np.float64), h, side="right") - 1, 0, None)
        return have[bucket]

    def _table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Bucket centres (px at the model input) and values of the buckets with cones (all when none has)."""
        edges = np.asarray(self.buckets_px, dtype=np.float64)
        centres = np.append(0.5 * (edges[:-1] + edges[1:]), 1.5 * edges[-1])
        have = np.asarray(self.counts) > 0
        if not have.any():
            have[:] = True
        return (centres[have], np.asarray(self.height_ratio, np.float64)[have], np.asarray(self.top_low, np.float64)[have],
                np.asarray(self.bottom_high, np.float64)[have])

    def at(self, height_px: np.ndarray, input_scale: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(height_ratio, top_low, bottom_high)`` (N,) for detected boxes (N,) full-image px high,
        interpolated between bucket centres, ends held."""
        s = self.input_scale if input_scale is None else float(input_scale)
        h = np.asarray(height_px, dtype=np.float64) * s
        c, r, t, b = self._table()
        return np.interp(h, c, r), np.interp(h, c, t), np.interp(h, c, b)

    def correct(self, boxes: np.ndarray, input_scale: float | None = None) -> np.ndarray:
        """(N, 4) detected boxes (u1, v1, u2, v2 full-image px) -> the labelled boxes they stand for: the
        labelled height is the detected one over the ratio; the top moves up by ``top_low``, the bottom
        down by ``bottom_high`` of it. Columns u unchanged."""
        b = np.array(boxes, dtype=np.float64).reshape(-1, 4)
        if len(b) == 0:
            return b
        r, t, bo = self.at(b[:, 3] - b[:, 1], input_scale)
        label_h = (b[:, 3] - b[:, 1]) / np.maximum(r, 1e-3)
        b[:, 1] -= t * label_h
        b[:, 3] += bo * label_h
        return b

    def detected(self, boxes: np.ndarray, input_scale: float | None = None) -> np.ndarray:
        """The inverse of :meth:`correct`: (N, 4) labelled boxes (u1, v1, u2, v2 full-image px) -> the boxes this
        detector draws around such cones, by the medians: the top moves down by ``top_low``, the bottom up by
        ``bottom_high`` of the labelled height (looked up at the detected height, one refinement). Columns u
        unchanged. Rendered drives use it to give a detector's boxes the real frames' behaviour
        (:mod:`cone_perception.synth.boxlook`)."""
        b = np.array(boxes, dtype=np.float64).reshape(-1, 4)
        if len(b) == 0:
            return b
        label_h = b[:, 3] - b[:, 1]
        r, _, _ = self.at(label_h, input_scale)
        _, t, bo = self.at(label_h * r, input_scale)
        b[:, 1] += t * label_h
        b[:, 3] -= bo * label_h
        return b

    def median_row(self, i: int) -> str:
        """One bucket as text (cards, warnings)."""
        lo = self.buckets_px[i]
        hi = self.buckets_px[i + 1] if i + 1 < len(self.buckets_px) else None
        name = f"{lo:g}-{hi:g} px" if hi is not None else f">= {lo:g} px"
        return (f"{name}: {self.counts[i]} cones, height x{self.height_ratio[i]:.3f}, top {100 * self.top_low[i]:+.1f} % low, "
                f"bottom {100 * self.bottom_high[i]:+.1f} % high")

    def to_dict(self) -> dict:
        """Plain types (the sidecar's ``box_model`` mapping)."""
        d = {"source": self.source, "note": self.note, "input_scale": float(self.input_scale),
             "sigma_rel": round(float(self.sigma_rel), 4), "buckets_px": [float(x) for x in self.buckets_px],
             "height_ratio": [round(float(x), 4) for x in self.height_ratio],
             "top_low": [round(float(x), 4) for x in self.top_low],
             "bottom_high": [round(float(x), 4) for x in self.bottom_high], "counts": [int(x) for x in self.counts]}
        if self.by_class:
            d["by_class"] = self.by_class
        return d

    @classmethod
    def from_dict(cls, d: dict, where: str = "box_model") -> "BoxModel":
        """The inverse of :meth:`to_dict`; ValueError naming ``where`` and the field for a bad mapping."""
        if not isinstance(d, dict):
            raise ValueError(f"{where}: must be a mapping")
        buckets = d.get("buckets_px")
        if (not isinstance(buckets, list) or not buckets
                or not all(isinstance(x, (int, float)) and np.isfinite(x) and x > 0 for x in buckets)
                or any(b <= a for a, b in zip(buckets, buckets[1:]))):
            raise ValueError(f"{where}.buckets_px: must be a non-empty, strictly increasing list of positive px")
        n = len(buckets)
        vals = {}
        for k in ("height_ratio", "top_low", "bottom_high", "counts"):
            v = d.get(k)
            if not isinstance(v, list) or len(v) != n or not all(isinstance(x, (int, float)) and np.isfinite(x) for x in v):
                raise ValueError(f"{where}.{k}: must be a list of {n} finite numbers (one per bucket)")
            vals[k] = tuple(v)
        if not all(float(c) == int(c) and c >= 0 for c in vals["counts"]):
            raise ValueError(f"{where}.counts: must be whole numbers >= 0 (cones measured in each bucket)")
        if str(d.get("source", "measured")) == "measured" and not any(vals["counts"]):
            raise ValueError(f"{where}.counts: all 0 in a measured box model: no bucket was measured")
        if not all(0.3 <= r <= 3.0 for r in vals["height_ratio"]):
            raise ValueError(f"{where}.height_ratio: values must lie within 0.3..3")
        for k in ("sigma_rel", "input_scale"):
            if not isinstance(d.get(k), (int, float)) or not d[k] > 0:
                raise ValueError(f"{where}.{k}: must be a positive number")
        return cls(tuple(float(x) for x in buckets), vals["height_ratio"], vals["top_low"], vals["bottom_high"],
                   tuple(int(x) for x in vals["counts"]), float(d["sigma_rel"]), float(d["input_scale"]),
                   str(d.get("source", "measured")), str(d.get("note", "")), d.get("by_class"))


#: A model without a measured box model: no shift (the boxes taken as the labels) and a per-cone spread of
#: 8 % of the box height (above the shipped models' measured 6.6-6.8 %, the fit's own 3 %), so its fits count
#: for less and fall back to the calibration sooner.
DEFAULT_BOX_MODEL = BoxModel()


@dataclass(frozen=True)
class BoxReading:
    """How the image fit reads one network's boxes: through its measured box model ``box_model`` (real frames:
    boxes corrected to the labels' first), or, where that is None, through the rendered box-top table ``table``
    (``(box height px, px)`` pairs, full-image px, interpolated, ends held: how far that network's box tops stand
    above the cones' tips on rendered drives beyond the fit's ``top_bias_px``; empty: not at all). ``what``: in
    words (logs, ``/diagnostics``)."""

    box_model: BoxModel | None = None
    table: tuple = ()
    what: str = ""


def box_top_extra_px(height_px: np.ndarray, table) -> np.ndarray:
    """(N,) px the detector's box tops stand above the cones' (``table``: (box height px, px) pairs,
    interpolated, ends held; empty = zero) for boxes (N,) px high."""
    h = np.asarray(height_px, dtype=np.float64)
    if not table:
        return np.zeros(h.shape)
    return np.interp(h, [a for a, _ in table], [b for _, b in table])


def range_cuts(n: int, far: np.ndarray | None, max_range_m: float, far_max_range_m: float | None) -> np.ndarray:
    """(n,) the image fit's range cut of each of n boxes (m): ``far_max_range_m`` for the far strip's network's (``far``,
    (n,) bool; at full resolution a cone at 25 m is still 12 px tall at its input, 6 px in the band's halved input),
    else ``max_range_m``; ``far`` or ``far_max_range_m`` None: ``max_range_m`` for all."""
    rng = np.full(n, float(max_range_m))
    if far is not None and far_max_range_m is not None:
        rng[np.asarray(far, dtype=bool).ravel()] = float(far_max_range_m)
    return rng


def read_boxes(boxes: np.ndarray, far: np.ndarray | None, band: BoxReading, far_reading: BoxReading | None,
               sigma_rel: float, counts=None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(N, 4) boxes (full-image px) each through the reading of the network that drew it (``far``: (N,) bool, the far
    strip's, read through ``far_reading``; None, or no ``far_reading``: all through ``band``): ``(boxes corrected by
    a measured box model, (N,) px their tops stand above the cones' by a rendered table, (N,) relative per-cone
    sigma (at least the fit's ``sigma_rel``), (N,) relative scatter of the box height from frame to frame: the box
    model's spread, 0 with a table, (N,) bool: read at all)``.

    A box whose measured box model has no measurement at its size (:meth:`BoxModel.measured`) is unknown, not exact:
    a far-strip box goes through the band's box model where that one has measured its size (at the box's size in the
    band model's input px), else it is left out of the fit (``False`` in the last array); both counted in ``counts``
    (its ``read_by_band`` and ``unmeasured``: :class:`~cone_perception.attitude.model.AttitudeCounts`), where given."""
    n = len(boxes)
    out, extra, rel = boxes.copy(), np.zeros(n), np.full(n, float(sigma_rel))
    scatter = np.zeros(n)
    heights = boxes[:, 3] - boxes[:, 1]
    use_far = far is not None and far_reading is not None
    far = np.asarray(far, dtype=bool).ravel() if use_far else np.zeros(n, dtype=bool)
    band_known = band.box_model.measured(heights) if band.box_model is not None else np.ones(n, dtype=bool)
    far_bm = far_reading.box_model if use_far else None
    far_known = far_bm.measured(heights) if far_bm is not None else np.ones(n, dtype=bool)
    own = far & far_known  # the strip's boxes its own reading knows
    by_band = far & ~far_known & band_known  # the rest through the band's measured model, where it knows their size
    band_m = (~far & band_known) | by_band
    used = own | band_m
    if counts is not None:
        counts.read_by_band += int(by_band.sum())
        counts.unmeasured += int((~used).sum())
    for rd, m in ((band, band_m), (far_reading, own)):
        if not m.any():
            continue
        if rd.box_model is not None:
            out[m] = rd.box_model.correct(boxes[m])
            rel[m] = max(sigma_rel, rd.box_model.sigma_rel)
            scatter[m] = rd.box_model.sigma_rel
        else:
            extra[m] = box_top_extra_px(heights[m], rd.table)
    return out, extra, rel, scatter, used


#: Model input px per full-image px of the far strip: it runs at full resolution (``detector/farband.py``), so the
#: strip's network's box model is looked up at the strip's own px (:func:`~cone_perception.attitude.box_files.far_reading_for`),
#: whatever scale it was measured at: a box model's buckets are px at the model input, and its measurement is best
#: made where one model-input px is one px of the labelled frames' own detail (docs/attitude.md, "Box model").
STRIP_INPUT_SCALE = 1.0

#: The shipped far model's box-top table on rendered drives (``models/cone_detector_far.pt`` run at full
#: resolution in the strip; (box height px, px), full-image px): the median top-row residual at the true
#: attitude per box height (negative: its box tops lie below the cones' tips), measured on tuning drives with
#: ``docs/experiments/far_box_model.py``, which also scores half of it (the band's table is half of the band
#: model's residual); figures in docs/benchmarks.md "The far model's box model (issue 26f)".
FAR_MODEL_TOP_BIAS_EXTRA_PX: tuple = ((14.0, -0.52), (18.0, -0.51), (22.0, -0.28), (28.0, -0.35), (40.0, -0.42),
                                      (72.0, -0.61))

#: Rendered box-top tables of the shipped models that have their own, by model file name; any other model's
#: boxes are read through the band's table (``ImageAttitudeConfig.top_bias_extra_px``, the default model's).
RENDERED_TABLES = {"cone_detector_far.pt": FAR_MODEL_TOP_BIAS_EXTRA_PX}
