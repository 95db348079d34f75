"""Driver adapter: pixel-exact against a reference conversion; per-frame errors; camera_info round trip."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cone_perception.adapter import DriverAdapter, bgr_to_yuyv, raw_frame_view
from cone_perception.crop import CropSpec
from cone_perception.errors import ConfigError, FrameError

W, H = 320, 240
CROPS = [
    CropSpec(0, H, 0, W, 1),
    CropSpec(64, 192, 0, W, 2),
    CropSpec(40, 200, 32, 288, 4),
    CropSpec(16, 208, 10, 250, 2),
]


def _frame(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (H, W, 3), dtype=np.uint8)


def _reference(bgr_full: np.ndarray, crop: CropSpec) -> np.ndarray:
    """Convert the WHOLE image, then crop, then area-downscale: the slow, obvious way."""
    band = bgr_full[crop.v0 : crop.v1, crop.u0 : crop.u1]
    if crop.downscale == 1:
        return band
    return cv2.resize(band, (crop.out_width, crop.out_height), interpolation=cv2.INTER_AREA)


@pytest.mark.parametrize("crop", CROPS, ids=lambda c: f"{c.v0}-{c.v1}x{c.u0}-{c.u1}/{c.downscale}")
@pytest.mark.parametrize("encoding", ["yuv422_yuy2", "yuyv", "bgr8", "rgb8"])
def test_raw_equals_reference(encoding: str, crop: CropSpec) -> None:
    adapter = DriverAdapter(crop, W, H)
    for seed in range(3):
        bgr = _frame(seed)
        if encoding in ("yuv422_yuy2", "yuyv"):
            raw = bgr_to_yuyv(bgr)
            full = cv2.cvtColor(raw, cv2.COLOR_YUV2BGR_YUY2)
            step = W * 2
        elif encoding == "rgb8":
            raw, full, step = bgr[:, :, ::-1].copy(), bgr, W * 3
        else:
            raw, full, step = bgr, bgr, W * 3
        out = adapter.from_raw(encoding, W, H, step, raw.tobytes())
        assert out.shape == (crop.out_height, crop.out_width, 3)
        assert out.dtype == np.uint8 and out.flags.c_contiguous
        np.testing.assert_array_equal(out, _reference(full, crop))


def test_padded_step_is_honoured() -> None:
    """Rows padded to a larger step (drivers align rows) convert like tight rows."""
    bgr = _frame(7)
    raw = bgr_to_yuyv(bgr)
    pad = 64
    padded = np.zeros((H, W * 2 + pad), dtype=np.uint8)
    padded[:, : W * 2] = raw.reshape(H, -1)
    padded[:, W * 2 :] = 255  # garbage in the padding must not leak into the image
    crop = CropSpec(64, 192, 0, W, 2)
    a = DriverAdapter(crop, W, H)
    np.testing.assert_array_equal(
        a.from_raw("yuv422_yuy2", W, H, W * 2 + pad, padded.tobytes()),
        a.from_raw("yuv422_yuy2", W, H, W * 2, raw.tobytes()),
    )


@pytest.mark.parametrize("ext", [".png", ".jpg"])
def test_compressed_equals_decode_then_crop(ext: str) -> None:
    bgr = cv2.GaussianBlur(_frame(3), (7, 7), 2)
    ok, buf = cv2.imencode(ext, bgr)
    assert ok
    crop = CropSpec(64, 192, 0, W, 2)
    out = DriverAdapter(crop, W, H).from_compressed(buf.tobytes())
    np.testing.assert_array_equal(out, _reference(cv2.imdecode(buf, cv2.IMREAD_COLOR), crop))
    if ext == ".png":  # lossless: must equal the original
        np.testing.assert_array_equal(out, _reference(bgr, crop))


@pytest.mark.parametrize(
    "encoding,width,height,step,nbytes,reason",
    [
        ("mono16", W, H, W * 2, W * H * 2, "unknown_encoding"),
        ("yuv422_yuy2", W - 1, H, W * 2, W * H * 2, "odd_width"),
        ("yuv422_yuy2", W, H, W * 2, W * H * 2 - 1, "data_too_short"),
        ("bgr8", W, H, W * 3 - 1, W * H * 3, "step_too_small"),
        ("bgr8", 0, H, 0, 0, "zero_size"),
        ("bgr8", W, 0, W * 3, 0, "zero_size"),
        ("bgr8", W // 2, H, W * 3 // 2, W * H * 3, "wrong_size"),
    ],
)
def test_bad_raw_frames_raise_frame_error(encoding, width, height, step, nbytes, reason) -> None:
    a = DriverAdapter(CropSpec(0, H, 0, W, 1), W, H)
    with pytest.raises(FrameError) as e:
        a.from_raw(encoding, width, height, step, bytes(nbytes))
    assert e.value.reason == reason


def test_undecodable_compressed_raises() -> None:
    a = DriverAdapter(CropSpec(0, H, 0, W, 1), W, H)
    for data, reason in ((b"", "undecodable"), (b"\xff\xd8\xff\xe0 not really a jpeg", "bad_header")):
        with pytest.raises(FrameError) as e:
            a.from_compressed(data)
        assert e.value.reason == reason


def test_raw_view_is_not_a_copy() -> None:
    data = bytearray(W * H * 2)
    _, view = raw_frame_view("yuyv", W, H, W * 2, data)
    data[5] = 77
    assert view[0, 5] == 77


@pytest.mark.parametrize("crop", CROPS)
def test_camera_info_roundtrip_to_full_image(crop: CropSpec) -> None:
    f = crop.camera_info_fields(W, H)
    back = CropSpec.from_camera_info(
        width=f["width"],
        height=f["height"],
        roi_x=f["roi"]["x_offset"],
        roi_y=f["roi"]["y_offset"],
        roi_w=f["roi"]["width"],
        roi_h=f["roi"]["height"],
        binning_x=f["binning_x"],
        binning_y=f["binning_y"],
    )
    assert back == crop
    # a pixel of the cropped image goes back to where it was cut from
    uv_c = np.array([[0.0, 0.0], [crop.out_width, crop.out_height], [3.5, 2.25]])
    uv_f = back.to_full(uv_c)
    np.testing.assert_allclose(uv_f[0], [crop.u0, crop.v0])
    np.testing.assert_allclose(uv_f[1], [crop.u1, crop.v1])
    np.testing.assert_allclose(back.to_cropped(uv_f), uv_c)
    boxes = back.boxes_to_full(np.array([[1, 2, 3, 4]], dtype=np.float32))
    d = crop.downscale
    np.testing.assert_allclose(boxes[0], [crop.u0 + d, crop.v0 + 2 * d, crop.u0 + 3 * d, crop.v0 + 4 * d])


def test_camera_info_zero_roi_means_full_image() -> None:
    c = CropSpec.from_camera_info(width=W, height=H, roi_x=0, roi_y=0, roi_w=0, roi_h=0, binning_x=0, binning_y=0)
    assert c == CropSpec(0, H, 0, W, 1)


@pytest.mark.parametrize(
    "crop,field",
    [
        (CropSpec(0, H + 2, 0, W, 1), "crop.v0/v1"),
        (CropSpec(100, 50, 0, W, 1), "crop.v0/v1"),
        (CropSpec(0, H, 0, W + 2, 1), "crop.u0/u1"),
        (CropSpec(0, H, 1, W, 1), "crop.u0/u1"),
        (CropSpec(0, H, 0, W, 3), "downscale"),
        (CropSpec(0, 242 - 4, 0, W, 4), "crop"),
    ],
)
def test_bad_crop_is_a_config_error(crop: CropSpec, field: str) -> None:
    with pytest.raises(ConfigError) as e:
        DriverAdapter(crop, W, H)
    assert e.value.field == field


def test_adapter_switches_opencv_thread_pool_off() -> None:
    """The adapter's conversion runs on the calling thread: a spinning OpenCV pool took a core from
    the network's threads and doubled the forward of 1-2 % of frames on two cores."""
    from cone_perception.adapter import OPENCV_THREADS
    from cone_perception.detector import Detector, default_model_path

    before = cv2.getNumThreads()
    try:
        cv2.setNumThreads(4)
        DriverAdapter(CropSpec(0, 64, 0, 64, 1), 64, 64)
        assert cv2.getNumThreads() == OPENCV_THREADS == 1
        cv2.setNumThreads(4)  # the detector's input preparation (blobFromImage) runs in its own node
        Detector.load(default_model_path())
        assert cv2.getNumThreads() == 1
    finally:
        cv2.setNumThreads(before)
