"""Offline replay of a rosbag through the full pipeline, without ROS.

The bag's camera topic (sensor_msgs/Image in ``yuv422_yuy2``/``bgr8``/``rgb8``, or
CompressedImage) is fed frame by frame through :class:`~cone_perception.pipeline.Pipeline`
(the code the fused node runs); ``cone_boxes`` and ``/cones`` are written with the original
header stamps to a new bag. A frame that cannot be processed (bad encoding, corrupt message)
is dropped and counted; the other frames go on.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from . import bagio
from .attitude import Attitude, AttitudeReport, attitude_vector
from .timing import StageTimer
from .errors import ConfigError, FrameError
from .evaluation import LocalisationReport
from .pipeline import Pipeline
from .records import BOX_DTYPE, CONE_DTYPE, from_pointcloud2, to_pointcloud2
from .stats import FrameStats

IMAGE_TYPES = (bagio.IMAGE, bagio.COMPRESSED_IMAGE)
BOXES_TOPIC = "/cone_boxes"
CONES_TOPIC = "/cones"
ATTITUDE_TOPIC = "/cones/attitude"
ATTITUDE_GT_TOPIC = "/attitude_gt"
IMU_TOPIC = "/imu"
TRACKED_TOPIC = "/cones/tracked"


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
    from .adapter import DriverAdapter, decode_compressed
    from .crop import CropSpec

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


def process_frame(pipeline: Pipeline, frame: Frame):
    """Run one bag frame through the pipeline (raises :class:`FrameError`)."""
    if frame.error is not None:
        raise frame.error
    msg = frame.msg
    if frame.msgtype == bagio.COMPRESSED_IMAGE:
        return pipeline.process_compressed(msg.data, stamp_ns=frame.stamp_ns)
    return pipeline.process_raw(msg.encoding, int(msg.width), int(msg.height), int(msg.step), msg.data,
                                stamp_ns=frame.stamp_ns)


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


@dataclass
class ReplayResult:
    boxes: dict[int, np.ndarray] = field(default_factory=dict)  # stamp ns -> BOX_DTYPE
    cones: dict[int, np.ndarray] = field(default_factory=dict)  # stamp ns -> CONE_DTYPE
    timer: StageTimer = field(default_factory=StageTimer)
    stats: FrameStats = field(default_factory=FrameStats)
    drops: list[tuple[int, str]] = field(default_factory=list)  # (stamp, message)
    wall_s: float = 0.0
    localisation: dict | None = None
    attitude: dict[int, Attitude] = field(default_factory=dict)  # stamp ns -> attitude used
    attitude_mode: str = "fixed"
    pipeline_attitude: dict | None = None  # image fit outcomes: fitted / too few cones / rejected
    tracked: dict[int, np.ndarray] = field(default_factory=dict)  # stamp ns -> TRACKED_CONE_DTYPE (replay --track)
    tracking: dict | None = None  # ReplayTracking.summary()


def offline_replay(
    bag: str | os.PathLike,
    pipeline: Pipeline,
    topic: str | None = None,
    out: str | os.PathLike | None = None,
    gt_topic: str | None = None,
    progress: Callable[[int], Iterator] | None = None,
    imu_topic: str = IMU_TOPIC,
    tracking=None,
) -> ReplayResult:
    """Replay ``bag`` through ``pipeline``; write ``/cone_boxes`` and ``/cones`` to ``out`` if given.

    ``progress`` wraps the frame iterator (e.g. a tqdm factory taking the total). ``tracking``: a
    :class:`~cone_perception.track_replay.ReplayTracking` (drops detections, tracks; ``/cones/tracked``
    is written too).
    """
    import time

    topic, _ = find_image_topic(bag, topic)
    total = bagio.bag_topics(bag)[topic][1]
    truth = read_ground_truth(bag, gt_topic) if gt_topic else None
    writer = None
    if out is not None:
        topics = {BOXES_TOPIC: bagio.POINTCLOUD2, CONES_TOPIC: bagio.POINTCLOUD2}
        if pipeline.attitude_mode != "fixed":
            topics[ATTITUDE_TOPIC] = bagio.VECTOR3_STAMPED
        if tracking is not None and tracking.stage is not None:
            topics[TRACKED_TOPIC] = bagio.POINTCLOUD2
        writer = bagio.BagWriter(Path(out), topics)
    res = ReplayResult()
    report = LocalisationReport(max_range_m=pipeline.calib.max_range_m) if truth is not None else None
    att_truth = read_attitude_truth(bag) if truth is not None else {}
    att_report = AttitudeReport() if truth is not None else None
    frames = iter_frames(bag, topic)
    imu_msgs = read_imu(bag, imu_topic) if pipeline.imu is not None else []
    k_imu = 0
    if progress is not None:
        frames = progress(frames, total)
    t_start = time.perf_counter()
    try:
        for fr in frames:
            while k_imu < len(imu_msgs) and imu_msgs[k_imu][0] <= fr.stamp_ns:  # the IMU up to this frame
                pipeline.imu.add(*imu_msgs[k_imu])
                k_imu += 1
            t0 = time.perf_counter()
            try:
                r = process_frame(pipeline, fr)
            except FrameError as e:
                res.stats.count_drop(e.reason)
                res.drops.append((fr.stamp_ns, str(e)))
                continue
            res.timer.add("end_to_end", time.perf_counter() - t0)
            for k, v in r.timing_ms.items():
                res.timer.add(k, v / 1e3)
            res.stats.count_ok()
            tracked = None
            if tracking is not None:
                r.cones, tracked = tracking.frame(fr.stamp_ns, r.cones, r.attitude)
                if tracked is not None:
                    res.tracked[fr.stamp_ns] = tracked
            res.boxes[fr.stamp_ns], res.cones[fr.stamp_ns] = r.boxes, r.cones
            if writer is not None:
                frame_id = getattr(fr.msg.header, "frame_id", "")
                writer.write(BOXES_TOPIC, fr.log_stamp_ns, to_pointcloud2(
                    r.boxes.astype(BOX_DTYPE), bagio.header(fr.stamp_ns, frame_id), bagio.PointCloud2, bagio.PointField))
                writer.write(CONES_TOPIC, fr.log_stamp_ns, to_pointcloud2(
                    r.cones, bagio.header(fr.stamp_ns, pipeline.calib.frame_id), bagio.PointCloud2, bagio.PointField))
                if tracked is not None:
                    writer.write(TRACKED_TOPIC, fr.log_stamp_ns, to_pointcloud2(
                        tracked, bagio.header(fr.stamp_ns, pipeline.calib.frame_id), bagio.PointCloud2, bagio.PointField))
                if ATTITUDE_TOPIC in topics:
                    roll, pitch, yaw = attitude_vector(r.attitude)
                    writer.write(ATTITUDE_TOPIC, fr.log_stamp_ns, bagio.Vector3Stamped(
                        header=bagio.header(fr.stamp_ns, pipeline.calib.frame_id), vector=bagio.Vector3(x=roll, y=pitch, z=yaw)))
            res.attitude[fr.stamp_ns] = r.attitude
            if report is not None and fr.stamp_ns in truth:
                pairs = report.add_frame(r.cones, truth[fr.stamp_ns])
                att_report.add_frame(r.attitude, att_truth.get(fr.stamp_ns), r.cones, truth[fr.stamp_ns], pairs)
    finally:
        if writer is not None:
            writer.close()
    res.wall_s = time.perf_counter() - t_start
    res.attitude_mode = pipeline.attitude_mode
    if pipeline.attitude is not None:
        res.pipeline_attitude = pipeline.attitude.counts.as_dict()
    if pipeline.imu is not None:
        res.pipeline_attitude = {**(res.pipeline_attitude or {}), **{f"imu_{k}": v for k, v in pipeline.imu.counts.as_dict().items()}}
    if report is not None:
        res.localisation = report.summary()
        res.localisation["attitude"] = att_report.summary()
    if tracking is not None:
        res.tracking = tracking.summary()
    return res
