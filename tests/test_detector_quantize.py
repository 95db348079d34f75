"""int8 static quantisation (``export --int8``): calibration frames, the quantised graph, the check."""

from __future__ import annotations

import cv2
import numpy as np
import onnx
import pytest
import yaml

from cone_perception.adapter import crop_bgr
from cone_perception.classes import CLASS_NAMES
from cone_perception.cli import main as cli_main
from cone_perception.crop import CropSpec
from cone_perception.detector import Detector
from cone_perception.errors import ConfigError
from cone_perception.train import quantize
from cone_perception.train.quantize import (
    calibration_blobs, compare_detections, head_output_convs, int8_frame_pool, qdq_summary, spread,
)

from synthetic_cones import SMOKE_SIZE, make_image, trained_smoke_model


@pytest.fixture(scope="module")
def smoke():
    """The overfitted smoke model (size p, 256x96) and its synthetic images (the calibration frames)."""
    ckpt, root, _ = trained_smoke_model()
    return ckpt, root / "images"


def _export_int8(tmp_path, ckpt, images, *extra):
    out = tmp_path / "model.onnx"
    rc = cli_main(["export", "--model", str(ckpt), "--format", "onnx", "--out", str(out), "--int8",
                   "--calib-images", str(images), "--calib-frames", "6", "--no-progress", *extra])
    assert rc == 0
    return out, tmp_path / "model.int8.onnx"


def _qdq_only_around_convs(model) -> None:
    """Every QuantizeLinear quantises a Conv's input or a Conv's output; nothing is a QLinear* op."""
    producer = {o: n for n in model.graph.node for o in n.output}
    consumers: dict[str, list] = {}
    for n in model.graph.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    for n in model.graph.node:
        assert not n.op_type.startswith("QLinear") and n.op_type not in ("ConvInteger", "MatMulInteger")
        if n.op_type != "QuantizeLinear":
            continue
        src = producer.get(n.input[0])
        dqs = [c for c in consumers.get(n.output[0], []) if c.op_type == "DequantizeLinear"]
        feeds_conv = any(c.op_type == "Conv" for dq in dqs for c in consumers.get(dq.output[0], []))
        assert (src is not None and src.op_type == "Conv") or feeds_conv, f"{n.name} quantises {n.input[0]}, not at a Conv"


def test_export_int8_quantises_convs_only_and_keeps_boxes(tmp_path, smoke, capsys):
    ckpt, images = smoke
    fp32, int8 = _export_int8(tmp_path, ckpt, images)
    said = capsys.readouterr().out
    assert "calibrating on 6 frames" in said and "float boxes matched" in said
    side = yaml.safe_load(int8.with_name(int8.name + ".yaml").read_text())
    assert side["names"] == list(CLASS_NAMES) and side["imgsz"] == list(SMOKE_SIZE)
    assert "per-channel" in side["quantisation"] and "6 frames" in side["calibration"]

    m = onnx.load(str(int8))
    s = qdq_summary(m)
    ref = onnx.load(str(fp32))
    n_conv = sum(n.op_type == "Conv" for n in ref.graph.node)
    last = head_output_convs(m)
    assert len(last) == 6  # box and class branch at three strides
    assert s["conv_float"] == last and len(s["conv_int8"]) == n_conv - 6
    assert s["op_types"]["QuantizeLinear"] > 0 and s["op_types"]["DequantizeLinear"] > 0
    _qdq_only_around_convs(m)
    # the box decoding (concat, DFL softmax + expectation, box arithmetic, class sigmoid) is float
    assert {"Softmax", "ReduceSum", "Sigmoid", "Split"} <= set(s["decode_ops"])
    assert not set(s["decode_ops"]) & set(quantize.QDQ_OPS)
    for name in quantize.decode_nodes(m, last):
        node = next(n for n in m.graph.node if n.name == name)
        assert node.op_type not in quantize.QDQ_OPS

    # Detector.load runs it; it is quantised (not the float numbers) and finds the same cones
    q = Detector.load(int8, backend="onnx")
    f = Detector.load(fp32, backend="onnx")
    assert q.imgsz == SMOKE_SIZE
    w, h = SMOKE_SIZE
    blob = np.full((1, 3, h, w), 0.45, np.float32)
    blob[..., : h // 2, : w // 3] = 0.9
    raw_q, raw_f = q.raw(blob), f.raw(blob)
    assert raw_q.shape == raw_f.shape and np.abs(raw_q - raw_f).max() > 1e-4
    pairs = []
    for p in sorted(images.glob("*.png")):
        img = cv2.imread(str(p))
        pairs.append((f.infer(img, in_size=SMOKE_SIZE), q.infer(img, in_size=SMOKE_SIZE)))
    r = compare_detections(pairs)
    assert r["ref_boxes"] >= 8 and r["matched"] >= 0.9 and r["mean_iou"] >= 0.9, r


def test_int8_head_and_all_ops_keep_the_decoding_float(tmp_path, smoke):
    ckpt, images = smoke
    _, int8 = _export_int8(tmp_path, ckpt, images, "--int8-head", "--int8-ops", "all")
    m = onnx.load(str(int8))
    s = qdq_summary(m)
    assert s["conv_float"] == [] and len(s["conv_int8"]) > 6
    assert s["dq_readers"].get("Mul", 0) > s["dq_readers"].get("Sigmoid", 0)  # SiLU's product takes int8 inputs too
    assert not set(s["decode_ops"]) & set(quantize.QDQ_OPS)
    assert Detector.load(int8, backend="onnx").raw(np.zeros((1, 3, SMOKE_SIZE[1], SMOKE_SIZE[0]), np.float32)).shape[0] == 4 + 5


def test_calibration_blob_is_what_the_detector_feeds_the_network(tmp_path, smoke):
    ckpt, _ = smoke
    img, _ = make_image(np.random.default_rng(3), 512, 300, 3)
    f = tmp_path / "autox3_mp4-7_jpg_x.png"
    cv2.imwrite(str(f), img)
    det = Detector.load(ckpt, backend="onnx")
    seen = []
    run = det._run
    det._run = lambda b: (seen.append(b.copy()), run(b))[1]
    for crop in ((96, 288), (100, 260, 0, 512)):  # 256x96 exactly; 256x80 (letterboxed)
        spec = CropSpec(*(crop if len(crop) == 4 else (*crop, 0, 512)), 2)
        det.detect(crop_bgr(cv2.imread(str(f)), spec), spec)
        (blob,) = list(calibration_blobs([f], SMOKE_SIZE, crop, downscale=2))
        assert np.array_equal(blob, seen[-1])
    det.detect_image(cv2.imread(str(f)))  # no crop: the whole frame letterboxed
    assert np.array_equal(next(calibration_blobs([f], SMOKE_SIZE)), seen[-1])


def test_validation_clips_are_never_calibration_frames(tmp_path):
    img = np.full((8, 8, 3), 100, np.uint8)
    names = ["autox4_mp4-1_jpg_a", "autox2_mp4-2_jpg_b", "accel_mp4-3_jpg_c", "autox3_mp4-4_jpg_d", "autox6_mp4-5_jpg_e",
             "skidpad_1_jpg_f"]
    for n in names:
        cv2.imwrite(str(tmp_path / f"{n}.jpg"), img)
    pool, dropped = int8_frame_pool(tmp_path)
    assert [p.stem for p in pool] == ["autox3_mp4-4_jpg_d", "autox6_mp4-5_jpg_e", "skidpad_1_jpg_f"] and dropped == 3
    assert [p.stem for p in int8_frame_pool(tmp_path, ["autox6"])[0]] == ["autox6_mp4-5_jpg_e"]
    with pytest.raises(ConfigError, match="calib-clips.*autox2.*validation"):
        int8_frame_pool(tmp_path, ["autox3", "autox2"])
    only_val = tmp_path / "val"
    only_val.mkdir()
    cv2.imwrite(str(only_val / "accel_mp4-9_jpg_z.jpg"), img)
    with pytest.raises(ConfigError, match="validation clips"):
        int8_frame_pool(only_val)
    assert [p.stem for p in spread(pool, 2)] == ["autox3_mp4-4_jpg_d", "skidpad_1_jpg_f"]
    assert len(spread(pool, 99)) == 3


def test_compare_detections_fails_on_moved_or_missing_boxes():
    ref = (np.array([[0, 0, 10, 20], [50, 0, 60, 20]], np.float32), np.array([0.9, 0.8], np.float32), np.array([0, 1]))
    same = compare_detections([(ref, ref)])
    assert same["ok"] and same["matched"] == 1.0 and same["mean_iou"] == pytest.approx(1.0) and same["max_dev_px"] == 0
    moved = (ref[0] + np.float32([2, 0, 2, 0]), ref[1] - 0.1, ref[2])  # IoU 8/12 each
    r = compare_detections([(ref, moved)])
    assert r["matched"] == 1.0 and r["mean_iou"] == pytest.approx(8 / 12) and not r["ok"]
    assert r["max_dev_px"] == pytest.approx(2) and r["max_score_diff"] == pytest.approx(0.1)
    wrong_class = (ref[0], ref[1], np.array([0, 2]))
    r = compare_detections([(ref, wrong_class)])
    assert r["matched"] == 0.5 and not r["ok"]


def test_int8_check_failure_removes_the_files(tmp_path, smoke, monkeypatch, capsys):
    ckpt, images = smoke
    monkeypatch.setattr(quantize, "MIN_MEAN_IOU", 1.01)  # no int8 model can pass this
    rc = cli_main(["export", "--model", str(ckpt), "--format", "onnx", "--out", str(tmp_path / "m.onnx"), "--int8",
                   "--calib-images", str(images), "--calib-frames", "3", "--no-progress"])
    assert rc == 2
    assert "int8 model too far from eager" in capsys.readouterr().err
    assert not (tmp_path / "m.int8.onnx").exists() and not (tmp_path / "m.int8.onnx.yaml").exists()
    assert (tmp_path / "m.onnx").exists()  # the float export passed its own check


@pytest.mark.parametrize("extra, says", [
    (["--format", "torchscript", "--int8", "--calib-images", "IMAGES"], "--int8: int8 quantisation needs --format onnx"),
    (["--format", "onnx", "--int8"], "--int8: calib-images: give a folder"),
    (["--format", "onnx", "--int8", "--calib-images", "MISSING"], "calib-images: calibration image folder not found"),
    (["--format", "onnx", "--int8", "--calib-images", "EMPTY"], "calib-images: no images"),
    (["--format", "onnx", "--calib-images", "IMAGES"], "--calib-images: calibration options need --int8"),
    (["--format", "onnx", "--int8", "--calib-images", "IMAGES", "--calib-frames", "0"], "--calib-frames: must be >= 1"),
])
def test_export_int8_bad_input_is_a_config_error(tmp_path, smoke, capsys, extra, says):
    ckpt, images = smoke
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "notes.txt").write_text("no images here")
    subst = {"IMAGES": str(images), "MISSING": str(tmp_path / "nowhere"), "EMPTY": str(tmp_path / "empty")}
    out = tmp_path / ("m.torchscript" if "torchscript" in extra else "m.onnx")
    rc = cli_main(["export", "--model", str(ckpt), "--out", str(out), *[subst.get(a, a) for a in extra]])
    err = capsys.readouterr().err
    assert rc == 2 and says in err, err
    if "MISSING" in extra:
        assert str(tmp_path / "nowhere") in err
    assert not out.exists()  # refused before anything was written
