"""Offline replay of a rosbag through the full pipeline, without ROS.

The bag's camera topic (sensor_msgs/Image in ``yuv422_yuy2``/``bgr8``/``rgb8``, or
CompressedImage) is fed frame by frame through :class:`~cone_perception.pipeline.Pipeline`
(the code the fused node runs); ``cone_boxes`` and ``/cones`` are written with the original
header stamps to a new bag. A frame that cannot be processed (bad encoding, corrupt message)
is dropped and counted; the other frames go on.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from ..attitude import Attitude, attitude_vector
from ..data import bagio
from ..data.bags import (
    ATTITUDE_TOPIC, BOXES_TOPIC, CONES_TOPIC, IMU_TOPIC, TRACKED_TOPIC, Frame, find_image_topic, iter_frames,
    read_attitude_truth, read_ground_truth, read_imu,
)
from ..errors import FrameError
from ..evaluation import GT_MIN_VISIBLE, LocalisationReport
from ..evaluation.attitude import AttitudeReport
from ..pipeline import Pipeline
from ..records import BOX_DTYPE, to_pointcloud2
from ..stats import FrameStats
from ..timing import StageTimer


def process_frame(pipeline: Pipeline, frame: Frame):
    """Run one bag frame through the pipeline (raises :class:`FrameError`)."""
    if frame.error is not None:
        raise frame.error
    msg = frame.msg
    if frame.msgtype == bagio.COMPRESSED_IMAGE:
        return pipeline.process_compressed(msg.data, stamp_ns=frame.stamp_ns)
    return pipeline.process_raw(msg.encoding, int(msg.width), int(msg.height), int(msg.step), msg.data,
                                stamp_ns=frame.stamp_ns)


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
    :class:`~cone_perception.replay.ReplayTracking` (drops detections, tracks; ``/cones/tracked``
    is written too).
    """
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
    report = LocalisationReport(max_range_m=pipeline.calib.max_range_m, min_visible=GT_MIN_VISIBLE) if truth is not None else None
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
                r.cones, tracked = tracking.frame(fr.stamp_ns, r.cones, r.attitude, r.weak_cones)
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
