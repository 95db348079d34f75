"""Typed record arrays for the PointCloud2 topics, converted both ways here only.

``cone_boxes`` and ``/cones`` travel as ``sensor_msgs/PointCloud2`` with height 1
and one point per box / cone. In Python they are numpy structured arrays:

* :data:`BOX_DTYPE`: ``u1 v1 u2 v2`` float32 (full-image px), ``score`` float32,
  ``class_id`` uint8 (24 bytes a point, 4-byte aligned).
* :data:`CONE_DTYPE`: ``x y z`` float32 (m, ``rear_axle``, z = 0), ``class_id``
  uint8, ``score`` float32, ``cov_xx cov_xy cov_yy`` float32 (m^2) (32 bytes).
* :data:`TRACKED_CONE_DTYPE` (``/cones/tracked``): the ``CONE_DTYPE`` fields plus ``track_id``
  uint32 (36 bytes); ``score`` is the track's certainty.

The converters are duck-typed over the message classes, so the same code builds
rclpy messages in the nodes and rosbags messages in the offline tools; this
module imports neither.

On the mapping path a frame's boxes are read as columns (:class:`BoxColumns`): made once from the
records, handed to every step (one box per cone, the attitude fit, the mapping), subsets taken from it. Their
``xyxy`` corners' areas, overlaps and IoU: :func:`xyxy_area`, :func:`xyxy_intersection`, :func:`xyxy_iou`.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import ConfigError, FrameError

BOX_DTYPE = np.dtype(
    {
        "names": ["u1", "v1", "u2", "v2", "score", "class_id"],
        "formats": ["<f4", "<f4", "<f4", "<f4", "<f4", "u1"],
        "offsets": [0, 4, 8, 12, 16, 20],
        "itemsize": 24,
    }
)

CONE_DTYPE = np.dtype(
    {
        "names": ["x", "y", "z", "class_id", "score", "cov_xx", "cov_xy", "cov_yy"],
        "formats": ["<f4", "<f4", "<f4", "u1", "<f4", "<f4", "<f4", "<f4"],
        "offsets": [0, 4, 8, 12, 16, 20, 24, 28],
        "itemsize": 32,
    }
)

TRACKED_CONE_DTYPE = np.dtype(
    {
        "names": list(CONE_DTYPE.names) + ["track_id"],
        "formats": [CONE_DTYPE.fields[n][0] for n in CONE_DTYPE.names] + ["<u4"],
        "offsets": [CONE_DTYPE.fields[n][1] for n in CONE_DTYPE.names] + [32],
        "itemsize": 36,
    }
)

# sensor_msgs/PointField datatype constants
_PF_CODE = {
    np.dtype("i1"): 1,
    np.dtype("u1"): 2,
    np.dtype("<i2"): 3,
    np.dtype("<u2"): 4,
    np.dtype("<i4"): 5,
    np.dtype("<u4"): 6,
    np.dtype("<f4"): 7,
    np.dtype("<f8"): 8,
}
_PF_DTYPE = {code: dt for dt, code in _PF_CODE.items()}


def empty(dtype: np.dtype, n: int = 0) -> np.ndarray:
    """A zero-filled record array of ``n`` points."""
    return np.zeros(n, dtype=dtype)


def boxes_from_arrays(boxes_px: np.ndarray, scores: np.ndarray, class_ids: np.ndarray) -> np.ndarray:
    """(N, 4) boxes, (N,) scores, (N,) class ids -> :data:`BOX_DTYPE` records."""
    b = np.asarray(boxes_px, dtype=np.float32).reshape(-1, 4)
    out = np.zeros(b.shape[0], dtype=BOX_DTYPE)
    out["u1"], out["v1"], out["u2"], out["v2"] = b.T
    out["score"] = np.asarray(scores, dtype=np.float32).reshape(-1)
    out["class_id"] = np.asarray(class_ids).reshape(-1).astype(np.uint8)
    return out


def boxes_to_arrays(records: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:data:`BOX_DTYPE` records -> ((N, 4) float32 boxes, (N,) scores, (N,) int class ids)."""
    b = np.stack([records["u1"], records["v1"], records["u2"], records["v2"]], axis=1).astype(np.float32)
    return b.reshape(-1, 4), records["score"].astype(np.float32), records["class_id"].astype(np.int64)


@dataclass(frozen=True, eq=False)
class BoxColumns:
    """One frame's :data:`BOX_DTYPE` boxes as columns, made once (:meth:`of`) and read by every step of the mapping
    stage. ``records`` (N,) BOX_DTYPE: the boxes themselves (what is published on ``cone_boxes``); ``xyxy`` (N, 4)
    float32 ``u1 v1 u2 v2`` (full-image px, pixel edges); ``score`` (N,) float32; ``class_id`` (N,) int64. The
    columns hold the records' values as they are (float32), so a step computes what it computed from the records."""

    records: np.ndarray
    xyxy: np.ndarray
    score: np.ndarray
    class_id: np.ndarray

    @classmethod
    def of(cls, boxes: "np.ndarray | BoxColumns") -> "BoxColumns":
        """The columns of ``boxes`` (BOX_DTYPE records, or records of another dtype with those fields, cast first);
        ``boxes`` itself where it already is a :class:`BoxColumns`."""
        if isinstance(boxes, BoxColumns):
            return boxes
        records = boxes if boxes.dtype == BOX_DTYPE else boxes.astype(BOX_DTYPE)
        xyxy, score, class_id = boxes_to_arrays(records)
        return cls(records, xyxy, score, class_id)

    def __len__(self) -> int:
        return len(self.records)

    def take(self, which: np.ndarray) -> "BoxColumns":
        """The boxes ``which`` selects ((N,) bool mask or indices), columns and records alike, in order."""
        return BoxColumns(self.records[which], self.xyxy[which], self.score[which], self.class_id[which])


def point_fields(dtype: np.dtype) -> list[tuple[str, int, int, int]]:
    """``(name, offset, datatype, count)`` of each field, in PointField terms."""
    out = []
    for name in dtype.names:
        fdt, off = dtype.fields[name][:2]
        out.append((name, int(off), _PF_CODE[fdt.newbyteorder("<") if fdt.byteorder == "=" else fdt], 1))
    return out


def _is_rosbags(cls: type) -> bool:
    return hasattr(cls, "__msgtype__")


def to_pointcloud2(records: np.ndarray, header: Any, cloud_cls: type, field_cls: type) -> Any:
    """Record array -> PointCloud2 of the given message classes (rclpy or rosbags).

    ``header`` is put in as it is (copy the image's header to keep its stamp).
    """
    records = np.ascontiguousarray(records)
    dtype = records.dtype
    rosbags = _is_rosbags(cloud_cls)
    fields = [
        field_cls(name=n, offset=o, datatype=d, count=c) for (n, o, d, c) in point_fields(dtype)
    ]
    raw = records.view(np.uint8).reshape(-1)
    n = int(records.shape[0])
    return cloud_cls(
        header=header,
        height=1,
        width=n,
        fields=fields,
        is_bigendian=False,
        point_step=dtype.itemsize,
        row_step=dtype.itemsize * n,
        data=raw.copy() if rosbags else raw.tobytes(),
        is_dense=True,
    )


def from_pointcloud2(msg: Any, dtype: np.dtype) -> np.ndarray:
    """PointCloud2 (rclpy or rosbags) -> record array of ``dtype``.

    Fields are found by name, so a cloud with other offsets or extra fields is
    read correctly. Raises :class:`FrameError` naming the missing or mistyped
    field, a big-endian cloud, or a ``data`` shorter than the points need.
    """
    if msg.is_bigendian:
        raise FrameError("bad_cloud", "big-endian PointCloud2 is not supported")
    n = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    by_name = {f.name: f for f in msg.fields}
    layout = {"names": [], "formats": [], "offsets": [], "itemsize": max(step, 1)}
    for name in dtype.names:
        f = by_name.get(name)
        if f is None:
            raise FrameError("bad_cloud", f"PointCloud2 has no field {name!r} (fields: {sorted(by_name)})")
        want = dtype.fields[name][0]
        got = _PF_DTYPE.get(int(f.datatype))
        if got is None or got.kind != want.kind:
            raise FrameError("bad_cloud", f"PointCloud2 field {name!r} has datatype {f.datatype}, expected {want}")
        if int(f.offset) + got.itemsize > step:
            raise FrameError("bad_cloud", f"PointCloud2 field {name!r} at offset {f.offset} exceeds point_step {step}")
        layout["names"].append(name)
        layout["formats"].append(got)
        layout["offsets"].append(int(f.offset))
    buf = np.frombuffer(msg.data, dtype=np.uint8) if not isinstance(msg.data, np.ndarray) else msg.data.view(np.uint8)
    if n == 0:
        return np.zeros(0, dtype=dtype)
    if buf.size < n * step:
        raise FrameError("bad_cloud", f"PointCloud2 data has {buf.size} bytes, {n} points of {step} need {n * step}")
    src = np.frombuffer(buf[: n * step].tobytes(), dtype=np.dtype(layout))
    out = np.zeros(n, dtype=dtype)
    for name in dtype.names:
        out[name] = src[name]
    return out


def read_boxes_csv(path: Path) -> np.ndarray:
    """CSV ``u1,v1,u2,v2,score,class_id`` -> BOX_DTYPE records; errors name file and line."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as e:
        raise ConfigError(str(path), None, f"cannot read: {e.strerror}") from None
    rows = []
    for i, line in enumerate(lines, 1):
        line = line.strip()
        if not line or line.startswith("#") or (i == 1 and line.replace(" ", "").startswith("u1,")):
            continue
        parts = line.split(",")
        if len(parts) != 6:
            raise ConfigError(str(path), f"line {i}", f"needs 6 columns u1,v1,u2,v2,score,class_id, got {len(parts)}")
        try:
            rows.append([float(x) for x in parts])
        except ValueError:
            raise ConfigError(str(path), f"line {i}", f"not numbers: {line!r}") from None
    a = np.asarray(rows, dtype=np.float64).reshape(-1, 6)
    if np.any(a[:, 5] != np.round(a[:, 5])) or np.any(a[:, 5] < 0):
        raise ConfigError(str(path), "class_id", "must be a non-negative integer")
    return boxes_from_arrays(a[:, :4], a[:, 4], a[:, 5].astype(np.int64))


# -- the stamp in a serialized message ------------------------------------------------------------

#: the encapsulations of plain CDR (what the ROS 2 middlewares write): big / little endian
_CDR_ENDIAN = {b"\x00\x00": ">", b"\x00\x01": "<"}


def cdr_stamp_ns(raw: bytes | bytearray | memoryview) -> int | None:
    """The header stamp (ns) of a serialized ROS 2 message whose first field is a ``std_msgs/Header``
    (Image, CompressedImage, PointCloud2, ...), read from its first 12 bytes (the 4-byte
    encapsulation, then ``int32 sec``, ``uint32 nanosec``) without deserializing the rest; ``None``
    for bytes that cannot be one (too short, unknown encapsulation, nanoseconds out of range)."""
    if len(raw) < 12:
        return None
    endian = _CDR_ENDIAN.get(bytes(raw[:2]))
    if endian is None:
        return None
    sec, nsec = struct.unpack_from(endian + "iI", raw, 4)
    if nsec >= 1_000_000_000:
        return None
    return sec * 1_000_000_000 + nsec


def with_cdr_stamp(raw: bytes, stamp_ns: int) -> bytes:
    """``raw`` (a serialized message with a header, as :func:`cdr_stamp_ns`) with its stamp set to
    ``stamp_ns``: how a publisher re-stamps recorded frames without deserializing them."""
    endian = _CDR_ENDIAN.get(bytes(raw[:2]))
    if endian is None or len(raw) < 12:
        raise ValueError("not a CDR-serialized message with a header")
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return raw[:4] + struct.pack(endian + "iI", sec, nsec) + raw[12:]


def xyxy_iou(a: np.ndarray, b: np.ndarray, inter: np.ndarray | None = None) -> np.ndarray:
    """(N, M) IoU of (N, 4) and (M, 4) ``u1 v1 u2 v2`` boxes (pixel edges), in float64 (``inter``: their
    :func:`xyxy_intersection` if at hand)."""
    inter = xyxy_intersection(a, b) if inter is None else inter
    union = xyxy_area(a)[:, None] + xyxy_area(b)[None] - inter
    return np.divide(inter, union, out=np.zeros_like(inter), where=union > 0)


def xyxy_area(a: np.ndarray) -> np.ndarray:
    """(N,) area (px^2) of (N, 4) ``u1 v1 u2 v2`` boxes, in float64."""
    u1, v1, u2, v2 = np.asarray(a, np.float64).reshape(-1, 4).T
    return (u2 - u1) * (v2 - v1)


def xyxy_intersection(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, M) area (px^2) shared by each of (N, 4) and (M, 4) ``u1 v1 u2 v2`` boxes, in float64."""
    au1, av1, au2, av2 = np.asarray(a, np.float64).reshape(-1, 4).T
    bu1, bv1, bu2, bv2 = np.asarray(b, np.float64).reshape(-1, 4).T
    iw = np.clip(np.minimum(au2[:, None], bu2[None]) - np.maximum(au1[:, None], bu1[None]), 0.0, None)
    return iw * np.clip(np.minimum(av2[:, None], bv2[None]) - np.maximum(av1[:, None], bv1[None]), 0.0, None)
