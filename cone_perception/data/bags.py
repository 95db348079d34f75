"""Reading a rosbag's topics (no ROS): the camera topic and its frames (full BGR images), ground-truth
cones, the IMU, the true attitude, odometry twists; the topic names the tools write and read.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from ..adapter import DriverAdapter, decode_compressed
from ..crop import CropSpec
from ..errors import ConfigError, FrameError
from ..records import CONE_DTYPE, from_pointcloud2
from . import bagio
from .bagio import ODOMETRY

IMAGE_TYPES = (bagio.IMAGE, bagio.COMPRESSED_IMAGE)
BOXES_TOPIC = "/cone_boxes"
CONES_TOPIC = "/cones"
ATTITUDE_TOPIC = "/cones/attitude"
ATTITUDE_GT_TOPIC = "/attitude_gt"
IMU_TOPIC = "/imu"
TRACKED_TOPIC = "/cones/tracked"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"


def find_image_topic(bag: str | os.PathLike, topic: str | None = None) -> tuple[str, str]:
    """``(topic, msgtype)`` of the bag's camera topic; ``topic`` picks one when there are several."""
    topics = bagio.bag_topics(bag)
    if topic is not None:
        if topic not in topics:
            raise ConfigError(str(bag), topic, f"topic not in bag (topics: {', '.join(sorted(topics))})")
        if topics[topic][0] not in IMAGE_TYPES:
            raise ConfigError(str(bag), topic, f"is {topics[topic][0]}, not an image topic")
        return topic, topics[topic][0]
    images = sorted(t for t, (ty, _) in topics.items() if ty in IMAGE_TYPES)
    if not images:
        raise ConfigError(str(bag), None, f"no sensor_msgs/Image or CompressedImage topic (topics: {', '.join(sorted(topics))})")
    if len(images) > 1:
        raise ConfigError(str(bag), None, f"several image topics ({', '.join(images)}); choose one with --topic")
    return images[0], topics[images[0]][0]


@dataclass
class Frame:
    """One camera message of a bag: header stamp (ns), log stamp, and the message (or the error)."""

    stamp_ns: int
    log_stamp_ns: int
    msgtype: str
    raw: bytes
    msg: object = None
    error: FrameError | None = None


def iter_frames(bag: str | os.PathLike, topic: str) -> Iterator[Frame]:
    """Camera messages of ``topic``; a message that does not deserialise carries ``error``."""
    for m in bagio.read_messages(bag, topic):
        try:
            msg = m.msg
            yield Frame(bagio.stamp_ns(msg.header), m.log_stamp_ns, m.msgtype, m.raw, msg)
        except Exception as e:  # noqa: BLE001 - rosbags raises many types for corrupt CDR
            yield Frame(m.log_stamp_ns, m.log_stamp_ns, m.msgtype, m.raw, None,
                        FrameError("corrupt_message", f"message at {m.log_stamp_ns} ns does not deserialise: {e}"))


def frame_bgr(frame: Frame) -> np.ndarray:
    """The full BGR uint8 image of a bag's camera message (raises :class:`FrameError` for a bad one)."""
    if frame.error is not None:
        raise frame.error
    m = frame.msg
    if frame.msgtype == bagio.COMPRESSED_IMAGE:
        return decode_compressed(m.data)
    w, h = int(m.width), int(m.height)
    return DriverAdapter(CropSpec.full_image(w - w % 2, h), w - w % 2, h).from_raw(m.encoding, w, h, int(m.step), m.data)


def read_bag_images(bag: str | os.PathLike, stamps: set[int], topic: str | None = None) -> dict[int, np.ndarray]:
    """``header stamp ns -> BGR image`` of the camera frames with these stamps (one pass; bad frames left out)."""
    topic, _ = find_image_topic(bag, topic)
    out = {}
    for fr in iter_frames(bag, topic):
        if fr.stamp_ns in stamps and fr.stamp_ns not in out:
            try:
                out[fr.stamp_ns] = frame_bgr(fr)
            except FrameError:
                continue
            if len(out) == len(stamps):
                break
    return out


def read_ground_truth(bag: str | os.PathLike, topic: str) -> dict[int, np.ndarray]:
    """``header stamp ns -> CONE_DTYPE`` records of a ground-truth cones topic (e.g. ``/cones_gt``)."""
    out = {}
    for m in bagio.read_messages(bag, topic):
        if m.msgtype != bagio.POINTCLOUD2:
            raise ConfigError(str(bag), topic, f"is {m.msgtype}, expected sensor_msgs/msg/PointCloud2")
        out[bagio.stamp_ns(m.msg.header)] = from_pointcloud2(m.msg, CONE_DTYPE)
    return out


def read_imu(bag: str | os.PathLike, topic: str = IMU_TOPIC) -> list[tuple[int, tuple[float, float, float, float]]]:
    """``(header stamp ns, orientation (x, y, z, w))`` of a bag's IMU topic in stamp order (empty without it)."""
    if topic not in bagio.bag_topics(bag):
        return []
    out = []
    for m in bagio.read_messages(bag, topic):
        q = m.msg.orientation
        out.append((bagio.stamp_ns(m.msg.header), (float(q.x), float(q.y), float(q.z), float(q.w))))
    return sorted(out, key=lambda t: t[0])


def read_imu_motion(bag: str | os.PathLike, topic: str = IMU_TOPIC) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A bag's IMU topic as arrays in stamp order: header stamps (N,) ns, orientation (N, 4) x, y, z, w,
    angular rate (N, 3) rad/s, linear acceleration (N, 3) m/s^2. Raises :class:`ConfigError` without the
    topic or for another message type."""
    topics = bagio.bag_topics(bag)
    if topic not in topics:
        raise ConfigError(str(bag), topic, f"no such topic (topics: {', '.join(sorted(topics))})")
    if topics[topic][0] != bagio.IMU:
        raise ConfigError(str(bag), topic, f"is {topics[topic][0]}, not {bagio.IMU}")
    rows = []
    for m in bagio.read_messages(bag, topic):
        q, w, a = m.msg.orientation, m.msg.angular_velocity, m.msg.linear_acceleration
        rows.append((bagio.stamp_ns(m.msg.header), (q.x, q.y, q.z, q.w), (w.x, w.y, w.z), (a.x, a.y, a.z)))
    rows.sort(key=lambda r: r[0])
    return (np.array([r[0] for r in rows], dtype=np.int64), np.array([r[1] for r in rows], dtype=np.float64).reshape(-1, 4),
            np.array([r[2] for r in rows], dtype=np.float64).reshape(-1, 3), np.array([r[3] for r in rows], dtype=np.float64).reshape(-1, 3))


def read_attitude_truth(bag: str | os.PathLike, topic: str = ATTITUDE_GT_TOPIC) -> dict[int, tuple[float, float]]:
    """``header stamp ns -> (pitch, roll)`` degrees of a synthetic bag's ``/attitude_gt`` (empty without it)."""
    if topic not in bagio.bag_topics(bag):
        return {}
    out = {}
    for m in bagio.read_messages(bag, topic):
        v = m.msg.vector
        out[bagio.stamp_ns(m.msg.header)] = (float(np.degrees(v.y)), float(np.degrees(v.x)))
    return out


def read_twists(bag: str | os.PathLike, topic: str) -> list[tuple[int, float, float, float]]:
    """``(header stamp ns, vx, vy, wz)`` of a ``nav_msgs/Odometry`` or ``geometry_msgs/TwistStamped`` topic, by stamp."""
    out = []
    for m in bagio.read_messages(bag, topic):
        if m.msgtype == ODOMETRY:
            tw = m.msg.twist.twist
        elif m.msgtype == TWIST_STAMPED:
            tw = m.msg.twist
        else:
            raise ConfigError(str(bag), topic, f"is {m.msgtype}, expected {ODOMETRY} or {TWIST_STAMPED}")
        out.append((bagio.stamp_ns(m.msg.header), float(tw.linear.x), float(tw.linear.y), float(tw.angular.z)))
    return sorted(out, key=lambda t: t[0])
