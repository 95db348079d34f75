"""Frames to time the pipeline on: synthetic raw frames and rendered scenes with cones."""

from __future__ import annotations

import cv2
import numpy as np

from ..adapter import bgr_to_yuyv
from ..synth.config import SynthConfig
from ..synth.scene import random_pose


def synthetic_frames(width: int, height: int, encoding: str, n: int, seed: int = 0) -> list[bytes]:
    """``n`` distinct raw frames of a smooth random scene in ``encoding`` (bytes, tight step)."""
    rng = np.random.default_rng(seed)
    out = []
    base = cv2.resize(rng.integers(0, 255, (height // 16, width // 16, 3), dtype=np.uint8), (width, height))
    for i in range(n):
        bgr = np.roll(base, 7 * i, axis=1)
        if encoding == "yuv422_yuy2":
            out.append(bgr_to_yuyv(bgr).tobytes())
        elif encoding == "rgb8":
            out.append(bgr[:, :, ::-1].tobytes())
        else:
            out.append(bgr.tobytes())
    return out


def rendered_frames(calib, n: int, seed: int = 4242) -> list[bytes]:
    """``n`` YUYV frames of rendered scenes with cones, at the calibration's image size."""
    cfg = SynthConfig(width=calib.image_width, height=calib.image_height, seed=seed, jitter=False)
    renderer, rng = cfg.renderer(), np.random.default_rng(seed)
    out = []
    for i in range(n):
        if i % 8 == 0:
            track, look = cfg.track(i, rng), renderer.new_look(rng)
        img, _ = renderer.render(track, random_pose(track, rng, False), look, rng)
        out.append(bgr_to_yuyv(img).tobytes())
    return out
