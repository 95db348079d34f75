"""Tracking: a local map of static cones with ids (:mod:`.tracker`), where the camera sees them (:mod:`.view`), the tracker as a pipeline stage
(:mod:`.stage`) and the car's motion between frames (:mod:`cone_perception.geometry.motion`, shared with the image attitude). Its figures against a synthetic
drive are :mod:`cone_perception.evaluation.tracking`. ROS-free.
"""

from __future__ import annotations

from ..geometry.motion import Motion2D, Registration, TwistBuffer, from_twist, register_cones
from .stage import TrackingStage
from .tracker import INPUT_EVENTS, ConeTracker, FrameInfo, TrackerConfig
from .view import FieldOfView

__all__ = ["ConeTracker", "FieldOfView", "FrameInfo", "INPUT_EVENTS", "Motion2D", "Registration", "TrackerConfig",
    "TrackingStage", "TwistBuffer", "from_twist", "register_cones"]
