"""The far band: the image rows near the horizon run a second time at full resolution.

At the car's 960x288 input (the band halved), cones beyond about 15 m are under 12 px tall and
most of them are missed. The far band cuts a strip of full-resolution rows (``V0,V1``, the whole
image width, no downscale) where those cones stand, runs the detector on it as well, and merges
its boxes with the band's:

* a far-band box that touches the strip's top or bottom edge (within ``EDGE_PX``) is dropped:
  it is a nearer cone cut by the strip, which the band sees whole;
* of a band box and a far-band box of one cone and class (:func:`same_cone`: the halved band's box of a
  small cone is too rough for IoU to pair them) one is kept (:func:`seen_by_far`): the far band's while its
  score is at least ``FAR_PREFER`` (half) of the band box's, else the band's (a low-score far box must not
  remove a confident band box); of a cone the band sees at least ``FAR_MAX_BAND_PX`` tall the band's, while its
  score is at least half the far box's (a near cone's box from the far model, trained for far cones, often covers
  only its top);
* the rest join the band's boxes, and one class-aware NMS keeps the best box of each cone.

Its rows (``far_rows``, one spelling for the node parameter and the commands' ``--far-rows``):

* ``auto`` (the default): the calibration's far strip (:mod:`cone_perception.geometry.strip`): the rows
  where cones 15-40 m ahead stand, as tall as the attitude margins need (``example_mainhoop``: 96 rows),
  moved each frame with the attitude the pipeline has (the previous frame's); off where the calibration
  has no ``camera_matrix`` or says ``far_strip: off`` (said, never silently);
* ``V0,V1``: those rows, fixed (the hand-set override);
* ``none`` or empty (the commands also take ``off``): no far band.

The band itself may run in two (``band_split``, :func:`band_split_for`, :class:`SplitDetector`): its near rows,
where every cone is large, at a quarter of full resolution (docs/detector.md, "Row-scaled band").

Cost: one more forward on ``width x (V1 - V0)`` px (1920x96: 0.67x the pixels of 960x288).
What it is worth: ``models/cone_detector.md``, "Small, far cones"; docs/benchmarks.md, "Far strip".
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from ..classes import CLASS_NAMES
from ..crop import CropSpec
from ..errors import ConfigError
from ..geometry.strip import DEFAULT_STRIP, SPLIT_DOWNSCALE, StripPlan, plan_band, plan_split
from ..model.postprocess import nms_per_class
from ..params import DEFAULT_IOU
from .detector import Detector

#: A far-band box whose top or bottom is this close to the strip's edge (full-image px) is a cut cone.
EDGE_PX = 2.0
FAR_PREFER = 0.5  # a far box wins over a band box of its cone while scored >= this x the band box's
#: ... while the band box is under this tall (full-image px); from this height on the band's box wins while scored >=
#: FAR_PREFER x the far box's: a cone the band sees this large is outside what the strip is for, and the far
#: model's box of it is the worse one (on the tuning drives, against the rendered box:
#: median IoU 0.85 far / 0.71 band under 16 px, 0.94 / 0.95 at 48-64 px, 0.62 / 0.91 from 96 px; docs/validation.md,
#: "Parts of a cone")
FAR_MAX_BAND_PX = 64.0
FAR_SAME_CLASS = True  # pair only boxes of one class (seen_by_far)
#: ``far_rows`` values: the calibration's strip, and no far band (``none``; the commands also take ``off``,
#: which a ROS parameter cannot hold: ``-p far_rows:=off`` reads as a boolean).
FAR_ROWS_AUTO = "auto"
FAR_ROWS_OFF = ("none", "", "off")


@dataclass(frozen=True)
class FarRows:
    """What a ``far_rows`` value means for one calibration (:func:`far_rows_for`): the strip's crop at the
    calibration's attitude (None: no far band), its plan when it moves with the attitude, and in words."""

    crop: CropSpec | None
    plan: StripPlan | None
    what: str


def far_rows_for(rows: str | None, calib, source: str = "far_rows") -> FarRows:
    """``auto`` / ``none`` (``""``, ``off``) / ``"V0,V1"`` (None: ``auto``) for a :class:`~cone_perception.geometry.calib.Calibration`.
    ConfigError naming ``source`` for bad rows; the calibration's own strip was checked at its load."""
    rows = FAR_ROWS_AUTO if rows is None else str(rows).strip()
    if rows.lower() in FAR_ROWS_OFF:
        return FarRows(None, None, f"far band off ({source} {rows or 'empty'})")
    if rows.lower() != FAR_ROWS_AUTO:
        crop = far_band_crop(rows, calib.image_width, calib.image_height, calib.crop, source)
        return FarRows(crop, None, f"far band rows {crop.v0}-{crop.v1} ({crop.height_full_px} rows, fixed: {source})")
    if calib.far_strip is None:
        return FarRows(None, None, f"far strip off (the calibration {calib.source} says far_strip: off)")
    if calib.camera_matrix is None:
        return FarRows(None, None, f"far strip off: the calibration {calib.source} has no camera_matrix to place it "
                                   f"with ({source} V0,V1 sets rows by hand)")
    plan = calib.strip_plan()
    crop = far_band_crop(plan.rows, calib.image_width, calib.image_height, calib.crop, f"{calib.source}: far_strip")
    s = plan.spec
    return FarRows(crop, plan, f"far strip rows {crop.v0}-{crop.v1} ({plan.height} rows: cones {s.near_m:g}-{s.far_m:g} m "
                               f"ahead, margins {s.pitch_margin_deg:g} deg pitch / {s.roll_margin_deg:g} deg roll), "
                               "moved with the attitude")


#: ``band_rows`` values: the calibration's own ``crop`` (the hand-set band, the default) and the band placed
#: from the calibration (:func:`band_rows_for`).
BAND_ROWS_CROP = "crop"
BAND_ROWS_AUTO = "auto"


@dataclass(frozen=True)
class BandRows:
    """What a ``band_rows`` value means for one calibration (:func:`band_rows_for`): the band's crop (the
    calibration's columns and downscale), its plan when placed from the calibration, and in words."""

    crop: CropSpec
    plan: StripPlan | None
    what: str

    def apply(self, calib):
        """``calib`` with this band as its ``crop`` (the one home of the band's rows: the adapter, the detector's
        input size, the mapping's cut boxes, the tracker's field of view and ``replay``'s expected cones read it)."""
        return calib if self.crop == calib.crop else replace(calib, crop=self.crop)


def band_rows_for(rows: str | None, calib, far_rows: str | None = FAR_ROWS_AUTO, source: str = "band_rows") -> BandRows:
    """``crop`` (None: the calibration's ``crop``) / ``auto`` / ``"V0,V1"`` for a calibration; the band's columns
    and downscale stay the calibration's. ``auto``: the rows from the top of the tallest cone as far ahead as the
    band must see (with the far strip ``far_rows`` auto on: the strip's ``near_m``, nearer cones are cut by the
    strip; else the calibration's ``max_range_m``) down to the hand-set crop's bottom, with the strip's attitude
    margins, a multiple of 32 rows at the band's scale, inside the image (:func:`~..geometry.strip.plan_band`);
    the calibration's ``crop`` where it has no ``camera_matrix`` (said). ConfigError naming ``source`` for a bad
    value or rows outside the image or not divisible by the downscale."""
    rows = BAND_ROWS_CROP if rows is None else str(rows).strip()
    band = calib.crop
    if rows.lower() == BAND_ROWS_CROP:
        return BandRows(band, None, f"band rows {band.v0}-{band.v1} (the calibration's crop)")
    if rows.lower() == BAND_ROWS_AUTO:
        if calib.camera_matrix is None:
            return BandRows(band, None, f"band rows {band.v0}-{band.v1}: the calibration {calib.source} has no "
                                        f"camera_matrix to place the band with (its crop)")
        strip = calib.strip_plan() if far_rows_for(far_rows, calib, "far_rows").plan is not None else None
        top_m = strip.spec.near_m if strip is not None else float(calib.max_range_m)
        cam = calib.pinhole_camera()
        plan = plan_band(cam, band.v1, top_m, band.downscale, calib.far_strip or DEFAULT_STRIP, calib.source, source)
        crop = replace(band, v0=plan.top0, v1=plan.top0 + plan.height)
        crop.validate(calib.image_width, calib.image_height, source)
        edge = ", ending at the image's edge" if crop.v0 == 0 or crop.v1 == calib.image_height else ""
        return BandRows(crop, plan, f"band rows {crop.v0}-{crop.v1} placed from the calibration (cones "
                                    f"{plan.spec.near_m:.1f}-{top_m:g} m ahead whole, margins "
                                    f"{plan.spec.pitch_margin_deg:g} deg pitch / {plan.spec.roll_margin_deg:g} deg roll"
                                    f"{edge})")
    try:
        v0, v1 = (int(t) for t in rows.split(","))
    except ValueError:
        raise ConfigError(source, None, f"expected crop, auto or two image rows V0,V1, got {rows!r}") from None
    if not 0 <= v0 < v1 <= calib.image_height:
        raise ConfigError(source, None, f"rows {v0},{v1}: need 0 <= V0 < V1 <= {calib.image_height} (the "
                                        f"{calib.image_width}x{calib.image_height} image)")
    crop = replace(band, v0=v0, v1=v1)
    try:
        crop.validate(calib.image_width, calib.image_height, source)
    except ConfigError as e:
        raise ConfigError(source, None, e.message) from None
    return BandRows(crop, None, f"band rows {v0}-{v1} (fixed: {source})")


def far_band_crop(rows: str | tuple[int, int], image_width: int, image_height: int, band: CropSpec,
                  source: str = "far_rows") -> CropSpec:
    """``"V0,V1"`` (or a pair) -> the far band's crop: rows V0..V1, the whole width, downscale 1.

    ConfigError naming ``source`` unless the rows lie inside the image, overlap the band (a far
    band beside the band would see cones the mapping was not calibrated for) and span 32-1024 rows."""
    if isinstance(rows, str):
        try:
            v0, v1 = (int(float(t)) for t in rows.split(","))
        except ValueError:
            raise ConfigError(source, None, f"expected two image rows V0,V1, got {rows!r}") from None
    else:
        v0, v1 = (int(r) for r in rows)
    if not 0 <= v0 < v1 <= image_height:
        raise ConfigError(source, None, f"rows {v0},{v1} are not inside the {image_width}x{image_height} image")
    if v1 <= band.v0 or v0 >= band.v1:
        raise ConfigError(source, None, f"rows {v0},{v1} do not overlap the band's rows {band.v0},{band.v1}")
    if not 32 <= v1 - v0 <= 1024:
        raise ConfigError(source, None, f"{v1 - v0} rows: the far band needs 32..1024 rows")
    crop = CropSpec(v0, v1, 0, image_width, 1)
    crop.validate(image_width, image_height, source)
    return crop


def drop_cut_boxes(boxes: np.ndarray, crop: CropSpec, edge_px: float = EDGE_PX) -> np.ndarray:
    """``BOX_DTYPE`` boxes of a strip minus those touching its top or bottom edge (cones the strip cuts)."""
    keep = (boxes["v1"] > crop.v0 + edge_px) & (boxes["v2"] < crop.v1 - edge_px)
    return boxes[keep]


def same_cone(band_boxes: np.ndarray, far_boxes: np.ndarray, same_class: bool = FAR_SAME_CLASS) -> np.ndarray:
    """(band, far) bool matrix: the pair are boxes of one cone (centres within half the taller box's height,
    heights within 2x of each other; with ``same_class`` of one class too). The halved band's box of a 10 px
    cone is a pixel or two off at full scale, so IoU often misses such a pair (both kept: a false cone)."""
    if len(band_boxes) == 0 or len(far_boxes) == 0:
        return np.zeros((len(band_boxes), len(far_boxes)), bool)
    bc = np.stack([band_boxes["u1"] + band_boxes["u2"], band_boxes["v1"] + band_boxes["v2"]], 1) / 2
    fc = np.stack([far_boxes["u1"] + far_boxes["u2"], far_boxes["v1"] + far_boxes["v2"]], 1) / 2
    bh = (band_boxes["v2"] - band_boxes["v1"])[:, None]
    fh = (far_boxes["v2"] - far_boxes["v1"])[None, :]
    d = np.hypot(bc[:, None, 0] - fc[None, :, 0], bc[:, None, 1] - fc[None, :, 1])
    m = (d <= 0.5 * np.maximum(bh, fh)) & (bh <= 2 * fh) & (fh <= 2 * bh)
    if same_class:
        m &= band_boxes["class_id"][:, None] == far_boxes["class_id"][None, :]
    return m


def seen_by_far(band_boxes: np.ndarray, far_boxes: np.ndarray, prefer: float = FAR_PREFER,
                same_class: bool = FAR_SAME_CLASS, max_band_px: float = FAR_MAX_BAND_PX) -> tuple[np.ndarray, np.ndarray]:
    """(band box gives way, far box gives way), a bool per box: of each pair of boxes of one cone
    (:func:`same_cone`) one is kept. Where the band box is under ``max_band_px`` tall (full-image px), the far
    band's, placed at full resolution, wins while its score is at least ``prefer`` times the band box's (a low-score
    far box must not remove a confident band box: at ``detect --conf 0.001`` it cost recall, issue 26); where it is
    taller, the band's wins while its score is at least ``prefer`` times the far box's (the far model's box of a
    cone the band sees large is the worse one, issue 41)."""
    m = same_cone(band_boxes, far_boxes, same_class)
    small = ((band_boxes["v2"] - band_boxes["v1"]) < max_band_px)[:, None]
    fs, bs = far_boxes["score"][None, :], band_boxes["score"][:, None]
    far_wins = m & np.where(small, fs >= prefer * bs, prefer * fs > bs)
    return far_wins.any(1), (m & ~far_wins).any(0)


def merge_boxes(band_boxes: np.ndarray, far_boxes: np.ndarray, iou: float = DEFAULT_IOU,
                prefer: float = FAR_PREFER, same_class: bool = FAR_SAME_CLASS,
                max_band_px: float = FAR_MAX_BAND_PX) -> np.ndarray:
    """Boxes of the band and of the far band (``BOX_DTYPE``, full-image px) -> one set, best first: of a band
    box and a far box of one cone one gives way (:func:`seen_by_far`), then one class-aware NMS over both
    keeps the best box of what still overlaps."""
    if len(far_boxes) == 0:
        return band_boxes
    band_out, far_out = seen_by_far(band_boxes, far_boxes, prefer, same_class, max_band_px)
    both = np.concatenate([band_boxes[~band_out], far_boxes[~far_out]])
    xywh = np.stack([both["u1"], both["v1"], both["u2"] - both["u1"], both["v2"] - both["v1"]], 1)
    keep = nms_per_class(xywh, both["score"], both["class_id"], 0.0, iou)
    return both[keep]


def drawn_by_far(merged: np.ndarray, far_boxes: np.ndarray) -> np.ndarray:
    """(N,) bool: which of the boxes ``merged`` (what :func:`merge_boxes` kept, or any subset of it) are the far
    band's (``far_boxes``, its input): the merge keeps rows of its inputs as they are, so a box is the far band's
    where its record (every field) is one of ``far_boxes``'s. The image attitude reads those through the far
    network's box model (issue 26f)."""
    if len(merged) == 0 or len(far_boxes) == 0:
        return np.zeros(len(merged), bool)

    def fields(r: np.ndarray) -> np.ndarray:  # every field's value, compared exactly (not the padding bytes)
        return np.column_stack([r[name].astype(np.float64) for name in r.dtype.names])

    m, f = fields(merged), fields(far_boxes)
    return (m[:, None, :] == f[None, :, :]).all(axis=2).any(axis=1)


def check_far_classes(band_detector, far_detector, source: str = "far_model") -> None:
    """ConfigError naming ``source`` (the far model's option) unless the far band's model finds the same
    cone classes as the band's: their boxes merge into one set, and a class only one of them knows would
    come and go with the cone's distance. Detectors without a ``class_map`` (test doubles) are not checked."""
    band, far = getattr(band_detector, "class_map", None), getattr(far_detector, "class_map", None)
    if band is None or far is None:
        return
    band, far = {int(c) for c in band}, {int(c) for c in far}
    if band != far:
        def names(ids):
            return ", ".join(CLASS_NAMES[i] for i in sorted(ids)) or "none"
        raise ConfigError(source, getattr(far_detector, "source", None),
                          f"the far band's model has the classes [{names(far)}], the band's model [{names(band)}]: "
                          f"only in the far model: [{names(far - band)}], only in the band's: [{names(band - far)}]")


@dataclass
class FarBand:
    """The far band of one camera: its crop and the detector built for its size (``Detector.load_for_band``).

    ``model_source``: the option the far band's model came from (``far_model``, ``--far-model``), named by
    :meth:`check_classes`'s error."""

    crop: CropSpec  # the strip's rows at the calibration's attitude (fixed rows: always these)
    detector: object  # a Detector (anything with detect(bgr, crop) -> BOX_DTYPE and a timing dict)
    model_source: str = "far_model"
    plan: StripPlan | None = None  # the calibration's strip, moved with the attitude; None: fixed rows
    verifier: object | None = None  # a second look at the strip's doubtful boxes (detector/verifier.py), or None

    def crop_for(self, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> tuple[CropSpec, bool]:
        """(this frame's strip crop, clamped): the strip moved with the attitude offset (degrees) and kept
        inside the image (``clamped``: it had to be); fixed rows do not move."""
        if self.plan is None:
            return self.crop, False
        top, clamped = self.plan.top_for(pitch_deg, roll_deg)
        if top == self.crop.v0:
            return self.crop, clamped
        return replace(self.crop, v0=top, v1=top + self.crop.height_full_px), clamped

    def check_classes(self, band_detector) -> None:
        """ConfigError naming :attr:`model_source` unless this band's model has the band model's classes
        (:func:`check_far_classes`); the Pipeline calls it before the first frame."""
        check_far_classes(band_detector, self.detector, self.model_source)

    @classmethod
    def load(cls, model, rows: str | tuple[int, int], image_width: int, image_height: int, band: CropSpec,
             source: str = "far_rows", model_source: str = "far_model", verifier=None, **detector_kw) -> "FarBand":
        """The far band of ``rows`` with ``model`` (the band's own, or a far model: ``model_source`` names
        its option in errors) built for its strip (``Detector.load_for_band``); ``verifier``: its second look
        (:func:`~cone_perception.detector.verifier.load_verifier`) or None."""
        crop = far_band_crop(rows, image_width, image_height, band, source)
        det = Detector.load_for_band(model, (crop.out_width, crop.out_height), **detector_kw)
        det.warmup()
        return cls(crop, det, model_source, verifier=verifier)

    @classmethod
    def for_calibration(cls, model, rows: str | None, calib, source: str = "far_rows",
                        model_source: str = "far_model", say=None, verifier=None, **detector_kw) -> "FarBand | None":
        """The far band ``rows`` (:func:`far_rows_for`: ``auto`` = the calibration's strip) of ``calib`` with
        ``model`` built for it, or None when off; ``say(text)`` is told which (e.g. ``print``); ``verifier``: its
        second look or None."""
        fr = far_rows_for(rows, calib, source)
        if say is not None:
            say(fr.what)
        if fr.crop is None:
            return None
        det = Detector.load_for_band(model, (fr.crop.out_width, fr.crop.out_height), **detector_kw)
        det.warmup()
        return cls(fr.crop, det, model_source, fr.plan, verifier)

    def detect(self, strip_bgr: np.ndarray, crop: CropSpec | None = None) -> np.ndarray:
        """Full-resolution strip ``(V1 - V0, W, 3)`` BGR cut at ``crop`` (this frame's rows, :meth:`crop_for`;
        default :attr:`crop`) -> its boxes, cut cones dropped (full-image px)."""
        crop = crop or self.crop
        return drop_cut_boxes(self.detector.detect(strip_bgr, crop), crop)

    def verify(self, boxes: np.ndarray, strip_bgr: np.ndarray, crop: CropSpec | None = None) -> np.ndarray:
        """``boxes`` (the band's and the strip's, merged) less the doubtful ones wholly inside the strip's rows
        (``crop``, default :attr:`crop`) where the verifier, looking at the strip's full-resolution pixels, sees no
        cone (detector/verifier.py; counted there). The band's boxes are judged too: a strip box the verifier drops
        would otherwise leave the band's box of the same place in its stead. Without a verifier: ``boxes``."""
        if self.verifier is None or len(boxes) == 0:
            return boxes
        crop = crop or self.crop
        inside = ((boxes["v1"] >= crop.v0) & (boxes["v2"] <= crop.v1) & (boxes["u1"] >= crop.u0)
                  & (boxes["u2"] <= crop.u1))
        if not inside.any():
            return boxes
        drop = np.zeros(len(boxes), bool)
        drop[inside] = self.verifier.drops(strip_bgr, boxes[inside], crop.u0, crop.v0, crop.downscale)
        return boxes[~drop]

    def merged(self, band_boxes: np.ndarray, strip_bgr: np.ndarray,
               crop: CropSpec | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(the band's boxes merged with the strip's (:func:`merge_boxes`) and verified (:meth:`verify`), which of
        them the strip drew (:func:`drawn_by_far`))``."""
        iou = getattr(self.detector, "iou", DEFAULT_IOU)
        far_boxes = self.detect(strip_bgr, crop)
        merged = self.verify(merge_boxes(band_boxes, far_boxes, iou), strip_bgr, crop)
        return merged, drawn_by_far(merged, far_boxes)


#: ``band_split`` values: the band in one piece (the default) and split from the calibration (:func:`band_split_for`).
BAND_SPLIT_OFF = ("none", "off", "")
BAND_SPLIT_AUTO = "auto"


@dataclass(frozen=True)
class BandSplit:
    """What a ``band_split`` value means for one calibration (:func:`band_split_for`): the upper band (the band's
    downscale) and the near band (``near.downscale``), both inside the calibration's ``crop``, or None (one band)."""

    upper: CropSpec | None
    near: CropSpec | None
    what: str


def band_split_for(value: str | None, calib, source: str = "band_split") -> BandSplit:
    """``none`` (None, empty, ``off``: one band) / ``auto`` / ``"N0,U1"`` for a calibration (its ``crop``, after
    ``band_rows``). ``auto``: :func:`~..geometry.strip.plan_split` from the calibration (its ``far_strip`` margins);
    ``N0,U1``: the near band from row N0 to the band's bottom at a quarter of full resolution, the upper band from
    the band's top to row U1 at the band's downscale. ConfigError naming ``source`` for a bad value, a calibration
    without ``camera_matrix`` for ``auto``, rows outside the band or bands that do not overlap."""
    v = "none" if value is None else str(value).strip().lower()
    band = calib.crop
    if v in BAND_SPLIT_OFF:
        return BandSplit(None, None, f"band {band.v0}-{band.v1} in one piece at 1/{band.downscale}")
    if band.downscale * 2 not in (SPLIT_DOWNSCALE,) or band.width_full_px % SPLIT_DOWNSCALE:
        raise ConfigError(source, None, f"needs a band at downscale {SPLIT_DOWNSCALE // 2} whose width is divisible by "
                                        f"{SPLIT_DOWNSCALE}, got downscale {band.downscale}, {band.width_full_px} px")
    if v == BAND_SPLIT_AUTO:
        if calib.camera_matrix is None:
            raise ConfigError(source, None, f"auto needs a camera_matrix in the calibration {calib.source}: set N0,U1")
        p = plan_split(calib.pinhole_camera(), (band.v0, band.v1), band.downscale, calib.far_strip or DEFAULT_STRIP,
                       source=calib.source, field=source)
        (u0, u1), (n0, _) = p.upper, p.near
        how = f"placed from the calibration (small cones nearer than {p.split_m:.1f} m at least {p.min_px:g} px there)"
    else:
        try:
            n0, u1 = (int(t) for t in v.split(","))
        except ValueError:
            raise ConfigError(source, None, f"expected none, auto or two image rows N0,U1, got {value!r}") from None
        how = f"fixed: {source}"
        if not band.v0 < n0 < u1 < band.v1:
            raise ConfigError(source, None, f"rows {n0},{u1}: need {band.v0} < N0 < U1 < {band.v1} (inside the band, "
                                            "the near band from N0 overlapping the upper band up to U1)")
        if (band.v1 - n0) % SPLIT_DOWNSCALE or (u1 - band.v0) % band.downscale:
            raise ConfigError(source, None, f"rows {n0},{u1}: the near band's rows must divide by {SPLIT_DOWNSCALE}, "
                                            f"the upper band's by {band.downscale}")
    upper = replace(band, v1=u1)
    near = replace(band, v0=n0, downscale=SPLIT_DOWNSCALE)
    return BandSplit(upper, near, f"band split: rows {upper.v0}-{upper.v1} at 1/{upper.downscale} "
                                  f"({upper.out_width}x{upper.out_height}), rows {near.v0}-{near.v1} at "
                                  f"1/{near.downscale} ({near.out_width}x{near.out_height}), {how}")


def drop_edge_boxes(boxes: np.ndarray, top: float | None = None, bottom: float | None = None,
                    edge_px: float = EDGE_PX) -> np.ndarray:
    """``BOX_DTYPE`` boxes minus those touching row ``top`` or row ``bottom`` (within ``edge_px``; None: not that
    edge): cones cut by an inner edge of a split band, seen whole by the other part."""
    keep = np.ones(len(boxes), bool)
    if top is not None:
        keep &= boxes["v1"] > top + edge_px
    if bottom is not None:
        keep &= boxes["v2"] < bottom - edge_px
    return boxes[keep]


#: A near-band box is kept where its foot reaches within this fraction of its height above the upper band's
#: bottom (less ``EDGE_PX``): the boundary's overlap, where both parts may keep a cone and the merge pairs them.
SPLIT_OVERLAP = 0.25


class SplitDetector:
    """The band's detector for a split band (``band_split``): takes the band as the adapter cuts it (the
    calibration's ``crop``, at its downscale) and runs its upper rows as they are and its near rows at the coarser
    scale (``cv2.INTER_AREA`` from the band: the same as from full resolution), each with a detector built for its
    size. Each cone is the upper band's whose foot stands above the upper band's bottom (less ``EDGE_PX``), else
    the near band's: an upper box touching that bottom is a cut cone, a near box with its foot above it (by more
    than ``SPLIT_OVERLAP`` of its height) a cone the upper band sees whole at twice the scale, and both are dropped
    (as is a near box touching the near band's top); of a cone both still keep (of any class) the upper band's box
    is kept while scored at least half the near box's (:func:`merge_boxes`). The rest of the pipeline sees one
    detector: ``timing`` sums the two, other attributes are the upper detector's (thresholds set on it reach both)."""

    def __init__(self, upper_detector, near_detector, split: BandSplit):
        self.upper_detector, self.near_detector, self.split = upper_detector, near_detector, split
        self.timing: dict[str, float] = {}

    def __getattr__(self, name):
        if name in ("upper_detector", "near_detector", "split"):
            raise AttributeError(name)
        return getattr(self.upper_detector, name)

    def __setattr__(self, name, value):
        if name in self._BOTH:  # a threshold changed at run time (the node's conf, iou, max_det): both parts'
            setattr(self.upper_detector, name, value)
            setattr(self.near_detector, name, value)
        else:
            object.__setattr__(self, name, value)

    _BOTH = ("conf", "iou", "max_det")

    @classmethod
    def load(cls, model, split: BandSplit, **detector_kw) -> "SplitDetector":
        """Both parts' detectors of ``model`` (``Detector.load_for_band`` for each size), warm."""
        dets = []
        for crop in (split.upper, split.near):
            d = Detector.load_for_band(model, (crop.out_width, crop.out_height), **detector_kw)
            d.warmup()
            dets.append(d)
        return cls(dets[0], dets[1], split)

    def warmup(self) -> None:
        pass  # loaded warm

    def input_size_for(self, w: int, h: int) -> tuple[int, int]:
        """The upper band's network input (the near band's: ``split.what``)."""
        up = self.split.upper
        return self.upper_detector.input_size_for(up.out_width, up.out_height)

    def detect(self, band_bgr: np.ndarray, crop: CropSpec) -> np.ndarray:
        """The band ``band_bgr`` cut at ``crop`` (the calibration's) -> boxes (full-image px)."""
        up, near = self.split.upper, self.split.near
        r = (up.v1 - crop.v0) // crop.downscale
        a = self.upper_detector.detect(np.ascontiguousarray(band_bgr[:r]), up)
        n0 = (near.v0 - crop.v0) // crop.downscale
        small = cv2.resize(band_bgr[n0:], (near.out_width, near.out_height), interpolation=cv2.INTER_AREA)
        b = self.near_detector.detect(small, near)
        ta, tb = dict(self.upper_detector.timing), dict(self.near_detector.timing)
        self.timing = {k: ta.get(k, 0.0) + tb.get(k, 0.0) for k in set(ta) | set(tb)}
        a = drop_edge_boxes(a, bottom=up.v1)
        # the near band keeps only the cones whose feet stand where the upper band cuts them: a cone with its foot
        # higher is whole in the upper band, at twice the scale (the near band's box of it, a few px tall, is
        # rough: kept, it paired badly and doubled the false cones on a rendered drive)
        # (less SPLIT_OVERLAP of its own height: the two networks place a foot a few px apart, and a cone at the
        # boundary dropped by both was lost; one both keep pairs in the merge)
        b = drop_edge_boxes(b[b["v2"] >= up.v1 - EDGE_PX - SPLIT_OVERLAP * (b["v2"] - b["v1"])], top=near.v0)
        # of any class: the two parts see one cone, and where the coarser one names its class otherwise (an orange
        # for a large orange) both boxes were kept, a false cone beside the true one
        return merge_boxes(b, a, getattr(self.upper_detector, "iou", DEFAULT_IOU), same_class=False)


__all__ = ["BAND_SPLIT_AUTO", "BAND_SPLIT_OFF", "BandSplit", "SplitDetector", "band_split_for", "drop_edge_boxes",
           "BAND_ROWS_AUTO", "BAND_ROWS_CROP", "BandRows", "EDGE_PX", "FAR_ROWS_AUTO", "FAR_ROWS_OFF", "FarBand",
           "FarRows", "band_rows_for", "check_far_classes", "drawn_by_far", "far_rows_for",
           "seen_by_far", "same_cone", "drop_cut_boxes", "far_band_crop", "merge_boxes"]
