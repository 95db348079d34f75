"""``cone-perception synth``: dataset, bag and preview outputs; bad input stops before any work."""

import json

import cv2
import numpy as np
import pytest
import yaml

from cone_perception.adapter import crop_raw_to_bgr, decode_compressed, raw_frame_view
from cone_perception.classes import CLASS_NAMES
from cone_perception.cli import main
from cone_perception.crop import CropSpec
from cone_perception.data import bagio
from cone_perception.geometry.calib import load_calibration
from cone_perception.records import CONE_DTYPE, from_pointcloud2
from cone_perception.synth.config import SynthConfig
from cone_perception.synth.writers import MIN_LABEL_BOX_PX, MIN_LABEL_VISIBLE

SMALL = ["--size", "320x180", "--quiet"]


def test_dataset_layout_labels_and_truth(tmp_path):
    out = tmp_path / "ds"
    assert main(["synth", "dataset", "--n", "4", "--frames-per-track", "2", "--val-frac", "0.5", "--out", str(out), "--seed", "3", *SMALL]) == 0
    data = yaml.safe_load((out / "data.yaml").read_text())
    assert data["names"] == list(CLASS_NAMES) and data["nc"] == len(CLASS_NAMES)
    assert (out / data["train"]).is_dir() and (out / data["val"]).is_dir()
    assert len(list((out / "images/train").glob("*.jpg"))) == 2 and len(list((out / "images/val").glob("*.jpg"))) == 2
    records = [json.loads(line) for line in (out / "gt.jsonl").read_text().splitlines()]
    assert len(records) == 4
    n_labels = 0
    for rec in records:
        img = cv2.imread(str(out / rec["image"]))
        assert img.shape == (180, 320, 3) and (rec["width"], rec["height"]) == (320, 180)
        assert set(rec["pose"]) >= {"x_m", "y_m", "yaw_deg", "pitch_deg", "roll_deg"}
        label = out / rec["image"].replace("images/", "labels/").replace(".jpg", ".txt")
        rows = [list(map(float, line.split())) for line in label.read_text().splitlines()]
        # every label row is one of the gt cones that passes the documented thresholds
        want = []
        for c in rec["cones"]:
            u1, v1, u2, v2 = c["box"]
            assert 0 <= u1 < u2 <= 320 and 0 <= v1 < v2 <= 180
            assert 0 < c["visible_fraction"] <= 1
            assert c["distance_m"] == pytest.approx(np.hypot(c["x_m"], c["y_m"]), abs=1e-3)
            if u2 - u1 >= MIN_LABEL_BOX_PX and v2 - v1 >= MIN_LABEL_BOX_PX and c["visible_fraction"] >= MIN_LABEL_VISIBLE:
                want.append([c["class_id"], (u1 + u2) / 640, (v1 + v2) / 360, (u2 - u1) / 320, (v2 - v1) / 180])
        assert np.allclose(np.array(rows).reshape(-1, 5), np.array(want).reshape(-1, 5), atol=1e-5)
        n_labels += len(rows)
    assert n_labels > 0
    calib = load_calibration(out / "calib.yaml")
    assert np.allclose(calib.H_F_B, SynthConfig(width=320, height=180).camera().H_F_B())
    # a non-empty output directory is refused
    assert main(["synth", "dataset", "--n", "1", "--out", str(out), *SMALL]) == 2


@pytest.mark.parametrize("compressed", [False, True])
def test_bag_round_trip_and_calibration(tmp_path, compressed):
    out = tmp_path / "scene"
    args = ["synth", "bag", "--seconds", "0.3", "--fps", "10", "--out", str(out), "--seed", "1", *SMALL]
    assert main(args + (["--compressed"] if compressed else [])) == 0
    topic = "/camera/image_raw/compressed" if compressed else "/camera/image_raw"
    topics = bagio.bag_topics(out)
    assert topics[topic][1] == 3 and topics["/cones_gt"][1] == 3
    images = list(bagio.read_messages(out, topic))
    clouds = list(bagio.read_messages(out, "/cones_gt"))
    gt_lines = [json.loads(x) for x in (tmp_path / "scene_gt.jsonl").read_text().splitlines()]
    calib = load_calibration(tmp_path / "scene_calib.yaml")
    assert (calib.image_width, calib.image_height) == (320, 180)
    means = []
    for k, (im, cl, gt) in enumerate(zip(images, clouds, gt_lines)):
        stamp = bagio.stamp_ns(im.msg.header)
        assert stamp == bagio.stamp_ns(cl.msg.header) == im.log_stamp_ns == gt["stamp_ns"]
        assert stamp - bagio.stamp_ns(images[0].msg.header) == k * 100_000_000  # frame i at start + i / fps
        assert cl.msg.header.frame_id == "rear_axle"
        if compressed:
            bgr = decode_compressed(im.msg.data)
        else:
            assert im.msg.encoding == "yuv422_yuy2"
            name, view = raw_frame_view(im.msg.encoding, im.msg.width, im.msg.height, im.msg.step, im.msg.data)
            bgr = crop_raw_to_bgr(name, view, CropSpec.full_image(320, 180))
        assert bgr.shape == (180, 320, 3) and bgr.std() > 5
        means.append(bgr.reshape(-1, 3).mean(0))
        cones = from_pointcloud2(cl.msg, CONE_DTYPE)
        assert len(cones) == len(gt["cones"]) > 0
        assert np.allclose(cones["x"], [c["x_m"] for c in gt["cones"]], atol=1e-4)
        assert np.array_equal(cones["class_id"], [c["class_id"] for c in gt["cones"]])
        assert np.allclose(cones["score"], [c["visible_fraction"] for c in gt["cones"]], atol=1e-4)  # score = visible fraction
    # a recording keeps its camera settings: no exposure / white-balance flicker between frames
    assert np.abs(np.array(means) - means[0]).max() < 6


def test_preview_writes_a_contact_sheet(tmp_path):
    out = tmp_path / "sheet.png"
    assert main(["synth", "preview", "--out", str(out), "--n", "3", *SMALL]) == 0
    img = cv2.imread(str(out))
    assert img.shape == (2 * 540, 2 * 960, 3)
    assert img[540:, 960:].max() == 0 and img[:540, :960].std() > 5  # 3 frames in a 2x2 grid


def test_bench_reports_frames_per_second(capsys):
    assert main(["synth", "bench", "--frames", "2", *SMALL]) == 0
    assert "frames/s" in capsys.readouterr().out


@pytest.mark.parametrize(
    "args, message",
    [
        (["dataset", "--n", "2", "--size=-640x360"], "--size"),
        (["dataset", "--n", "2", "--size", "640by360"], "--size"),
        (["dataset", "--n", "0"], "--n"),
        (["bag", "--seconds", "1", "--fps", "0"], "--fps"),
        (["bag", "--seconds", "-1"], "--seconds"),
        (["bag", "--seconds", "1", "--pitch", "-60"], "looks at the sky"),
        (["dataset", "--n", "2", "--pitch", "-45", "--hfov", "60"], "looks at the sky"),
        (["preview", "--n", "2", "--hfov", "200"], "--hfov"),
        (["dataset", "--n", "2", "--tracks", "oval"], "--tracks"),
    ],
)
def test_bad_parameters_stop_before_any_work(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    out_arg = str(out) + (".png" if args[0] == "preview" else "")
    assert main(["synth", *args, "--out", out_arg, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert not list(tmp_path.iterdir()), "nothing may be written"


def test_unwritable_output_is_refused(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    for args in (
        ["dataset", "--n", "1", "--out", str(blocker / "ds")],
        ["bag", "--seconds", "0.1", "--out", str(blocker / "bag")],
        ["preview", "--out", str(blocker / "p.png")],
    ):
        assert main(["synth", *args, *SMALL]) == 2
        assert "cannot create directory" in capsys.readouterr().err
    (tmp_path / "bag").mkdir()
    assert main(["synth", "bag", "--seconds", "0.1", "--out", str(tmp_path / "bag"), *SMALL]) == 2
    assert "already exists" in capsys.readouterr().err


def test_vary_mount_records_each_frames_camera(tmp_path):
    from cone_perception.geometry import GroundMapper
    from cone_perception.geometry.camera import MountPose, PinholeCamera

    out = tmp_path / "vm"
    args = ["synth", "dataset", "--n", "3", "--frames-per-track", "1", "--vary-mount", "--no-jitter", "--out", str(out), *SMALL]
    assert main(args) == 0
    records = [json.loads(line) for line in (out / "gt.jsonl").read_text().splitlines()]
    hfovs = set()
    for rec in records:
        cam = rec["camera"]
        K = np.array(cam["K"])
        hfovs.add(round(float(K[0, 0]), 3))
        pc = PinholeCamera(K, rec["width"], rec["height"], MountPose(**cam["mount"]))
        full = [c for c in rec["cones"] if c["visible_fraction"] >= 0.999]
        xy, ok = GroundMapper(pc.H_F_B(), 1e3).map_pixels(np.array([c["foot_px"] for c in full]).reshape(-1, 2))
        assert np.all(ok)
        assert np.hypot(*(xy - np.array([[c["x_m"], c["y_m"]] for c in full]).reshape(-1, 2)).T).max() < 0.02
    assert len(hfovs) == 3  # each track got its own viewpoint


def test_mapcheck_shows_the_jitter_error(capsys):
    from cone_perception.synth.mapcheck import mapping_check

    off = mapping_check(SynthConfig(width=960, height=540, jitter=False, nose_prob=0.0, photometric=False), 6)
    on = mapping_check(SynthConfig(width=960, height=540, jitter=True, nose_prob=0.0, photometric=False), 6)
    assert off[0]["n"] > 5 and off[0]["median_m"] < 0.4  # perfect boxes, near cones: foot-point rule only
    assert on[1]["median_m"] > 2 * off[1]["median_m"]  # +-1 deg pitch matters at 10-20 m
    assert main(["synth", "mapcheck", "--frames", "1", *SMALL]) == 0
    assert "median" in capsys.readouterr().out
