"""The declared size of a compressed image, read from its header without decoding it (ROS-free).

A 69-byte PNG can declare 100000x100000 px and a 629-byte JPEG 16000x16000: decoding either costs
seconds and gigabytes (or a ``cv2.error``). :func:`declared_size` reads the width and height the
file declares from the first bytes of its header (no pixel is decoded, no allocation follows the
declared size), so :func:`cone_perception.adapter.decode_compressed` can refuse a frame before the
decoder sees it.

Formats read: JPEG (baseline, progressive, lossless: the first SOFn marker, as libjpeg uses), PNG
(IHDR), BMP (core and info headers), PNM/PAM (P1-P7), WebP (VP8, VP8L, VP8X). Everything else
OpenCV might decode (TIFF, JPEG 2000, OpenEXR, Radiance HDR, Sun raster, PFM, ...) is refused:
its size cannot be checked cheaply, and no camera driver sends it.
"""

from __future__ import annotations

import struct

FORMATS = ("jpeg", "png", "bmp", "pnm", "webp")

#: PNM/PAM headers are text; a header longer than this is refused (real ones are < 100 bytes).
PNM_HEADER_MAX_BYTES = 1024

# JPEG start-of-frame markers (C4 DHT, C8 JPG and CC DAC are not frames)
_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
# markers without a length field: TEM, RST0-7, SOI
_STANDALONE = {0x01, 0xD0, 0xD1, 0xD2, 0xD3, 0xD4, 0xD5, 0xD6, 0xD7, 0xD8}


class HeaderError(ValueError):
    """The header is not one of :data:`FORMATS` or is malformed; ``reason`` is a short stable key."""

    def __init__(self, reason: str, message: str):
        self.reason = reason
        super().__init__(message)


def sniff_format(head: bytes) -> str | None:
    """The format of a compressed image from its first bytes (one of :data:`FORMATS`), or ``None``."""
    if head[:3] == b"\xff\xd8\xff":
        return "jpeg"
    if head[:8] == b"\x89PNG\r\n\x1a\n":
        return "png"
    if head[:2] == b"BM":
        return "bmp"
    if len(head) >= 2 and head[0] == ord("P") and head[1] in b"1234567":
        return "pnm"
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        return "webp"
    return None


def declared_size(data) -> tuple[str, int, int]:
    """``(format, width, height)`` in px as declared by the header of ``data`` (bytes-like).

    Reads only the header (O(number of JPEG segments before the frame header), no decoding).
    Raises :class:`HeaderError` for an unknown format, a truncated or malformed header, or a zero size.
    """
    mv = memoryview(data)
    if mv.format != "B" or mv.ndim != 1:
        mv = mv.cast("B")
    head = bytes(mv[:32])
    fmt = sniff_format(head)
    if fmt is None:
        raise HeaderError(
            "unsupported_format",
            f"not a {'/'.join(f.upper() for f in FORMATS)} image (first bytes {head[:8].hex()})",
        )
    w, h = _READERS[fmt](mv)
    if w <= 0 or h <= 0:
        raise HeaderError("zero_size", f"{fmt.upper()} header declares {w}x{h} px")
    return fmt, w, h


def _need(mv: memoryview, end: int, fmt: str) -> None:
    if len(mv) < end:
        raise HeaderError("truncated", f"{fmt.upper()} header truncated ({len(mv)} bytes)")


def _png(mv: memoryview) -> tuple[int, int]:
    _need(mv, 24, "png")
    if bytes(mv[12:16]) != b"IHDR":
        raise HeaderError("bad_header", "PNG does not start with an IHDR chunk")
    return struct.unpack(">II", mv[16:24])


def _jpeg(mv: memoryview) -> tuple[int, int]:
    i, n = 2, len(mv)
    while True:
        # a marker: one or more 0xFF fill bytes, then the marker code
        if i >= n or mv[i] != 0xFF:
            raise HeaderError("bad_header", f"JPEG: no marker at byte {i} before the frame header")
        while i < n and mv[i] == 0xFF:
            i += 1
        _need(mv, i + 1, "jpeg")
        marker = mv[i]
        i += 1
        if marker in _STANDALONE:
            continue
        if marker in (0xD9, 0xDA):  # EOI or SOS before any frame header
            raise HeaderError("bad_header", "JPEG: no frame header (SOFn) before the scan data")
        _need(mv, i + 2, "jpeg")
        length = (mv[i] << 8) | mv[i + 1]
        if length < 2:
            raise HeaderError("bad_header", f"JPEG: segment length {length} at byte {i}")
        if marker in _SOF:
            _need(mv, i + 7, "jpeg")
            h = (mv[i + 3] << 8) | mv[i + 4]
            w = (mv[i + 5] << 8) | mv[i + 6]
            return w, h  # height 0 (defined later by a DNL marker) is refused as zero_size
        i += length


def _bmp(mv: memoryview) -> tuple[int, int]:
    _need(mv, 18, "bmp")
    (dib,) = struct.unpack("<I", mv[14:18])
    if dib == 12:  # OS/2 BITMAPCOREHEADER: unsigned 16-bit sizes
        _need(mv, 22, "bmp")
        return struct.unpack("<HH", mv[18:22])
    if dib < 40:
        raise HeaderError("bad_header", f"BMP: unknown info header size {dib}")
    _need(mv, 26, "bmp")
    w, h = struct.unpack("<ii", mv[18:26])
    return w, abs(h)  # a negative height is a top-down bitmap


def _pnm(mv: memoryview) -> tuple[int, int]:
    head = bytes(mv[:PNM_HEADER_MAX_BYTES])
    if head[1:2] == b"7":  # PAM: "WIDTH n" / "HEIGHT n" lines up to ENDHDR
        if b"ENDHDR" not in head:
            raise HeaderError("bad_header", f"PAM header has no ENDHDR in its first {PNM_HEADER_MAX_BYTES} bytes")
        fields = {}
        for line in head.split(b"ENDHDR", 1)[0].splitlines()[1:]:
            parts = line.split(b"#", 1)[0].split()
            if len(parts) >= 2:
                fields[parts[0].upper()] = parts[1]
        try:
            return int(fields[b"WIDTH"]), int(fields[b"HEIGHT"])
        except (KeyError, ValueError):
            raise HeaderError("bad_header", "PAM header lacks a numeric WIDTH or HEIGHT") from None
    tokens, i = [], 2
    while len(tokens) < 2:  # whitespace-separated decimal width and height, '#' comments to end of line
        while i < len(head) and head[i : i + 1].isspace():
            i += 1
        if i < len(head) and head[i : i + 1] == b"#":
            eol = head.find(b"\n", i)
            if eol < 0:
                break
            i = eol + 1
            continue
        j = i
        while j < len(head) and head[j : j + 1].isdigit():
            j += 1
        if j == i or j >= len(head):
            break
        tokens.append(int(head[i:j]))
        i = j
    if len(tokens) < 2:
        raise HeaderError("bad_header", f"PNM header has no width and height in its first {PNM_HEADER_MAX_BYTES} bytes")
    return tokens[0], tokens[1]


def _webp(mv: memoryview) -> tuple[int, int]:
    _need(mv, 30, "webp")
    chunk = bytes(mv[12:16])
    if chunk == b"VP8 ":  # lossy: 3-byte frame tag, start code 9d 01 2a, then 14-bit sizes
        if bytes(mv[23:26]) != b"\x9d\x01\x2a":
            raise HeaderError("bad_header", "WebP VP8: bad start code")
        w, h = struct.unpack("<HH", mv[26:30])
        return w & 0x3FFF, h & 0x3FFF
    if chunk == b"VP8L":  # lossless: signature 0x2f, then 14-bit width-1 and height-1
        if mv[20] != 0x2F:
            raise HeaderError("bad_header", "WebP VP8L: bad signature")
        (bits,) = struct.unpack("<I", mv[21:25])
        return (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
    if chunk == b"VP8X":  # extended: 24-bit canvas width-1 and height-1
        b = bytes(mv[24:30])
        return int.from_bytes(b[0:3], "little") + 1, int.from_bytes(b[3:6], "little") + 1
    raise HeaderError("bad_header", f"WebP: unknown first chunk {chunk!r}")


_READERS = {"jpeg": _jpeg, "png": _png, "bmp": _bmp, "pnm": _pnm, "webp": _webp}
