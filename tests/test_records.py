"""PointCloud2 record arrays: both ways, with rclpy and rosbags messages, through CDR bytes."""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header

from cone_perception.errors import FrameError
from cone_perception.records import (
    BOX_DTYPE, CONE_DTYPE, BoxColumns, boxes_from_arrays, from_pointcloud2, point_fields, to_pointcloud2,
)

TS = get_typestore(Stores.ROS2_JAZZY)
RB_CLOUD = TS.types["sensor_msgs/msg/PointCloud2"]
RB_FIELD = TS.types["sensor_msgs/msg/PointField"]
RB_HEADER = TS.types["std_msgs/msg/Header"]
RB_TIME = TS.types["builtin_interfaces/msg/Time"]


def _cones(n: int = 5) -> np.ndarray:
    rng = np.random.default_rng(1)
    c = np.zeros(n, dtype=CONE_DTYPE)
    for name in CONE_DTYPE.names:
        c[name] = rng.integers(0, 5, n) if name == "class_id" else rng.normal(size=n)
    return c


def test_field_layout_matches_the_architecture() -> None:
    assert [f[0] for f in point_fields(BOX_DTYPE)] == ["u1", "v1", "u2", "v2", "score", "class_id"]
    assert [f[0] for f in point_fields(CONE_DTYPE)] == ["x", "y", "z", "class_id", "score", "cov_xx", "cov_xy", "cov_yy"]
    types = {n: d for n, _, d, _ in point_fields(CONE_DTYPE)}
    assert types["class_id"] == PointField.UINT8 and types["x"] == PointField.FLOAT32
    # offsets are 4-byte aligned for C++ consumers
    assert all(off % 4 == 0 for _, off, _, _ in point_fields(CONE_DTYPE))


@pytest.mark.parametrize("dtype", [BOX_DTYPE, CONE_DTYPE])
def test_rclpy_round_trip_through_cdr(dtype) -> None:
    recs = _cones() if dtype == CONE_DTYPE else boxes_from_arrays(np.arange(12.0).reshape(3, 4), [0.1, 0.5, 0.9], [0, 1, 4])
    h = Header(frame_id="rear_axle")
    h.stamp.sec, h.stamp.nanosec = 12, 345
    msg = to_pointcloud2(recs, h, PointCloud2, PointField)
    assert (msg.height, msg.width, msg.point_step) == (1, recs.shape[0], dtype.itemsize)
    back = deserialize_message(serialize_message(msg), PointCloud2)
    assert back.header.stamp.sec == 12 and back.header.frame_id == "rear_axle"
    np.testing.assert_array_equal(from_pointcloud2(back, dtype), recs)


def test_rosbags_messages_and_cross_serialization() -> None:
    cones = _cones(4)
    header = RB_HEADER(stamp=RB_TIME(sec=3, nanosec=7), frame_id="rear_axle")
    msg = to_pointcloud2(cones, header, RB_CLOUD, RB_FIELD)
    raw = TS.serialize_cdr(msg, RB_CLOUD.__msgtype__)
    np.testing.assert_array_equal(from_pointcloud2(TS.deserialize_cdr(raw, RB_CLOUD.__msgtype__), CONE_DTYPE), cones)
    # the same bytes are a valid rclpy message (what the live replay publishes)
    ros_msg = deserialize_message(bytes(raw), PointCloud2)
    np.testing.assert_array_equal(from_pointcloud2(ros_msg, CONE_DTYPE), cones)


def test_fields_found_by_name_with_other_offsets_and_extra_fields() -> None:
    # a producer that packs its own way: extra field first, 4-byte class id, other order
    src = np.zeros(3, dtype=[("intensity", "<f4"), ("class_id", "<u4"), ("y", "<f4"), ("x", "<f4"), ("z", "<f4"),
                             ("score", "<f4"), ("cov_xx", "<f4"), ("cov_xy", "<f4"), ("cov_yy", "<f4")])
    src["x"], src["y"], src["class_id"], src["score"] = [1, 2, 3], [4, 5, 6], [0, 1, 2], [0.5, 0.6, 0.7]
    fields = [PointField(name=n, offset=src.dtype.fields[n][1], datatype=6 if n == "class_id" else 7, count=1)
              for n in src.dtype.names]
    msg = PointCloud2(height=1, width=3, fields=fields, is_bigendian=False, point_step=src.dtype.itemsize,
                      row_step=src.dtype.itemsize * 3, data=src.tobytes(), is_dense=True)
    out = from_pointcloud2(msg, CONE_DTYPE)
    np.testing.assert_array_equal(out["x"], [1, 2, 3])
    np.testing.assert_array_equal(out["class_id"], [0, 1, 2])


def test_bad_clouds_raise_frame_errors() -> None:
    cones = _cones(2)
    good = to_pointcloud2(cones, Header(), PointCloud2, PointField)
    missing = to_pointcloud2(cones, Header(), PointCloud2, PointField)
    missing.fields = [f for f in missing.fields if f.name != "score"]
    with pytest.raises(FrameError, match="no field 'score'"):
        from_pointcloud2(missing, CONE_DTYPE)
    short = to_pointcloud2(cones, Header(), PointCloud2, PointField)
    short.data = bytes(good.data)[:-5]
    with pytest.raises(FrameError, match="bytes"):
        from_pointcloud2(short, CONE_DTYPE)
    typed = to_pointcloud2(cones, Header(), PointCloud2, PointField)
    typed.fields[0].datatype = PointField.INT32
    with pytest.raises(FrameError, match="datatype"):
        from_pointcloud2(typed, CONE_DTYPE)
    with pytest.raises(FrameError, match="no field"):
        from_pointcloud2(good, BOX_DTYPE)  # a /cones cloud is not a boxes cloud


def test_empty_cloud() -> None:
    msg = to_pointcloud2(np.zeros(0, CONE_DTYPE), Header(), PointCloud2, PointField)
    assert msg.width == 0 and from_pointcloud2(msg, CONE_DTYPE).shape == (0,)


def test_box_columns_hold_the_records_values_and_subsets_keep_them_together() -> None:
    recs = boxes_from_arrays(np.array([[10.25, 20.5, 30.125, 60.0], [1.0, 2.0, 3.0, 4.0], [5.5, 6.5, 9.5, 12.0]]),
                             np.array([0.9, 0.3, 0.6]), np.array([1, 0, 4]))
    cols = BoxColumns.of(recs)
    assert len(cols) == 3 and cols.records is recs
    assert cols.xyxy.dtype == np.float32 and cols.xyxy.shape == (3, 4) and cols.score.dtype == np.float32
    np.testing.assert_array_equal(cols.xyxy[:, 2], recs["u2"])
    np.testing.assert_array_equal(cols.xyxy[0], [10.25, 20.5, 30.125, 60.0])
    assert cols.class_id.tolist() == [1, 0, 4]
    assert BoxColumns.of(cols) is cols  # made once: a view is taken as it is
    sub = cols.take(cols.score >= 0.5)
    assert sub.records.tolist() == recs[[0, 2]].tolist() and sub.class_id.tolist() == [1, 4]
    np.testing.assert_array_equal(sub.xyxy, cols.xyxy[[0, 2]])
    empty = BoxColumns.of(recs[:0])
    assert empty.xyxy.shape == (0, 4) and len(empty) == 0
    packed = np.zeros(2, dtype=[(n, BOX_DTYPE.fields[n][0]) for n in BOX_DTYPE.names])  # the fields without padding
    packed["u2"] = 7.0
    assert BoxColumns.of(packed).records.dtype == BOX_DTYPE and BoxColumns.of(packed).xyxy[:, 2].tolist() == [7.0, 7.0]
