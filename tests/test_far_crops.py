"""`data far-crops`: windows around small cones at native scale, with their clipped labels."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import yaml

from cone_perception.cli import main as cli_main
from cone_perception.data.datasets import load_data_yaml
from cone_perception.data.farcrops import boxes_in_window, far_crops, window_around
from cone_perception.errors import ConfigError

W, H = 400, 200


def _dataset(root, n=4):
    """Grey frames 400x200, each with a small blue cone (6x10 px at x 300, y 60), a large yellow one
    (40x60 px at x 40, y 120) and, in frame 0 only, nothing else; labels in YOLO form (names blue, yellow)."""
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir(parents=True)
    for i in range(n):
        img = np.full((H, W, 3), 100, np.uint8)
        img[60:70, 300:306] = (200, 50, 0)  # small blue cone: 6x10 px, a bright patch to find again
        img[120:180, 40:80] = (0, 200, 220)
        cv2.imwrite(str(root / "images" / f"f{i}.png"), img)
        lines = [f"0 {303 / W} {65 / H} {6 / W} {10 / H}", f"1 {60 / W} {150 / H} {40 / W} {60 / H}"]
        (root / "labels" / f"f{i}.txt").write_text("\n".join(lines) + "\n")
    (root / "data.yaml").write_text(yaml.safe_dump({"path": str(root), "train": "images", "names": ["blue", "yellow"]}))
    return root / "data.yaml"


def test_window_holds_the_box_and_stays_inside_the_image():
    rng = np.random.default_rng(0)
    for _ in range(200):
        x0, y0, x1, y1 = window_around(np.array([300, 60, 306, 70], np.float32), (W, H), (96, 32), rng)
        assert (x1 - x0, y1 - y0) == (96, 32)
        assert 0 <= x0 <= 300 and 306 <= x1 <= W and 0 <= y0 <= 60 and 70 <= y1 <= H
    # a window wider than the image: the whole width
    x0, y0, x1, y1 = window_around(np.array([300, 60, 306, 70], np.float32), (W, H), (960, 32), rng)
    assert (x0, x1) == (0, W) and y1 - y0 == 32


def test_boxes_clipped_and_cut_cones_dropped():
    boxes = np.array([[10, 10, 20, 30], [90, 10, 110, 30], [95, 10, 115, 30]], np.float32)
    cls = np.array([0, 1, 2])
    b, c = boxes_in_window(boxes, cls, (0, 0, 100, 40))
    # the first whole; the second half inside (kept, clipped); the third a quarter inside (< 30 %: dropped)
    assert c.tolist() == [0, 1]
    np.testing.assert_allclose(b, [[10, 10, 20, 30], [90, 10, 100, 30]])


def test_far_crops_cut_native_scale_windows_with_labels(tmp_path):
    data = _dataset(tmp_path / "src")
    rep = far_crops(data, tmp_path / "out", size=(128, 64), max_height=24, per_image=2, seed=3, progress=False)
    # one candidate per frame (the 60-px cone is above --max-height): one window each
    assert rep.images == 4 and rep.crops == 4 and rep.without_candidate == 0
    assert rep.by_height["8-12"] >= 4
    imgs = sorted((tmp_path / "out" / "images").iterdir())
    assert len(imgs) == 4
    for p in imgs:
        img = cv2.imread(str(p))
        assert img.shape[:2] == (64, 128)  # not resized
        lab = np.loadtxt(tmp_path / "out" / "labels" / f"{p.stem}.txt", ndmin=2)
        small = lab[lab[:, 0] == 0]  # project class 0 = blue
        assert len(small) == 1
        cx, cy, bw, bh = small[0, 1:] * [128, 64, 128, 64]
        assert (bw, bh) == pytest.approx((6, 10), abs=0.01)  # native size kept
        patch = img[int(cy - bh / 2) + 2 : int(cy + bh / 2) - 2, int(cx - bw / 2) + 1 : int(cx + bw / 2) - 1]
        assert patch.size and np.abs(patch.astype(int).mean((0, 1)) - (200, 50, 0)).max() < 25  # the label sits on the cone
    # the output reads back as a training set, classes in project ids
    train, _, _ = load_data_yaml(tmp_path / "out" / "data.yaml")
    assert sum(len(e.image_paths) for e in train) == 4


def test_far_crops_counts_frames_without_a_small_cone(tmp_path):
    data = _dataset(tmp_path / "src", n=2)
    rep = far_crops(data, tmp_path / "out", size=(128, 64), max_height=8, progress=False)
    assert rep.crops == 0 and rep.without_candidate == 2


def test_far_crops_bad_input_names_the_option(tmp_path):
    data = _dataset(tmp_path / "src", n=1)
    with pytest.raises(ConfigError, match="--min-height"):
        far_crops(data, tmp_path / "o1", min_height=30, max_height=20, progress=False)
    with pytest.raises(ConfigError, match="--size"):
        far_crops(data, tmp_path / "o2", size=(16, 64), progress=False)
    with pytest.raises(ConfigError, match="--around-conf"):
        far_crops(data, tmp_path / "o4", around=tmp_path / "p.jsonl", around_conf=1.5, progress=False)
    with pytest.raises(ConfigError, match="val"):
        far_crops(data, tmp_path / "o3", split="val", progress=False)
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("")
    with pytest.raises(ConfigError, match="new or empty"):
        far_crops(data, tmp_path / "full", progress=False)


def test_far_crops_cli(tmp_path, capsys):
    data = _dataset(tmp_path / "src", n=2)
    rc = cli_main(["data", "far-crops", str(data), str(tmp_path / "out"), "--size", "128x64", "--no-progress"])
    assert rc == 0
    assert "2 crops" in capsys.readouterr().out
    assert len(list((tmp_path / "out" / "labels").iterdir())) == 2


def _predictions(path, boxes_by_frame):
    """A `detect` prediction file of the `_dataset` frames: name -> [[u1, v1, u2, v2, score, class], ...]."""
    path.write_text("".join(json.dumps({"image": f"images/{name}", "width": W, "height": H, "boxes": b}) + "\n"
                            for name, b in boxes_by_frame.items()))
    return path


def test_far_crops_around_false_detections_cut_hard_negatives(tmp_path):
    """--around: windows around a model's false detections (a 6x12 px box on the grey at x 200, y 20), not around
    its true ones (on the small blue cone) nor its weak ones."""
    data = _dataset(tmp_path / "src", n=3)
    false_box, on_cone, weak = [197, 14, 203, 26, 0.6, 1], [300, 60, 306, 70, 0.9, 0], [100, 20, 106, 32, 0.1, 1]
    pred = _predictions(tmp_path / "p.jsonl", {"f0.png": [false_box, on_cone, weak], "f1.png": [on_cone]})
    rep = far_crops(data, tmp_path / "out", size=(128, 64), per_image=3, seed=1, progress=False, around=pred)
    # f0: one false detection, one window; f1: only a true one; f2: not in the file
    assert rep.crops == 1 and rep.without_candidate == 2
    (img,) = (tmp_path / "out" / "images").iterdir()
    assert img.stem.startswith("f0")
    assert cv2.imread(str(img)).shape[:2] == (64, 128)
    assert "false detections" in (tmp_path / "out" / "data.yaml").read_text()


def test_false_detections_are_those_on_no_labelled_cone():
    from cone_perception.data.farcrops import false_detections
    from cone_perception.records import boxes_from_arrays

    labels = np.array([[300, 60, 306, 70]], np.float32)
    pred = boxes_from_arrays(np.array([[300, 61, 306, 71], [297, 60, 303, 70], [200, 20, 206, 30]], np.float32),
                             np.array([0.9, 0.8, 0.1]), np.array([0, 1, 1]))
    # the first overlaps the cone (IoU 0.82), the second half of it (IoU 0.33, still a detection of it), the third no cone
    assert false_detections(pred, labels, 0.05).tolist() == [[200, 20, 206, 30]]
    assert false_detections(pred, labels, 0.25).shape == (0, 4)  # the third below the score
    assert len(false_detections(pred, labels[:0], 0.05)) == 3  # no labels: every detection is false


def test_far_crops_around_leaves_out_detections_on_unlabelled_rendered_cones(tmp_path):
    """A rendered set's gt.jsonl lists cones its labels leave out (too small, mostly hidden): a detection on one is
    no false detection (a window around it would teach the model to miss a real cone)."""
    data = _dataset(tmp_path / "src", n=2)
    unlabelled = [150, 100, 154, 104]  # a 4x4 px cone: below the label limit, in gt.jsonl only
    (tmp_path / "src" / "gt.jsonl").write_text("".join(
        json.dumps({"image": f"images/f{i}.png", "width": W, "height": H,
                    "cones": [{"class_id": 0, "box": unlabelled, "x_m": 40.0, "y_m": 1.0}]}) + "\n" for i in range(2)))
    on_it, paint = [148, 96, 156, 106, 0.7, 1], [197, 14, 203, 26, 0.6, 1]
    pred = _predictions(tmp_path / "p.jsonl", {"f0.png": [on_it], "f1.png": [on_it, paint]})
    rep = far_crops(data, tmp_path / "out", size=(128, 64), per_image=3, seed=1, progress=False, around=pred)
    assert rep.crops == 1 and rep.without_candidate == 1  # f1's paint only
    (img,) = (tmp_path / "out" / "images").iterdir()
    assert img.stem.startswith("f1")
