"""Driver adapter: camera frames (YUYV, BGR, RGB, JPEG/PNG) -> cropped BGR band.

The work is done on as few bytes as possible: the rows (and columns) of the
band are sliced out of the raw buffer before any colour conversion, so a
1920x1080 YUYV frame costs only the 1920x576 band's conversion.

Every per-frame problem raises :class:`~cone_perception.errors.FrameError`
with a ``reason`` key; the caller drops that frame and counts it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Callable

import cv2
import numpy as np

from .crop import CropSpec
from .errors import FrameError
from .imageheader import HeaderError, declared_size

# encoding -> (canonical name, bytes per pixel)
_ENCODINGS = {
    "yuv422_yuy2": ("yuyv", 2),
    "yuyv": ("yuyv", 2),
    "yuy2": ("yuyv", 2),
    "bgr8": ("bgr8", 3),
    "rgb8": ("rgb8", 3),
}
SUPPORTED_ENCODINGS = tuple(_ENCODINGS)

# OpenCV's own thread pool stays off: the band's conversion is short on one thread, and pool workers
# that spin after it take a core from the network's threads, which slows some forwards down
# (measured in docs/benchmarks.md, "Backend and threads").
OPENCV_THREADS = 1


def pin_opencv_threads() -> None:
    """Set OpenCV's process-wide thread count to :data:`OPENCV_THREADS` (the adapter and the
    detector's input preparation call it)."""
    cv2.setNumThreads(OPENCV_THREADS)


def raw_frame_view(encoding: str, width: int, height: int, step: int, data) -> tuple[str, np.ndarray]:
    """Validate a raw image message and view its buffer as ``(height, step)`` uint8.

    Returns the canonical encoding name and the view (no copy).
    Raises :class:`FrameError` for unknown encodings, zero sizes, odd YUYV
    widths, a too small ``step`` and a too short ``data``.
    """
    enc = _ENCODINGS.get(str(encoding).lower())
    if enc is None:
        raise FrameError("unknown_encoding", f"unsupported encoding {encoding!r}; supported: {', '.join(SUPPORTED_ENCODINGS)}")
    name, bpp = enc
    if width <= 0 or height <= 0:
        raise FrameError("zero_size", f"image has zero size ({width}x{height})")
    if name == "yuyv" and width % 2:
        raise FrameError("odd_width", f"YUYV image width must be even, got {width}")
    if step < width * bpp:
        raise FrameError("step_too_small", f"step {step} < width {width} * {bpp} bytes per pixel for {encoding}")
    buf = np.frombuffer(data, dtype=np.uint8)
    if buf.size < step * height:
        raise FrameError("data_too_short", f"data has {buf.size} bytes, step*height needs {step * height}")
    return name, buf[: step * height].reshape(height, step)


def _downscale(bgr: np.ndarray, crop: CropSpec) -> np.ndarray:
    if crop.downscale == 1:
        return np.ascontiguousarray(bgr)
    return cv2.resize(bgr, (crop.out_width, crop.out_height), interpolation=cv2.INTER_AREA)


def crop_raw_to_bgr(name: str, view: np.ndarray, crop: CropSpec) -> np.ndarray:
    """Cut the band out of a validated raw buffer view, convert to BGR, downscale."""
    h, w = crop.height_full_px, crop.width_full_px
    if name == "yuyv":
        band = view[crop.v0 : crop.v1, 2 * crop.u0 : 2 * crop.u1].reshape(h, w, 2)
        bgr = cv2.cvtColor(band, cv2.COLOR_YUV2BGR_YUY2)
        return _downscale(bgr, crop)
    band = view[crop.v0 : crop.v1, 3 * crop.u0 : 3 * crop.u1].reshape(h, w, 3)
    if name == "rgb8":
        band = cv2.cvtColor(band, cv2.COLOR_RGB2BGR)
    return _downscale(band, crop)


def crop_bgr(bgr_full: np.ndarray, crop: CropSpec) -> np.ndarray:
    """Crop + downscale an already decoded full BGR image."""
    return _downscale(bgr_full[crop.v0 : crop.v1, crop.u0 : crop.u1], crop)


#: Limits of :func:`decode_compressed` where no calibration gives the image size (``detect``,
#: ``calibrate``): larger declared images are refused before decoding (a 40 MP BGR image is 120 MB).
MAX_DECODE_SIDE_PX = 16384
MAX_DECODE_PIXELS = 40_000_000


def decode_compressed(
    data,
    expect_wh: tuple[int, int] | None = None,
    max_side_px: int = MAX_DECODE_SIDE_PX,
    max_pixels: int = MAX_DECODE_PIXELS,
) -> np.ndarray:
    """JPEG/PNG/BMP/PNM/WebP bytes -> full BGR image ``(H, W, 3) uint8``; every problem is a
    :class:`FrameError`.

    The declared size is read from the header first (:func:`~cone_perception.imageheader.declared_size`,
    no decoding) and the frame refused before the decoder runs when it is not ``expect_wh`` (W, H px:
    the calibration's image; EXIF orientation is then ignored, as a camera's frames are in sensor
    orientation) or, without ``expect_wh``, when a side exceeds ``max_side_px`` or the area
    ``max_pixels``. A decoder error (``cv2.error`` or any other) is a dropped frame with its cause,
    and so is a decoded image whose size is not the declared one.
    The one decoding path of the nodes, ``replay``, ``detect`` and ``calibrate``.
    """
    buf = np.frombuffer(data, dtype=np.uint8)
    if buf.size == 0:
        raise FrameError("undecodable", "compressed image has no data")
    try:
        fmt, w, h = declared_size(buf)
    except HeaderError as e:
        raise FrameError(e.reason, f"compressed image ({buf.size} bytes): {e}") from None
    flags = cv2.IMREAD_COLOR
    if expect_wh is not None:
        if (w, h) != tuple(expect_wh):
            reason = "too_large" if w > expect_wh[0] or h > expect_wh[1] else "wrong_size"
            raise FrameError(reason, f"{fmt.upper()} header declares {w}x{h} px but the calibration is for "
                                     f"{expect_wh[0]}x{expect_wh[1]} (not decoded)")
        flags |= cv2.IMREAD_IGNORE_ORIENTATION
    elif max(w, h) > max_side_px or w * h > max_pixels:
        raise FrameError("too_large", f"{fmt.upper()} header declares {w}x{h} px, more than the limit of "
                                      f"{max_side_px} px a side and {max_pixels / 1e6:g} MP (not decoded)")
    try:
        img = cv2.imdecode(buf, flags)
    except Exception as e:  # noqa: BLE001 - cv2.error and whatever else a decoder raises: drop the frame
        raise FrameError("decoder_error", f"{fmt.upper()} ({buf.size} bytes) failed to decode: "
                                          f"{type(e).__name__}: {str(e).strip()[:200]}") from None
    if img is None:
        raise FrameError("undecodable", f"compressed image ({buf.size} bytes) could not be decoded as {fmt.upper()}")
    if img.ndim != 3 or (img.shape[1], img.shape[0]) not in ((w, h), (h, w)):  # (h, w): EXIF rotation
        raise FrameError("wrong_size", f"{fmt.upper()} decoded to {img.shape} but its header declares {w}x{h}")
    return img


@dataclass
class DriverAdapter:
    """Turns camera frames into the cropped BGR band of one calibrated camera.

    ``image_width``/``image_height`` are the full image size the calibration was
    made for; frames of another size are rejected (the homography would not apply).
    """

    crop: CropSpec
    image_width: int
    image_height: int
    far: CropSpec | None = None  # the far band's full-resolution rows (detector/farband.py), or None

    def __post_init__(self) -> None:
        self.crop.validate(self.image_width, self.image_height)
        if self.far is not None:
            self.far.validate(self.image_width, self.image_height, "far band")
        pin_opencv_threads()

    def _check_size(self, width: int, height: int) -> None:
        if (width, height) != (self.image_width, self.image_height):
            raise FrameError(
                "wrong_size",
                f"image is {width}x{height} but the calibration is for {self.image_width}x{self.image_height}",
            )

    def _raw_view(self, encoding: str, width: int, height: int, step: int, data) -> tuple[str, np.ndarray]:
        name, view = raw_frame_view(encoding, width, height, step, data)
        self._check_size(width, height)
        return name, view

    def from_raw(self, encoding: str, width: int, height: int, step: int, data) -> np.ndarray:
        """sensor_msgs/Image fields -> cropped BGR ``(out_h, out_w, 3) uint8`` (the band only)."""
        return crop_raw_to_bgr(*self._raw_view(encoding, width, height, step, data), self.crop)

    def from_compressed(self, data) -> np.ndarray:
        """sensor_msgs/CompressedImage data (JPEG/PNG/...) -> cropped BGR; a header declaring another
        size than the calibration's is refused before decoding."""
        return self.cutters_compressed(data)[0]()

    def cutters_raw(self, encoding: str, width: int, height: int, step: int, data, far: CropSpec | None = None
                    ) -> tuple[Callable[[], np.ndarray], Callable[[], np.ndarray] | None]:
        """sensor_msgs/Image fields -> (the band as :meth:`from_raw`, the far band's full-resolution strip
        ``(V1 - V0, W, 3)`` BGR or None without one), each as a callable: the frame is validated now (once; a
        :class:`FrameError` here), the band and the strip are cut and converted when called, each on the thread that
        runs its detector (the pipeline: the strip's on the far strip's worker, at the same time as the band's).
        ``far``: this frame's strip rows (the strip moved with the attitude, inside the image), else :attr:`far`'s."""
        name, view = self._raw_view(encoding, width, height, step, data)
        far = far or self.far
        strip = partial(crop_raw_to_bgr, name, view, far) if far is not None else None
        return partial(crop_raw_to_bgr, name, view, self.crop), strip

    def cutters_compressed(self, data, far: CropSpec | None = None
                           ) -> tuple[Callable[[], np.ndarray], Callable[[], np.ndarray] | None]:
        """As :meth:`cutters_raw` for a compressed image: decoded now (once), band and strip cut when called."""
        img = decode_compressed(data, expect_wh=(self.image_width, self.image_height))
        far = far or self.far
        return partial(crop_bgr, img, self.crop), (partial(crop_bgr, img, far) if far is not None else None)

    def camera_info_fields(self) -> dict:
        """Fields of the ``image_cropped/camera_info`` that goes with each output."""
        return self.crop.camera_info_fields(self.image_width, self.image_height)


# rows Y, U, V; columns B, G, R, offset
_BGR_TO_YUV601_LIMITED = np.array(
    [[0.098, 0.504, 0.257, 16.0], [0.439, -0.291, -0.148, 128.0], [-0.071, -0.368, 0.439, 128.0]], dtype=np.float64
)


def bgr_to_yuyv(bgr: np.ndarray) -> np.ndarray:
    """Full BGR image -> YUYV bytes as ``(H, W, 2) uint8`` (BT.601, as cameras send).

    Used to make YUYV test frames and benchmark input; chroma of each pixel pair
    is averaged. Width must be even.
    """
    h, w = bgr.shape[:2]
    if w % 2:
        raise ValueError(f"YUYV needs an even width, got {w}")
    # BT.601 limited ("video") range, the inverse of OpenCV's COLOR_YUV2BGR_YUY2 used by crop_raw_to_bgr
    yuv = cv2.transform(bgr, _BGR_TO_YUV601_LIMITED).astype(np.uint16)
    out = np.empty((h, w, 2), dtype=np.uint8)
    out[:, :, 0] = yuv[:, :, 0]
    u = ((yuv[:, 0::2, 1] + yuv[:, 1::2, 1] + 1) // 2).astype(np.uint8)
    v = ((yuv[:, 0::2, 2] + yuv[:, 1::2, 2] + 1) // 2).astype(np.uint8)
    out[:, 0::2, 1] = u
    out[:, 1::2, 1] = v
    return out
