"""Mapping stage: detected boxes (full-image px) -> cones in ``rear_axle`` metres.

One call per frame: :meth:`ConeMapper.map_boxes` takes a frame's boxes as
:class:`~cone_perception.records.BoxColumns` (made once from the :data:`BOX_DTYPE`
records; records are taken too, and made columns at the entry), validates them, picks each class's foot point, maps it through the
calibration's ``H_F_B``, moves it by the class's foot offset away from the
camera along the viewing ray (from the base edge the camera sees to the cone's
centre) and returns :data:`CONE_DTYPE` records with covariance.

Foot offset from the box width (calibration ``foot_offset_from_width: true``): a cone stands on a
square base plate (side ``s``, :data:`~cone_perception.classes.CONE_SIZE_M`) at any yaw; the
plate's edge nearest the camera lies ``h = s/2 (|cos a| + |sin a|)`` before its centre (``a``: the
plate's yaw against the viewing ray), between ``s/2`` and ``s/sqrt(2)``, and the plate is ``2 h``
wide across the ray. So each box's width, measured on the ground at its foot row, gives that cone's
offset (half of it, clipped to ``s/2 .. s/sqrt(2)``) instead of the class's fixed
``foot_offset_m`` (kept for classes of unknown size and boxes whose edges do not map).

Before the mapping, the pipeline and the ``mapping`` node keep one box per cone (:func:`one_box_per_cone`): a
second box of a cone another, better-scored box already has (another class on the same spot, or a much weaker
small box of its class) would be a second, false cone (issue 26g); so would a box of a part of a cone inside that
cone's taller box, its top at that box's top (issue 41).

A box on the ground must also stand up like a cone (``min_height_ratio``, :meth:`ConeMapper.height_ratios`): its
height against the height a cone of its class has, standing where the box's foot maps (the cone model of the
image attitude fit, :meth:`~cone_perception.attitude.ImageAttitude.model_heights`). A mark painted on the ground
is flat: its box's top lies on the ground too, so the box is lower than a cone standing at the range its foot row
says (a worn yellow line taken for yellow cones, issue 26; the measured ratios are in docs/benchmarks.md, "Flat
boxes"). Only weak boxes (scoring under :data:`FLAT_MAX_SCORE`) are judged, so that a true cone whose box the
detector drew low is kept where the detector is sure of it.
After the mapping, two cones of one class (of two classes from 15 m on) nearly on one viewing ray and less than 2 m
apart along it, the better-scored nearer than ``one_ray_range_m``, are one cone seen twice (:func:`one_cone_per_ray`): two boxes of one far cone a few
pixels apart in foot row map a metre or two apart along the ray, on one bearing, where the image cannot tell them
from two cones of a row (issue 26, session 15). The better-scored stays, its covariance stretched to cover the other.
Every box dropped is counted by cause in :attr:`ConeMapper.dropped`.

Pixel conventions: boxes are in pixel-EDGE coordinates (a box around pixel
columns 10..19 has u1 = 10, u2 = 20, as detectors and YOLO labels use them);
the calibration, like OpenCV, uses pixel-CENTRE coordinates (pixel 10 spans
9.5..10.5). A foot point therefore moves by -0.5 px before it is mapped.
"""

from __future__ import annotations

import numpy as np

from .attitude import Attitude, AttitudeModel, ImageAttitude
from .classes import CONE_SIZE_M, NUM_CLASSES
from .errors import FrameError
from .geometry import GroundMapper, apply_homography, foot_point_weights, foot_points
from .geometry.calib import Calibration
from .records import CONE_DTYPE, BoxColumns, xyxy_area, xyxy_intersection, xyxy_iou

#: causes of :attr:`ConeMapper.dropped`: a second box of a cone (:func:`one_box_per_cone`, counted by its
#: callers); the foot above the horizon or beyond ``max_range_m``; a box lower
#: than ``min_height_ratio`` x a cone's height at the range its foot gives (a mark on the ground); a second cone
#: on one viewing ray (:func:`one_cone_per_ray`, ``one_ray_range_m``)
DROP_CAUSES = ("second_box", "off_ground", "flat", "one_ray")
#: The height gate acts only on boxes scoring under this: painted marks give weak boxes, and on the real validation
#: clips far fewer true cones' boxes are low among the weak ones (docs/benchmarks.md, "Flat boxes").
FLAT_MAX_SCORE = 0.5


#: a frame's boxes: their :class:`~cone_perception.records.BoxColumns`, or :data:`BOX_DTYPE` records (made columns
#: at the entry of the step that takes them)
Boxes = BoxColumns | np.ndarray


def validate_boxes(boxes: Boxes) -> None:
    """Raise :class:`FrameError` for NaN/inf, ``u2 < u1``, ``v2 < v1`` or an unknown class id."""
    cols = BoxColumns.of(boxes)
    b, s, c = cols.xyxy, cols.score, cols.class_id
    if not (np.all(np.isfinite(b)) and np.all(np.isfinite(s))):
        i = int(np.flatnonzero(~(np.isfinite(b).all(axis=1) & np.isfinite(s)))[0])
        raise FrameError("bad_box", f"box {i} has a non-finite value: {b[i].tolist()} score {s[i]}")
    bad = np.flatnonzero((b[:, 2] < b[:, 0]) | (b[:, 3] < b[:, 1]))
    if bad.size:
        i = int(bad[0])
        raise FrameError("bad_box", f"box {i} has u2 < u1 or v2 < v1: {b[i].tolist()}")
    bad = np.flatnonzero(c >= NUM_CLASSES)
    if bad.size:
        raise FrameError("bad_class", f"box {int(bad[0])} has unknown class id {int(c[bad[0]])} (0..{NUM_CLASSES - 1})")


#: Boxes of different classes overlapping at least this much (IoU) are taken for one cone seen as two classes:
#: the lower-scored goes (:func:`one_box_per_cone`). On the tuning drives (docs/benchmarks.md, "False cones
#: within 40 m (issue 26g)") such pairs were two boxes of one cone 200 times and of two cones 4 times at IoU >= 0.6.
CROSS_CLASS_IOU = 0.6
#: Small boxes (both under SMALL_BOX_PX tall, full-image px) of one class overlapping at IoU >= SMALL_SAME_IOU, the
#: weaker scored under SMALL_WEAKER x the stronger: a second box of one far cone (the NMS's IoU 0.45 misses such
#: pairs: a shift of 2-4 px is a third of a 10 px box), so the weaker goes. Far cones of a row overlap as much,
#: which is why the score must say so too (docs/benchmarks.md).
SMALL_BOX_PX = 16.0
SMALL_SAME_IOU = 0.3
SMALL_WEAKER = 0.6
#: A part of a cone (:func:`part_of`): the upper half of a large orange cone another cone overlaps got a box of its
#: own (issue 41). On flat ground a farther cone's top stands above a nearer one's, so no other cone's box lies inside
#: a cone's box with its top at that box's top. Chosen on the tuning drives (docs/validation.md, "Parts of a cone"):
#: under PART_MIN_PX the two are two boxes of one far cone, the shorter as often the better; a taller box scored
#: under PART_WEAKER x the part's is the one drawn too tall.
PART_INSIDE = 0.8
PART_MAX_HEIGHT = 0.8
PART_TOP_FRAC = 0.15
PART_MIN_PX = 32.0
PART_WEAKER = 0.6


def box_iou(a: Boxes, b: Boxes) -> np.ndarray:
    """(N, M) IoU of the boxes ``a`` and ``b`` (:data:`BOX_DTYPE` records or their columns; pixel edges)."""
    return xyxy_iou(BoxColumns.of(a).xyxy, BoxColumns.of(b).xyxy)


def one_box_per_cone(boxes: Boxes, iou: float = CROSS_CLASS_IOU, small_px: float = SMALL_BOX_PX,
                     small_iou: float = SMALL_SAME_IOU, small_weaker: float = SMALL_WEAKER, *,
                     part_inside: float = PART_INSIDE, part_max_height: float = PART_MAX_HEIGHT,
                     part_top_frac: float = PART_TOP_FRAC, part_min_px: float = PART_MIN_PX,
                     part_weaker: float = PART_WEAKER) -> Boxes:
    """``boxes`` minus those that are a second box of a cone a better-scored box already has (greedy, best score
    first; order kept), of the kind given (:class:`~cone_perception.records.BoxColumns` or :data:`BOX_DTYPE`
    records):

    * a box of ANOTHER class overlapping it at IoU >= ``iou``: the detector's NMS is per class, so a far cone it
      is unsure of can come out as a blue and a yellow box on one spot (two cones on ``/cones``, one false);
    * a box of the same class, both under ``small_px`` tall, overlapping it at IoU >= ``small_iou`` and scored
      under ``small_weaker`` x its score (``small_weaker`` 0: off);
    * whatever the classes, a part of a taller box's cone (:func:`part_of` with the ``part_*`` settings), that box
      scored at least ``part_weaker`` x its score (``part_inside`` above 1: off).

    Everything else is left to the detector's NMS."""
    n = len(boxes)
    if n < 2:
        return boxes
    cols = BoxColumns.of(boxes)
    score = np.asarray(cols.score, np.float64)
    cls = cols.class_id
    same = cls[:, None] == cls[None, :]
    xyxy = np.asarray(cols.xyxy, np.float64)
    inter = xyxy_intersection(xyxy, xyxy)  # the overlaps, for the IoU and the parts
    ov = xyxy_iou(xyxy, xyxy, inter)
    over = (ov >= iou) & ~same
    if small_weaker > 0:
        h = xyxy[:, 3] - xyxy[:, 1]
        small = (h[:, None] < small_px) & (h[None, :] < small_px)
        weaker = np.minimum(score[:, None], score[None, :]) < small_weaker * np.maximum(score[:, None], score[None, :])
        over |= (ov >= small_iou) & same & small & weaker
    np.fill_diagonal(over, False)
    part = part_of(xyxy, part_inside, part_max_height, part_top_frac, part_min_px, inter)
    part &= score[:, None] >= part_weaker * score[None, :]
    if not over.any() and not part.any():
        return boxes
    keep = ~part.any(axis=0)  # a part goes: its cone keeps its whole box
    for i in np.argsort(-score, kind="stable"):
        if keep[i]:  # a kept box removes the lower-scored (ties: the later) boxes it pairs with
            keep[over[i] & (score <= score[i])] = False
    return cols.take(keep) if isinstance(boxes, BoxColumns) else boxes[keep]


def part_of(xyxy: np.ndarray, inside: float = PART_INSIDE, max_height: float = PART_MAX_HEIGHT,
            top_frac: float = PART_TOP_FRAC, min_px: float = PART_MIN_PX, inter: np.ndarray | None = None) -> np.ndarray:
    """(N, N) bool: box j lies where a part of box i's cone would (:func:`one_box_per_cone`; scores aside): at least
    ``inside`` of j's area inside i (at least ``min_px`` tall), at most ``max_height`` x as tall, its top within
    ``top_frac`` x i's height of i's top; ``inter``: their :func:`xyxy_intersection` if at hand."""
    _, v1, _, v2 = np.asarray(xyxy, np.float64).reshape(-1, 4).T
    h, area = v2 - v1, xyxy_area(xyxy)[None, :]
    inter = xyxy_intersection(xyxy, xyxy) if inter is None else inter
    share = np.divide(inter, area, out=np.zeros((len(h), len(h))), where=area > 0)
    part = ((share >= inside) & (h[:, None] >= min_px) & (h[None, :] <= max_height * h[:, None])
            & (np.abs(v1[None, :] - v1[:, None]) <= top_frac * h[:, None]))
    np.fill_diagonal(part, False)
    return part


#: :func:`one_cone_per_ray`'s ways to make one cone of a pair: ``drop`` (the better-scored cone as it was),
#: ``keep`` (its position, its covariance stretched along the pair to cover the other's), ``merge`` (the
#: score-weighted mean of their positions and the moment-matched covariance)
RAY_MERGE_MODES = ("drop", "keep", "merge")
#: :class:`ConeMapper`'s :func:`one_cone_per_ray`: two cones of one class (of two classes from
#: ONE_RAY_CROSS_CLASS_FROM_M on) less than ONE_RAY_ACROSS_M off one viewing ray and less than ONE_RAY_ALONG_M apart
#: along it are one cone, the better-scored kept where it is (``keep``). Screened on ten tuning drives
#: (docs/benchmarks.md, "Duplicates on one ray"): two boxes of one cone a few pixels apart lie 0.1 m (median) across
#: the ray, two cones of a row 0.2 m; pairs of two classes nearer than 10 m were real cones (7-15 m recall).
ONE_RAY_ACROSS_M = 0.15
ONE_RAY_ALONG_M = 2.0
ONE_RAY_CROSS_CLASS_FROM_M = 15.0


def one_cone_per_ray(cones: np.ndarray, camera_xy, across_m: float, along_m: float, along_frac: float = 0.0,
                     mode: str = "keep", max_range_m: float = np.inf, cross_class_from_m: float = np.inf,
                     min_range_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(:data:`CONE_DTYPE` records, mask of the input records kept) after making one cone of each pair of cones
    of one class (or of two classes where the better-scored one is at least ``cross_class_from_m`` from the camera;
    its class stays) standing nearly on one viewing ray: the other cone less than ``across_m`` (m) off the ray from
    the camera's ground point ``camera_xy`` through the better-scored one, and less than ``max(along_m,
    along_frac x its range)`` (m) before or behind it along that ray, the better-scored one at least
    ``min_range_m`` and less than ``max_range_m`` (m) from the camera. Two boxes of one far cone a few pixels
    apart map about 1.5 m apart along the ray (a pixel of foot row is metres there), on the same bearing; two
    cones of a row stand 2-5 m apart and off one ray unless the row points at the camera, and cones of the two rows
    at least a track width (3 m) apart (docs/benchmarks.md, "Duplicates on one ray").

    Greedy, best score first: a kept cone takes every lower-scored cone (ties: the later) that pairs with it;
    ``mode`` (:data:`RAY_MERGE_MODES`) says what the kept cone becomes. The output keeps the input order."""
    if mode not in RAY_MERGE_MODES:
        raise ValueError(f"mode must be one of {RAY_MERGE_MODES}, got {mode!r}")
    n = len(cones)
    keep = np.ones(n, dtype=bool)
    if n < 2 or across_m <= 0:
        return cones, keep
    xy = np.c_[cones["x"], cones["y"]].astype(np.float64)
    ray = xy - np.asarray(camera_xy, np.float64)
    rng = np.linalg.norm(ray, axis=1)
    u = ray / np.maximum(rng, 1e-9)[:, None]
    d = xy[None, :, :] - xy[:, None, :]  # d[i, j] = xy[j] - xy[i]
    along = np.einsum("ijk,ik->ij", d, u)  # along cone i's ray
    across = np.abs(d[..., 0] * u[:, 1:2] - d[..., 1] * u[:, 0:1])
    score = np.asarray(cones["score"], np.float64)
    near_enough = (rng >= min_range_m) & (rng < max_range_m)
    pair = (((cones["class_id"][:, None] == cones["class_id"][None, :]) | (rng >= cross_class_from_m)[:, None])
            & (across < across_m) & (np.abs(along) < np.maximum(along_m, along_frac * rng)[:, None])
            & near_enough[:, None])
    np.fill_diagonal(pair, False)
    if not pair.any():
        return cones, keep
    out = cones.copy()
    for i in np.argsort(-score, kind="stable"):
        if not keep[i]:
            continue
        takes = np.flatnonzero(pair[i] & keep & (score <= score[i]))
        if takes.size == 0:
            continue
        keep[takes] = False
        if mode == "drop":
            continue
        grp = np.r_[i, takes]
        cov = np.stack([np.stack([cones["cov_xx"][grp], cones["cov_xy"][grp]], -1),
                        np.stack([cones["cov_xy"][grp], cones["cov_yy"][grp]], -1)], -2).astype(np.float64)
        if mode == "keep":  # where it was; every other position within one sigma along the pair
            dd = xy[takes] - xy[i]
            c = cov[0] + np.einsum("ni,nj->ij", dd, dd)
            p = xy[i]
        else:  # the score-weighted mixture's mean and covariance
            w = np.maximum(score[grp], 1e-6)
            w = w / w.sum()
            p = w @ xy[grp]
            dd = xy[grp] - p
            c = np.einsum("n,nij->ij", w, cov + dd[:, :, None] * dd[:, None, :])
        out["x"][i], out["y"][i] = p
        out["cov_xx"][i], out["cov_xy"][i], out["cov_yy"][i] = c[0, 0], c[0, 1], c[1, 1]
    return out[keep], keep


class ConeMapper:
    """Boxes -> cones for one calibrated camera."""

    def __init__(self, calib: Calibration, min_height_ratio: float = 0.0, one_ray_range_m: float = 0.0):
        """``min_height_ratio``: boxes lower than this x the height a cone of their class has where their foot maps,
        scoring under :data:`FLAT_MAX_SCORE`, are dropped as marks on the ground (0: off; needs a mount pose in the
        calibration, else it cannot act). ``one_ray_range_m``: two cones nearly on one viewing ray
        (:func:`one_cone_per_ray` at :data:`ONE_RAY_ACROSS_M`, :data:`ONE_RAY_ALONG_M`; of one class, of two from
        :data:`ONE_RAY_CROSS_CLASS_FROM_M` on), the better-scored nearer
        than this (m from the camera), are one cone: the other is dropped (0: off)."""
        if not (np.isfinite(min_height_ratio) and 0.0 <= min_height_ratio < 1.0):
            raise ValueError(f"min_height_ratio must be in [0, 1), got {min_height_ratio}")
        if not (np.isfinite(one_ray_range_m) and one_ray_range_m >= 0.0):
            raise ValueError(f"one_ray_range_m must be a number of metres >= 0, got {one_ray_range_m}")
        self.calib = calib
        self.min_height_ratio = float(min_height_ratio)
        self.one_ray_range_m = float(one_ray_range_m)
        self._ray_origin = calib.camera_ground_xy()  # where the viewing rays start on the ground
        #: boxes dropped by :meth:`map_boxes` so far, by cause (:data:`DROP_CAUSES`); the replay summary and the
        #: nodes' /diagnostics report them
        self.dropped = dict.fromkeys(DROP_CAUSES, 0)
        self._sizes = None  # the image fit's cone model, for model_heights (built on first use)
        self.ground = GroundMapper(
            calib.H_F_B,
            calib.max_range_m,
            (calib.pixel_sigma_u, calib.pixel_sigma_v),
            calib.camera_matrix,
            calib.dist_coeffs,
        )
        self._u_weights = foot_point_weights(calib.foot_points)
        self._offset_m = np.asarray(calib.foot_offset_m, dtype=np.float64)
        self._from_width = bool(getattr(calib, "foot_offset_from_width", False))
        self._camera_xy = calib.camera_ground_xy() if (np.any(self._offset_m) or self._from_width) else np.zeros(2)
        #: half the base plate side per class id (NaN: size unknown)
        self._plate_half_m = np.array([CONE_SIZE_M[c][1] / 2 if c in CONE_SIZE_M else np.nan for c in range(NUM_CLASSES)])
        #: H_F_B for a body attitude offset; None without a mount pose in the calibration (fixed H only)
        self.attitude_model = None
        if calib.mount_pose is not None and calib.camera_matrix is not None:
            self.attitude_model = AttitudeModel(calib.H_F_B, calib.camera_matrix, calib.mount_pose,
                                                calib.ground_reference_px())

    def image_attitude(self, config=None):
        """A new :class:`~cone_perception.attitude.ImageAttitude` for this calibration (needs a mount pose)."""
        c = self.calib
        if self.attitude_model is None:
            raise ValueError(f"{c.source}: attitude from the image needs mount_pose and camera_matrix in the calibration")
        return ImageAttitude(c.camera_matrix, c.mount_pose, self._offset_m, (c.image_width, c.image_height),
                             (float(c.crop.v0), float(c.crop.v1)), c.dist_coeffs, config)

    def _ground_for(self, attitude: Attitude | None) -> GroundMapper:
        if attitude is None or attitude.is_zero:
            return self.ground
        if self.attitude_model is None:
            raise ValueError(f"{self.calib.source}: an attitude offset needs mount_pose and camera_matrix in the calibration")
        g = self.ground
        return GroundMapper(self.attitude_model.H_F_B(attitude.pitch_deg, attitude.roll_deg), g.max_range_m,
                            tuple(g.sigma), g.K, g.dist)

    def foot_points(self, boxes: Boxes) -> np.ndarray:
        """(N, 2) foot pixels (pixel-centre coordinates) of the boxes, by each box's class rule."""
        cols = BoxColumns.of(boxes)
        return foot_points(cols.xyxy, cols.class_id, self._u_weights) - 0.5

    def foot_offsets(self, xy_m: np.ndarray, class_ids: np.ndarray, offsets_m: np.ndarray | None = None) -> np.ndarray:
        """(N, 2) mapped foot points -> cone centres: moved by the class's foot offset (or ``offsets_m``,
        (N,) m) along the ground ray from the camera."""
        off = self._offset_m[np.asarray(class_ids, dtype=np.intp)] if offsets_m is None else np.asarray(offsets_m)
        if not np.any(off):
            return xy_m
        d = xy_m - self._camera_xy
        n = np.linalg.norm(d, axis=1, keepdims=True)
        return xy_m + d / np.maximum(n, 1e-9) * off[:, None]

    def width_offsets(self, boxes: Boxes, foot_uv: np.ndarray, ground: GroundMapper | None = None) -> np.ndarray:
        """(N,) m foot offsets from the boxes' widths (module doc): half the ground distance between the
        box's left and right edges at its foot row, clipped to the class's plate ``s/2 .. s/sqrt(2)``;
        the class's fixed offset where the size is unknown or an edge does not map.
        ``foot_uv``: (N, 2) foot pixels (pixel-centre coordinates, :meth:`foot_points`)."""
        ground = ground or self.ground
        cols = BoxColumns.of(boxes)
        b = cols.xyxy
        cls = np.asarray(cols.class_id, dtype=np.intp)
        left, _ = ground.map_pixels(np.c_[b[:, 0] - 0.5, foot_uv[:, 1]])
        right, _ = ground.map_pixels(np.c_[b[:, 2] - 0.5, foot_uv[:, 1]])
        half = 0.5 * np.hypot(right[:, 0] - left[:, 0], right[:, 1] - left[:, 1])
        lo = self._plate_half_m[cls]
        with np.errstate(invalid="ignore"):
            off = np.clip(half, lo, lo * np.sqrt(2.0))
        return np.where(np.isfinite(off), off, self._offset_m[cls])

    def height_ratios(self, boxes: Boxes, xy_m: np.ndarray) -> np.ndarray:
        """(N,) each box's height (undistorted px, at its centre column) over the height a cone of its class has
        with its centre at ``xy_m`` (N, 2) (the box mapped, :meth:`map_boxes`): the cone model of the image
        attitude fit at zero attitude (an attitude error of a tenth of a degree changes it by under 1 % at 40 m).
        NaN where it is not known: no mount pose in the calibration, a class of unknown size, behind the camera."""
        n = len(boxes)
        if self.attitude_model is None or n == 0:
            return np.full(n, np.nan)
        if self._sizes is None:
            self._sizes = self.image_attitude()
        cols = BoxColumns.of(boxes)
        b, c = cols.xyxy, cols.class_id
        uc = 0.5 * (b[:, 0] + b[:, 2]) - 0.5
        und = self.ground.undistort(np.r_[np.c_[uc, b[:, 1] - 0.5], np.c_[uc, b[:, 3] - 0.5]])
        h = und[n:, 1] - und[:n, 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            return h / self._sizes.model_heights(np.asarray(xy_m, dtype=np.float64).reshape(-1, 2), np.asarray(c, np.intp))

    def box_foot_of(self, xy_m: np.ndarray, class_ids: np.ndarray) -> np.ndarray:
        """Inverse of the box -> cone mapping: (N, 2) cone centres (m) -> (N, 2) box foot points
        in pixel-EDGE coordinates (where this calibration expects each class's foot point; with the
        class's fixed foot offset, also under ``foot_offset_from_width``)."""
        xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        off = self._offset_m[np.asarray(class_ids, dtype=np.intp)]
        if np.any(off):
            d = xy - self._camera_xy
            xy = xy - d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9) * off[:, None]
        return self.ground_to_pixels(xy) + 0.5

    def box_u_range(self, u_foot: np.ndarray, width_px: np.ndarray, class_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u1, u2) of boxes ``width_px`` wide whose class rule puts the foot point at ``u_foot``."""
        a = self._u_weights[np.asarray(class_ids, dtype=np.intp)]
        u1 = np.asarray(u_foot, dtype=np.float64) - a * np.asarray(width_px, dtype=np.float64)
        return u1, u1 + width_px

    def ground_to_pixels(self, xy_m: np.ndarray) -> np.ndarray:
        """(N, 2) ground points (m) -> (N, 2) full-image px where the camera sees them."""
        return self.ground.ground_to_pixels(xy_m)

    def map_boxes(self, boxes: Boxes, attitude: Attitude | None = None) -> np.ndarray:
        """A frame's boxes (:class:`~cone_perception.records.BoxColumns`, or :data:`BOX_DTYPE` records made columns
        here), validated -> :data:`CONE_DTYPE` records.

        Boxes whose foot point is above the horizon or beyond ``max_range_m``
        are dropped (they are never published), and with ``min_height_ratio`` boxes too low for a cone
        standing there (:meth:`height_ratios`) scoring under :data:`FLAT_MAX_SCORE`, and with ``one_ray_range_m``
        a second cone on one viewing ray (:meth:`one_per_ray`); each counted in :attr:`dropped`. Raises
        :class:`FrameError` for a malformed box (the whole message is dropped by the caller).
        ``attitude``: the body's attitude offset for this frame (needs a mount pose); its
        uncertainty is added to each cone's covariance.
        """
        out, _ = self._map(BoxColumns.of(boxes), attitude, self.dropped)
        return self.one_per_ray(out)[0]

    def box_ranges(self, boxes: Boxes, attitude: Attitude | None = None) -> np.ndarray:
        """(N,) float64: the distance (m) from the ``rear_axle`` origin of the cone each box maps to by itself (as
        :meth:`map_boxes` maps it, before :meth:`one_per_ray`), NaN where it maps to none (above the horizon,
        beyond the range, flat). Nothing is counted in :attr:`dropped`: the debug image's distances, drawn beside
        the frame's own mapping. Raises :class:`FrameError` as :meth:`map_boxes` does."""
        out, valid = self._map(BoxColumns.of(boxes), attitude, dict.fromkeys(DROP_CAUSES, 0))
        ranges = np.full(len(boxes), np.nan)
        ranges[valid] = np.hypot(out["x"].astype(np.float64), out["y"].astype(np.float64))
        return ranges

    def _map(self, cols: BoxColumns, attitude: Attitude | None, dropped: dict) -> tuple[np.ndarray, np.ndarray]:
        """(the cones of the boxes kept, in order; (N,) bool: which boxes they are), the drops counted in
        ``dropped``."""
        validate_boxes(cols)
        if len(cols) == 0:
            return np.zeros(0, dtype=CONE_DTYPE), np.zeros(0, dtype=bool)
        ground = self._ground_for(attitude)
        uv = self.foot_points(cols)
        xy, valid = ground.map_pixels(uv)
        dropped["off_ground"] += int((~valid).sum())
        off = self.width_offsets(cols, uv, ground)[valid] if self._from_width else None
        xy[valid] = self.foot_offsets(xy[valid], cols.class_id[valid], off)
        if self.min_height_ratio > 0 and valid.any():
            idx = np.flatnonzero(valid)
            weak = np.asarray(cols.score[idx], np.float64) < FLAT_MAX_SCORE
            with np.errstate(invalid="ignore"):
                flat = (self.height_ratios(cols.take(idx), xy[idx]) < self.min_height_ratio) & weak  # NaN: not known, kept
            valid[idx[flat]] = False
            dropped["flat"] += int(flat.sum())
        cov = ground.covariance(uv[valid])
        if (self.attitude_model is not None and attitude is not None and valid.any()
                and (attitude.sigma_pitch_deg > 0 or attitude.sigma_roll_deg > 0)):
            cov = cov + self._attitude_covariance(uv[valid], attitude)
        out = np.zeros(int(valid.sum()), dtype=CONE_DTYPE)
        out["x"] = xy[valid, 0]
        out["y"] = xy[valid, 1]
        out["class_id"] = cols.class_id[valid]
        out["score"] = cols.score[valid]
        out["cov_xx"] = cov[:, 0, 0]
        out["cov_xy"] = cov[:, 0, 1]
        out["cov_yy"] = cov[:, 1, 1]
        return out, valid

    def one_per_ray(self, cones: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(cones, mask of those kept): :func:`one_cone_per_ray` at this mapper's ``one_ray_range_m`` (what
        :meth:`map_boxes` does last), each cone it drops counted (``one_ray``)."""
        if self.one_ray_range_m <= 0 or len(cones) < 2:
            return cones, np.ones(len(cones), dtype=bool)
        out, keep = one_cone_per_ray(cones, self._ray_origin, ONE_RAY_ACROSS_M, ONE_RAY_ALONG_M, mode="keep",
                                     max_range_m=self.one_ray_range_m, cross_class_from_m=ONE_RAY_CROSS_CLASS_FROM_M)
        self.dropped["one_ray"] += int((~keep).sum())
        return out, keep

    def _attitude_covariance(self, uv: np.ndarray, att: Attitude) -> np.ndarray:
        """(N, 2, 2) m^2: J diag(sigma_pitch^2, sigma_roll^2) J^T, J = d(x, y)/d(pitch, roll) (central
        differences of 0.1 degree about the attitude used)."""
        J = self._attitude_jacobian_px(uv, att)
        return J @ att.covariance_deg2() @ np.transpose(J, (0, 2, 1))

    def attitude_jacobian(self, xy_m: np.ndarray) -> np.ndarray | None:
        """(N, 2) rear_axle ground points (m) -> (N, 2, 2) m/deg: how each point's mapped position moves
        with the body's (pitch, roll) offset about zero (column 0 pitch, 1 roll); None without a mount pose.
        An attitude error common to a frame moves all its cones by ``J @ delta`` (the tracker takes it out)."""
        if self.attitude_model is None:
            return None
        xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        if len(xy) == 0:
            return np.zeros((0, 2, 2))
        und, w = apply_homography(np.linalg.inv(self.ground.H), xy)  # undistorted px of the calibrated H
        und[w <= 0] = np.nan
        return self._attitude_jacobian_px(und, Attitude(), undistorted=True)

    def _attitude_jacobian_px(self, uv: np.ndarray, att: Attitude, undistorted: bool = False) -> np.ndarray:
        """(N, 2) full-image px (``undistorted``: already without the lens) -> (N, 2, 2) m/deg, central
        differences of 0.1 degree about ``att``."""
        eps = 0.1
        J = np.empty((uv.shape[0], 2, 2))
        und = uv if undistorted else self.ground.undistort(uv)  # once: the lens does not depend on the attitude
        H = self.attitude_model.H_F_B
        for k, d in enumerate(((eps, 0.0), (0.0, eps))):
            xa = apply_homography(H(att.pitch_deg + d[0], att.roll_deg + d[1]), und)[0]
            xb = apply_homography(H(att.pitch_deg - d[0], att.roll_deg - d[1]), und)[0]
            with np.errstate(invalid="ignore", divide="ignore"):
                J[:, :, k] = np.nan_to_num((xa - xb) / (2 * eps))
        return J


def expected_truth(truth: np.ndarray, calib, mapper=None) -> np.ndarray:
    """True cones a detector is expected to find: at least half visible (``score`` of ``/cones_gt``
    holds the visible fraction) and standing inside the camera's band and range.
    ``mapper``: the calibration's :class:`~cone_perception.mapping.ConeMapper`, if already built."""
    keep = truth["score"] >= 0.5
    uv = (mapper or ConeMapper(calib)).ground_to_pixels(np.c_[truth["x"], truth["y"]])
    c = calib.crop
    inside = (uv[:, 0] >= c.u0) & (uv[:, 0] < c.u1) & (uv[:, 1] >= c.v0) & (uv[:, 1] < c.v1)
    return truth[keep & inside & (np.hypot(truth["x"], truth["y"]) <= calib.max_range_m)]
