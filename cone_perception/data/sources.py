"""Image sources -> full BGR frames: an image file, a folder of images, a video file, a rosbag2 camera topic.

One reader for every command that reads frames (``detect``, ``bench table``, ``calibrate --image/--bag``,
``demo``'s pictures); a bag message becomes a frame through :func:`cone_perception.data.bags.frame_bgr`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from ..adapter import decode_compressed
from ..errors import ConfigError, FrameError
from .bags import find_image_topic, frame_bgr, iter_frames

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp")
#: Files read with OpenCV's VideoCapture.
VIDEO_SUFFIXES = (".mp4", ".avi", ".mkv", ".mov", ".m4v", ".webm")



def iter_source(source: Path, topic: str | None = None, every: int = 1
                ) -> Iterator[tuple[str, np.ndarray | None, str | None]]:
    """``(name, bgr full image or None, error or None)`` for an image, a folder, a video or a bag;
    of a video or a bag every ``every``-th frame only."""
    if every < 1:
        raise ConfigError("--every", None, f"must be >= 1, got {every}")
    if not source.exists():
        raise ConfigError(str(source), None, "source does not exist")
    if source.is_dir() and (source / "metadata.yaml").is_file():
        for k, item in enumerate(iter_bag(source, topic)):
            if k % every == 0:
                yield item
        return
    if source.is_file() and source.suffix.lower() in VIDEO_SUFFIXES:
        yield from iter_video(source, every)
        return
    files = [source] if source.is_file() else sorted(p for p in source.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise ConfigError(str(source), None, f"no images ({', '.join(IMAGE_SUFFIXES)}) found")

    for f in files:
        name = str(f.relative_to(source)) if source.is_dir() else f.name
        try:  # the nodes' decoding: the header's size is checked before the decoder runs
            yield name, decode_compressed(f.read_bytes()), None
        except FrameError as e:
            yield name, None, f"{e.reason}: {e}"
        except OSError as e:
            yield name, None, f"unreadable: {e.strerror}"


def iter_video(path: Path, every: int = 1) -> Iterator[tuple[str, np.ndarray | None, str | None]]:
    """``(<stem>_<frame index 000000>, bgr frame, None)`` of every ``every``-th frame of a video file.
    A file OpenCV cannot open, or one that yields no frame, is a :class:`ConfigError` naming it."""
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise ConfigError(str(path), None, "cannot open the video (OpenCV VideoCapture; is it a video file "
                                               "of a codec this OpenCV build reads?)")
        k, read = 0, 0
        while True:
            if k % every == 0:
                ok, frame = cap.read()
                if not ok:
                    break
                read += 1
                yield f"{path.stem}_{k:06d}", frame, None
            elif not cap.grab():
                break
            k += 1
        if read == 0:
            raise ConfigError(str(path), None, "the video holds no readable frame")
    finally:
        cap.release()


def iter_bag(bag: Path, topic: str | None = None) -> Iterator[tuple[str, np.ndarray | None, str | None]]:
    """``(header stamp ns, bgr full image or None, error or None)`` of every message on the bag's camera topic."""

    topic, _ = find_image_topic(bag, topic)
    for fr in iter_frames(bag, topic):
        try:
            yield str(fr.stamp_ns), frame_bgr(fr), None
        except FrameError as e:
            yield str(fr.stamp_ns), None, str(e)


def read_image(path: Path) -> np.ndarray:
    """One image file -> full BGR image, decoded as the nodes decode (the header's size checked first);
    :class:`ConfigError` naming the file otherwise."""
    if not path.is_file():
        raise ConfigError(str(path), None, "image file not found")
    try:
        return decode_compressed(path.read_bytes())
    except FrameError as e:
        raise ConfigError(str(path), None, f"cannot decode the image ({e.reason}): {e}") from None


def read_bag_image(bag: Path, index: int, topic: str | None = None) -> tuple[np.ndarray, str]:
    """The ``index``-th message (from 0) of a rosbag2's camera topic as a full BGR image, and a description
    ``bag#topic[index]``. :class:`ConfigError` naming the bag and ``--topic`` / ``--frame`` otherwise."""
    if not Path(bag).exists():
        raise ConfigError(str(bag), None, "bag not found")
    if index < 0:
        raise ConfigError(str(bag), "--frame", f"must be >= 0, got {index}")
    topic, _ = find_image_topic(bag, topic)
    count = 0
    for k, fr in enumerate(iter_frames(bag, topic)):
        count = k + 1
        if k < index:
            continue
        try:
            return frame_bgr(fr), f"{bag}#{topic}[{index}]"
        except FrameError as e:
            raise ConfigError(str(bag), "--frame", f"image message {index} on {topic}: {e}") from None
    raise ConfigError(str(bag), "--frame", f"frame {index} not in the bag: it has {count} image messages on {topic}")
