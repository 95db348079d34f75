"""Replay of a rosbag's camera topic through the pipeline: offline, without ROS (:mod:`.offline`), with the
tracker and its scoring (:mod:`.tracking`); live through node processes in
:mod:`cone_perception.rostools.live_replay`. Reading the bag's topics is :mod:`cone_perception.data.bags`.
"""

from __future__ import annotations

from .offline import ReplayResult, offline_replay, process_frame
from .tracking import ReplayTracking, drive_truth_beside, drop_detections, format_replay_tracking

__all__ = ["ReplayResult", "ReplayTracking", "drive_truth_beside", "drop_detections", "format_replay_tracking",
    "offline_replay", "process_frame"]
