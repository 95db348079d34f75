"""Decoding that cannot be weaponised: sizes read from the header, bombs refused before decoding."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from cone_perception import adapter
from cone_perception.adapter import DriverAdapter, decode_compressed
from cone_perception.crop import CropSpec
from cone_perception.data.hostile import BOMBS, bmp_bomb, jpeg_bomb, jpeg_with_size, png_bomb, pnm_bomb
from cone_perception.errors import FrameError
from cone_perception.imageheader import HeaderError, declared_size

W, H = 640, 480


def _img(w: int = W, h: int = H) -> np.ndarray:
    return np.random.default_rng(0).integers(0, 255, (h, w, 3), dtype=np.uint8)


@pytest.mark.parametrize("ext", [".jpg", ".png", ".bmp", ".ppm", ".pgm", ".pbm", ".pam", ".webp"])
@pytest.mark.parametrize("size", [(640, 480), (37, 1001), (1, 1)])
def test_declared_size_is_what_opencv_decodes(ext: str, size: tuple[int, int]) -> None:
    img = _img(*size)
    if ext in (".pgm", ".pbm"):
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    ok, buf = cv2.imencode(ext, img)
    assert ok
    fmt, w, h = declared_size(buf.tobytes())
    dec = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    assert (w, h) == size == (dec.shape[1], dec.shape[0]), fmt


def test_progressive_jpeg_and_app_segments() -> None:
    ok, buf = cv2.imencode(".jpg", _img(), [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])
    data = buf.tobytes()
    app = b"\xff\xe1" + (2 + 1000).to_bytes(2, "big") + b"x" * 1000  # an EXIF-sized APP1 before the frame
    assert declared_size(data[:2] + app + data[2:])[1:] == (W, H)


@pytest.mark.parametrize("make, size", [(png_bomb, (100_000, 100_000)), (jpeg_bomb, (16_000, 16_000)),
                                        (bmp_bomb, (100_000, 100_000)), (pnm_bomb, (100_000, 100_000))])
def test_bomb_headers_are_read(make, size) -> None:
    assert declared_size(make())[1:] == size


def test_the_bombs_are_as_small_as_in_the_issue() -> None:
    assert len(png_bomb()) <= 69 and len(jpeg_bomb()) < 1000


@pytest.mark.parametrize("data, reason", [
    (b"GIF89a\x01\x00\x01\x00", "unsupported_format"),
    (b"II*\x00\x08\x00\x00\x00", "unsupported_format"),  # TIFF: size not checkable cheaply
    (b"\x89PNG\r\n\x1a\n\x00\x00", "truncated"),
    (b"\x89PNG\r\n\x1a\n" + b"\0\0\0\x0dIHDX" + b"\0" * 12, "bad_header"),
    (b"\xff\xd8\xff\xe0 not really a jpeg", "bad_header"),
    (b"\xff\xd8\xff\xda\x00\x02", "bad_header"),  # scan before frame header
    (b"\xff\xd8\xff", "truncated"),
    (b"\xff\xd8\xff\xe0\x00\x01", "bad_header"),  # segment length < 2 would loop
    (b"P6\n# only a comment", "bad_header"),
    (b"P6 0 10 255\n", "zero_size"),
    (b"P7\nWIDTH 3\nENDHDR\n", "bad_header"),
    (b"BM" + b"\0" * 20, "bad_header"),
    (b"RIFF\0\0\0\0WEBPVP8 " + b"\0" * 20, "bad_header"),
])
def test_malformed_headers_raise_with_reason(data: bytes, reason: str) -> None:
    with pytest.raises(HeaderError) as e:
        declared_size(data)
    assert e.value.reason == reason


def test_jpeg_zero_height_is_refused() -> None:
    with pytest.raises(HeaderError) as e:
        declared_size(jpeg_with_size(640, 0))
    assert e.value.reason == "zero_size"


@pytest.fixture
def no_decoder(monkeypatch):
    """cv2.imdecode fails the test if called: a refused frame must never reach the decoder."""
    def boom(*a, **k):
        raise AssertionError("the decoder ran on a frame that should have been refused from its header")
    monkeypatch.setattr(adapter.cv2, "imdecode", boom)


@pytest.mark.parametrize("name", sorted(BOMBS))
def test_bombs_are_refused_before_decoding(name: str, no_decoder) -> None:
    with pytest.raises(FrameError) as e:
        decode_compressed(BOMBS[name]())
    assert e.value.reason == "too_large" and "not decoded" in str(e.value)


@pytest.mark.parametrize("name", sorted(BOMBS))
def test_adapter_refuses_a_size_other_than_the_calibration_before_decoding(name: str, no_decoder) -> None:
    a = DriverAdapter(CropSpec(0, H, 0, W, 1), W, H)
    with pytest.raises(FrameError) as e:
        a.from_compressed(BOMBS[name]())
    assert e.value.reason == "too_large"
    ok, small = cv2.imencode(".jpg", _img(320, 240))
    with pytest.raises(FrameError) as e:
        a.from_compressed(small.tobytes())
    assert e.value.reason == "wrong_size"


def test_a_configured_maximum_is_honoured(no_decoder) -> None:
    ok, buf = cv2.imencode(".png", _img())
    with pytest.raises(FrameError, match="640x480"):
        decode_compressed(buf.tobytes(), max_pixels=W * H - 1)
    with pytest.raises(FrameError):
        decode_compressed(buf.tobytes(), max_side_px=W - 1)


def test_every_decoder_error_is_a_dropped_frame(monkeypatch) -> None:
    def raises(*a, **k):
        raise cv2.error("OpenCV(4.x) imgcodecs: the decoder gave up")
    monkeypatch.setattr(adapter.cv2, "imdecode", raises)
    ok, buf = cv2.imencode(".png", _img())
    with pytest.raises(FrameError) as e:
        decode_compressed(buf.tobytes())
    assert e.value.reason == "decoder_error" and "error" in str(e.value)


def test_a_decoded_size_other_than_the_declared_is_refused(monkeypatch) -> None:
    monkeypatch.setattr(adapter.cv2, "imdecode", lambda buf, flags: np.zeros((10, 10, 3), np.uint8))
    ok, buf = cv2.imencode(".png", _img())
    with pytest.raises(FrameError) as e:
        decode_compressed(buf.tobytes())
    assert e.value.reason == "wrong_size"


def test_valid_images_still_decode_exactly() -> None:
    img = _img()
    for ext in (".png", ".bmp", ".ppm"):
        ok, buf = cv2.imencode(ext, img)
        np.testing.assert_array_equal(decode_compressed(buf.tobytes()), img)
        np.testing.assert_array_equal(decode_compressed(bytearray(buf.tobytes()), expect_wh=(W, H)), img)


def test_detect_on_a_folder_with_a_bomb_processes_the_good_images(tmp_path: Path, capsys) -> None:
    from cone_perception.data.sources import iter_source

    (tmp_path / "a_bomb.png").write_bytes(png_bomb())
    (tmp_path / "b_bomb.jpg").write_bytes(jpeg_bomb())
    for i in range(2):
        cv2.imwrite(str(tmp_path / f"good{i}.jpg"), _img())
    out = {name: (img, err) for name, img, err in iter_source(tmp_path)}
    assert out["good0.jpg"][0].shape == (H, W, 3) and out["good1.jpg"][0].shape == (H, W, 3)
    assert out["a_bomb.png"][0] is None and "100000x100000" in out["a_bomb.png"][1]
    assert out["b_bomb.jpg"][0] is None and "16000x16000" in out["b_bomb.jpg"][1]
