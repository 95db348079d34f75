"""Runtime-table inputs (``bench pipeline --input``, ``bench table``): which crop each setting gives,
that whole frames (1080 rows, not a multiple of 32) run through the pipeline and give full-image
boxes, and that the table applies each setting's crop / downscale to the validation frames."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace

import cv2
import numpy as np
import pytest

from cone_perception.adapter import bgr_to_yuyv
from cone_perception.bench.table import INPUT_SETTINGS, crop_for_setting
from cone_perception.crop import CropSpec
from cone_perception.detector import Detector
from cone_perception.errors import ConfigError
from cone_perception.geometry.calib import load_calibration
from cone_perception.pipeline import Pipeline

# the stub network's one box, in NETWORK-INPUT px: x1 100, y1 100, x2 140, y2 160
STUB_BOX = (100.0, 100.0, 140.0, 160.0)


class StubNet:
    """Stands in for the network: records the input shapes, returns one blue cone box at STUB_BOX."""

    def __init__(self) -> None:
        self.shapes: list[tuple[int, ...]] = []

    def __call__(self, blob: np.ndarray) -> np.ndarray:
        self.shapes.append(tuple(blob.shape))
        out = np.zeros((4 + 5, 8), np.float32)
        x1, y1, x2, y2 = STUB_BOX
        out[:4, 0] = ((x1 + x2) / 2, (y1 + y2) / 2, x2 - x1, y2 - y1)
        out[4 + 0, 0] = 0.9  # class 0 (blue)
        return out


def stub_detector(source: str = "stub.pt") -> tuple[Detector, StubNet]:
    net = StubNet()
    return Detector(net, list(range(5)), (960, 288), False, "torch", source), net


def test_each_setting_gives_its_crop() -> None:
    band = CropSpec(384, 960, 0, 1920, 2)
    got = {s: crop_for_setting(band, s, 1920, 1080) for s in INPUT_SETTINGS}
    assert got["full"] == CropSpec(0, 1080, 0, 1920, 1)
    assert got["half"] == CropSpec(0, 1080, 0, 1920, 2)
    assert got["crop"] == CropSpec(384, 960, 0, 1920, 1)
    assert got["crop_half"] == CropSpec(384, 960, 0, 1920, 2)
    assert [(c.out_width, c.out_height) for c in got.values()] == [(1920, 1080), (960, 540), (1920, 576), (960, 288)]
    # the band's columns are kept too
    assert crop_for_setting(CropSpec(96, 672, 64, 1856), "crop_half", 1920, 1080) == CropSpec(96, 672, 64, 1856, 2)
    with pytest.raises(ConfigError, match="unknown input setting"):
        crop_for_setting(band, "quarter", 1920, 1080)


@pytest.mark.parametrize("setting,net_input,scale,v_off", [
    ("full", (1088, 1920), 1, 0),     # 1080 rows padded to 1088
    ("half", (544, 960), 2, 0),       # 540 rows padded to 544
    ("crop", (576, 1920), 1, 384),
    ("crop_half", (288, 960), 2, 384),
])
def test_whole_frame_runs_through_the_pipeline(setting, net_input, scale, v_off) -> None:
    calib = load_calibration("example_mainhoop")
    calib = replace(calib, crop=crop_for_setting(calib.crop, setting, calib.image_width, calib.image_height))
    det, net = stub_detector()
    pipe = Pipeline(calib, det)
    frame = bgr_to_yuyv(np.full((1080, 1920, 3), 90, np.uint8))
    res = pipe.process_raw("yuv422_yuy2", 1920, 1080, 2 * 1920, frame.tobytes())
    assert net.shapes == [(1, 3, *net_input)]
    assert len(res.boxes) == 1
    x1, y1, x2, y2 = STUB_BOX
    want = (x1 * scale, y1 * scale + v_off, x2 * scale, y2 * scale + v_off)
    got = tuple(float(res.boxes[k][0]) for k in ("u1", "v1", "u2", "v2"))
    assert got == pytest.approx(want, abs=1e-3)
    assert res.timing_ms["forward"] >= 0


def test_bench_pipeline_reports_the_setting() -> None:
    from cone_perception.bench.frames import synthetic_frames
    from cone_perception.bench.pipeline import bench_pipeline

    calib = load_calibration("example_mainhoop")
    calib = replace(calib, crop=crop_for_setting(calib.crop, "full", 1920, 1080))
    det, net = stub_detector()
    r = bench_pipeline(calib, det, synthetic_frames(1920, 1080, "yuv422_yuy2", 2), n_frames=3, warmup=1)
    assert r["model_input"] == [1920, 1088]
    assert r["crop"] == {"v0": 0, "v1": 1080, "u0": 0, "u1": 1920, "downscale": 1}
    assert r["stages"]["end_to_end"]["n"] == 3 and len(net.shapes) == 4
    assert r["boxes_per_frame"] == 1.0


def test_table_applies_each_setting_to_the_val_frames(tmp_path, monkeypatch) -> None:
    """Ground truth = the stub's box as the FULL setting maps it: full matches it; half (box x2) and
    crop (box + 96 rows) must not. A second box centred below the band counts as outside it, a third
    one reaching across the band's bottom edge as cut."""
    from cone_perception.bench import table as _table
    from cone_perception.bench.frames import synthetic_frames

    val = tmp_path / "val"
    (val / "images").mkdir(parents=True)
    (val / "labels").mkdir()
    x1, y1, x2, y2 = STUB_BOX
    for i in range(2):
        cv2.imwrite(str(val / "images" / f"f{i}.jpg"), np.full((1080, 1920, 3), 100, np.uint8))
        (val / "labels" / f"f{i}.txt").write_text(
            f"0 {(x1 + x2) / 2 / 1920} {(y1 + y2) / 2 / 1080} {(x2 - x1) / 1920} {(y2 - y1) / 1080}\n"
            f"0 {1000 / 1920} {900 / 1080} {40 / 1920} {60 / 1080}\n"     # below the band
            f"0 {1500 / 1920} {665 / 1080} {40 / 1920} {50 / 1080}\n")    # centre inside, bottom cut at row 672

    made = []

    def fake_load(model, backend, crop, threads, **kw):
        det, net = stub_detector()
        made.append((crop, net))
        return det

    monkeypatch.setattr(_table, "load_for_crop", fake_load)
    monkeypatch.setattr(_table, "rendered_frames", lambda calib, n: synthetic_frames(1920, 1080, "yuv422_yuy2", 1))
    out = tmp_path / "out"
    args = argparse.Namespace(models=None, val=val, gt_names="blue_cone", band=(96, 672), out=out,
                              settings=",".join(INPUT_SETTINGS), det_conf=0.001, conf=0.25, frames=2, warmup=0,
                              backend="torch", bf16=False, threads=1, scenes=1)
    assert _table.run_table(args, load_calibration("example_mainhoop")) == 0

    doc = json.loads((out / "table.json").read_text())
    rows = {r["setting"]: r for r in doc["rows"]}
    assert list(rows) == list(INPUT_SETTINGS)
    assert [rows[s]["model_input"] for s in INPUT_SETTINGS] == ["1920x1088", "960x544", "1920x576", "960x288"]
    assert rows["full"]["recall"] == pytest.approx(1 / 3)
    assert rows["full"]["map50"] == pytest.approx(1 / 3, abs=0.02)
    for s in ("half", "crop", "crop_half"):
        assert rows[s]["recall"] == 0.0 and rows[s]["map50"] == pytest.approx(0.0, abs=1e-9)
    # in band: only the crop settings are scored a second time, on what the band shows
    assert rows["full"]["map50_in_band"] is None and rows["half"]["recall_min_height_in_band"] is None
    assert rows["crop"]["map50_in_band"] == pytest.approx(0.0, abs=1e-9)
    # the val frames were cut with the --band rows (96..672), the bench frames with the calibration's (384..960)
    preds = [json.loads(line) for line in (out / "preds" / "stub_crop.jsonl").read_text().splitlines()]
    assert len(preds) == 2 and preds[0]["boxes"][0][:4] == pytest.approx([x1, y1 + 96, x2, y2 + 96])
    assert [c for c, _ in made] == [CropSpec(0, 1080, 0, 1920, 1), CropSpec(0, 1080, 0, 1920, 2),
                                    CropSpec(384, 960, 0, 1920, 1), CropSpec(384, 960, 0, 1920, 2)]
    c = doc["conditions"]
    assert (c["val_boxes"], c["val_boxes_outside_band"], c["val_boxes_not_inside_band"], c["val_images"]) == (6, 2, 4, 2)
    md = (out / "table.md").read_text()
    assert md.count("| stub |") == 4 and "2 boxes (33.3 %)" in md and "4 (66.7 %) reach beyond it" in md


def test_table_needs_its_inputs(tmp_path) -> None:
    from cone_perception.cli import main

    assert main(["bench", "table", "--band", "96,672", "--out", str(tmp_path / "o")]) == 2
    assert main(["bench", "table", "--val", str(tmp_path), "--band", "96,672", "--out", str(tmp_path / "o"),
                 "--settings", "full,quarter"]) == 2


def test_fixed_size_backends_are_built_for_the_setting() -> None:
    """ONNX is built for the padded input of the setting (960x540 -> 960x544), not the checkpoint's 960x288."""
    from cone_perception.bench.pipeline import load_for_crop

    det = load_for_crop(None, "onnx", CropSpec(0, 1080, 0, 1920, 2), threads=1)
    assert det.imgsz == (960, 544) and det.input_size_for(960, 540) == (960, 544)
    assert det._run.session.get_inputs()[0].shape == [1, 3, 544, 960]
    boxes, _, _ = det.infer(np.full((540, 960, 3), 114, np.uint8))
    assert boxes.shape[1] == 4
