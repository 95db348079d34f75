"""bgr_to_yuyv is the inverse of the adapter's YUYV decoding (BT.601 limited range)."""

import numpy as np

from cone_perception.adapter import bgr_to_yuyv, crop_raw_to_bgr
from cone_perception.crop import CropSpec


def test_yuyv_encode_decode_round_trip():
    rng = np.random.default_rng(0)
    img = np.repeat(rng.integers(0, 256, (64, 128, 3), dtype=np.uint8), 2, axis=1)  # chroma constant per pixel pair
    yuyv = bgr_to_yuyv(img)
    assert yuyv.shape == (64, 256, 2)
    back = crop_raw_to_bgr("yuyv", yuyv.reshape(64, 512), CropSpec.full_image(256, 64))
    err = np.abs(back.astype(int) - img.astype(int))
    assert err.max() <= 3 and err.mean() < 1.0
    # video range: black -> Y 16, white -> Y 235, grey has neutral chroma 128
    y = bgr_to_yuyv(np.array([[[0, 0, 0], [255, 255, 255]]], dtype=np.uint8))
    assert y[0, 0, 0] == 16 and y[0, 1, 0] == 235 and y[0, 0, 1] == 128 and y[0, 1, 1] == 128
