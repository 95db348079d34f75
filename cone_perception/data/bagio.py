"""rosbag2 (MCAP) reading and writing without ROS, through ``rosbags``.

One place for bag I/O, shared by the synthetic scenes, the replay tool and the
tests. Messages are ``rosbags`` message classes of the ROS 2 Jazzy type store
(:data:`TYPESTORE`), built with the helpers here or
:func:`cone_perception.records.to_pointcloud2`.

Writing::

    with BagWriter(path, {"/camera/image_raw": IMAGE}) as bag:
        bag.write("/camera/image_raw", stamp_ns, image_msg_from_bgr(bgr, stamp_ns, "camera"))

Reading::

    for m in read_messages(path, "/camera/image_raw"):
        m.stamp_ns, m.raw (CDR bytes), m.msg (deserialised on first access)
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping

import numpy as np
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from ..adapter import bgr_to_yuyv
from ..errors import ConfigError

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
VECTOR3_STAMPED = "geometry_msgs/msg/Vector3Stamped"
IMU = "sensor_msgs/msg/Imu"
ODOMETRY = "nav_msgs/msg/Odometry"

Header = TYPESTORE.types["std_msgs/msg/Header"]
Time = TYPESTORE.types["builtin_interfaces/msg/Time"]
Image = TYPESTORE.types[IMAGE]
CompressedImage = TYPESTORE.types[COMPRESSED_IMAGE]
PointCloud2 = TYPESTORE.types[POINTCLOUD2]
PointField = TYPESTORE.types["sensor_msgs/msg/PointField"]
Vector3Stamped = TYPESTORE.types[VECTOR3_STAMPED]
Vector3 = TYPESTORE.types["geometry_msgs/msg/Vector3"]
Quaternion = TYPESTORE.types["geometry_msgs/msg/Quaternion"]
Imu = TYPESTORE.types[IMU]
Odometry = TYPESTORE.types[ODOMETRY]
Point = TYPESTORE.types["geometry_msgs/msg/Point"]
Pose = TYPESTORE.types["geometry_msgs/msg/Pose"]
PoseWithCovariance = TYPESTORE.types["geometry_msgs/msg/PoseWithCovariance"]
Twist = TYPESTORE.types["geometry_msgs/msg/Twist"]
TwistWithCovariance = TYPESTORE.types["geometry_msgs/msg/TwistWithCovariance"]


def header(stamp_ns: int, frame_id: str) -> Any:
    """``std_msgs/Header`` with the stamp in integer nanoseconds."""
    return Header(stamp=Time(sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000)), frame_id=frame_id)


def stamp_ns(hdr: Any) -> int:
    """Nanoseconds of a header's stamp (rosbags or rclpy header)."""
    return int(hdr.stamp.sec) * 1_000_000_000 + int(hdr.stamp.nanosec)


def image_msg_from_bgr(bgr: np.ndarray, stamp: int, frame_id: str, encoding: str = "yuv422_yuy2") -> Any:
    """(H, W, 3) uint8 BGR -> ``sensor_msgs/Image`` in ``yuv422_yuy2`` (as cameras send) or ``bgr8``."""
    h, w = bgr.shape[:2]
    if encoding == "yuv422_yuy2":
        data, step = bgr_to_yuyv(bgr).reshape(-1), 2 * w
    elif encoding == "bgr8":
        data, step = np.ascontiguousarray(bgr).reshape(-1), 3 * w
    else:
        raise ValueError(f"image_msg_from_bgr: encoding must be yuv422_yuy2 or bgr8, got {encoding!r}")
    return Image(header=header(stamp, frame_id), height=h, width=w, encoding=encoding, is_bigendian=0, step=step, data=data)


def compressed_msg_from_bgr(bgr: np.ndarray, stamp: int, frame_id: str, quality: int = 90) -> Any:
    """(H, W, 3) uint8 BGR -> ``sensor_msgs/CompressedImage`` (JPEG)."""
    import cv2

    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return CompressedImage(header=header(stamp, frame_id), format="jpeg", data=buf.reshape(-1))


class BagWriter:
    """A new rosbag2 directory (MCAP storage) with the given ``topic -> message type``.

    Raises :class:`ConfigError` if ``path`` exists or its parent cannot be written.
    """

    def __init__(self, path: str | os.PathLike, topics: Mapping[str, str]):
        self.path = Path(path)
        check_new_output(self.path, "bag")
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._conns = {t: self._writer.add_connection(t, ty, typestore=TYPESTORE) for t, ty in topics.items()}
        self.counts = {t: 0 for t in topics}

    def write(self, topic: str, stamp: int, msg: Any) -> None:
        """Serialise ``msg`` (a :data:`TYPESTORE` message) and write it at ``stamp`` ns."""
        conn = self._conns[topic]
        self.write_raw(topic, stamp, TYPESTORE.serialize_cdr(msg, conn.msgtype))

    def write_raw(self, topic: str, stamp: int, cdr: bytes | memoryview) -> None:
        """Write already serialised CDR bytes at ``stamp`` ns."""
        self._writer.write(self._conns[topic], int(stamp), cdr)
        self.counts[topic] += 1

    def close(self) -> None:
        self._writer.close()

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def write_bag(path: str | os.PathLike, topics: Mapping[str, str], messages: Iterable[tuple[str, int, Any]]) -> dict[str, int]:
    """Write ``(topic, stamp_ns, msg)`` items to a new bag; returns the message count per topic."""
    with BagWriter(path, topics) as bag:
        for topic, stamp, msg in messages:
            bag.write(topic, stamp, msg)
        return dict(bag.counts)


@dataclass
class BagMessage:
    """One message of a bag: topic, type, log stamp (ns), raw CDR; ``msg`` deserialises lazily."""

    topic: str
    msgtype: str
    log_stamp_ns: int
    raw: bytes
    _msg: Any = field(default=None, repr=False)

    @property
    def msg(self) -> Any:
        if self._msg is None:
            self._msg = TYPESTORE.deserialize_cdr(self.raw, self.msgtype)
        return self._msg


def _open_reader(path: str | os.PathLike) -> Reader:
    p = Path(path)
    if not p.exists():
        raise ConfigError(str(p), None, "bag does not exist")
    try:
        reader = Reader(p)
        reader.open()
    except Exception as e:  # rosbags raises its own error types for broken metadata / storage
        raise ConfigError(str(p), None, f"cannot open as rosbag2: {e}") from None
    return reader


def bag_topics(path: str | os.PathLike) -> dict[str, tuple[str, int]]:
    """``topic -> (message type, message count)`` of a bag."""
    reader = _open_reader(path)
    try:
        return {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
    finally:
        reader.close()


def read_messages(path: str | os.PathLike, topics: str | Iterable[str] | None = None) -> Iterator[BagMessage]:
    """Messages of the given topic(s) (all if None) in log-time order.

    Raises :class:`ConfigError` naming the bag and the topic if a requested topic is not in it.
    """
    reader = _open_reader(path)
    try:
        want = [topics] if isinstance(topics, str) else (None if topics is None else list(topics))
        conns = reader.connections
        if want is not None:
            have = {c.topic for c in conns}
            for t in want:
                if t not in have:
                    raise ConfigError(str(path), t, f"topic not in bag (topics: {', '.join(sorted(have))})")
            conns = [c for c in conns if c.topic in want]
        it = reader.messages(connections=conns)
        while True:
            try:
                conn, t, raw = next(it)
            except StopIteration:
                break
            except Exception as e:  # rosbags / mcap raise their own types for truncated or broken storage
                raise ConfigError(str(path), None, f"bag is corrupt or truncated: {type(e).__name__}: {e}") from None
            yield BagMessage(conn.topic, conn.msgtype, int(t), bytes(raw))
    finally:
        reader.close()


def ensure_writable_dir(path: Path) -> None:
    """Create ``path`` (and parents) if needed; :class:`ConfigError` unless it is a writable directory."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError(str(path), None, f"cannot create directory: {e.strerror}") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise ConfigError(str(path), None, "directory is not writable")


def check_new_output(path: Path, what: str) -> None:
    """Raise :class:`ConfigError` unless ``path`` does not exist and its parent is (or can be made) writable."""
    if path.exists():
        raise ConfigError(str(path), None, f"{what} output already exists; remove it or choose another path")
    ensure_writable_dir(path.parent)
