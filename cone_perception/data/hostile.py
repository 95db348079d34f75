"""Crafted hostile inputs for the tests and ``cone-perception fuzz`` (ROS-free, bytes only).

The decompression bombs of issue 20: a 69-byte PNG declaring 100000x100000 px (``cv2.imdecode``
raises ``cv2.error``) and a JPEG of a few hundred bytes declaring 16000x16000 px (decoded in full:
seconds and > 1 GB).
"""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np


def png_chunk(kind: bytes, payload: bytes) -> bytes:
    return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload))


def png_bomb(width: int = 100_000, height: int = 100_000) -> bytes:
    """A tiny PNG whose IHDR declares ``width`` x ``height`` 8-bit RGB px (69 bytes)."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + png_chunk(b"IDAT", zlib.compress(b"")) + png_chunk(b"IEND", b"")


def jpeg_with_size(width: int, height: int, src_px: int = 16) -> bytes:
    """A valid small JPEG whose frame header is patched to declare ``width`` x ``height`` px."""
    ok, buf = cv2.imencode(".jpg", np.full((src_px, src_px, 3), 128, np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 50])
    data = bytearray(buf.tobytes())
    i = 2
    while True:  # walk the segments to the SOF0 marker
        marker, length = data[i + 1], (data[i + 2] << 8) | data[i + 3]
        if marker == 0xC0:
            data[i + 5 : i + 9] = struct.pack(">HH", height, width)
            return bytes(data)
        i += 2 + length


def jpeg_bomb() -> bytes:
    """A JPEG of a few hundred bytes declaring 16000x16000 px (OpenCV decodes it in full)."""
    return jpeg_with_size(16_000, 16_000)


def bmp_bomb(width: int = 100_000, height: int = 100_000) -> bytes:
    """A 54-byte BMP header declaring ``width`` x ``height`` 24-bit px, no pixel data."""
    return b"BM" + struct.pack("<IHHI", 54, 0, 0, 54) + struct.pack("<IiiHHIIiiII", 40, width, height, 1, 24, 0, 0, 0, 0, 0, 0)


def pnm_bomb(width: int = 100_000, height: int = 100_000) -> bytes:
    """A binary PPM header declaring ``width`` x ``height`` px and a few bytes of data."""
    return f"P6\n# bomb\n{width} {height}\n255\n".encode() + b"\0" * 16


BOMBS = {"png_100000": png_bomb, "jpeg_16000": jpeg_bomb, "bmp_100000": bmp_bomb, "pnm_100000": pnm_bomb}
