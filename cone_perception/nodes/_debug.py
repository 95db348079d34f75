"""``image_cropped/debug`` of a node (``debug_image: true``): drawn by the core
(:mod:`cone_perception.vis.debug_image`) at most ``debug_image_hz`` times a second, and only while
someone subscribes."""

from __future__ import annotations

import time

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import Image

from ..crop import CropSpec
from ..mapping import ConeMapper
from ..vis.debug_image import DebugImage
from . import _msgs
from ._common import QOS_IMAGE_OUT
from ._params import RuntimeParameters, declare

DEBUG_TOPIC = "image_cropped/debug"


class DebugImagePublisher:
    """Declares ``debug_image`` / ``debug_image_hz`` on ``node``, both changeable at run time.
    ``mapper``: for the cones' distances on the image (None: no distances)."""

    def __init__(self, node: Node, mapper: ConeMapper | None, runtime: RuntimeParameters) -> None:
        self.node = node
        self.debug = DebugImage(mapper, float(declare(node, "debug_image_hz")))
        self.pub = None
        self.published = 0
        self.set_enabled(bool(declare(node, "debug_image")))
        runtime.register("debug_image", self.set_enabled)
        runtime.register("debug_image_hz", self.set_hz)

    def set_enabled(self, on) -> None:
        self.enabled = bool(on)
        if self.enabled and self.pub is None:  # advertised from the first time it is switched on
            self.pub = self.node.create_publisher(Image, DEBUG_TOPIC, QOS_IMAGE_OUT)

    def set_hz(self, hz) -> None:
        self.debug.limit.hz = float(hz)

    def publish(self, band_bgr: np.ndarray, boxes: np.ndarray, crop: CropSpec, header) -> None:
        """Draw and publish the frame's debug image if switched on, subscribed and due."""
        if not self.enabled or self.pub is None or self.pub.get_subscription_count() == 0:
            return
        if not self.debug.limit.due(time.monotonic()):
            return
        self.pub.publish(_msgs.bgr_image(self.debug.render(band_bgr, boxes, crop), header))
        self.published += 1
