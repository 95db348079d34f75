"""The far strip's second look (detector/verifier.py): the crop, which boxes it asks about and drops (counted), the
shipped verifier on rendered cones and on the road, its file refused with a clear error, and its training."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cone_perception.crop import SIDE, CropSpec, crop_patch
from cone_perception.detector import verifier as vf
from cone_perception.detector.farband import FarBand
from cone_perception.errors import ConfigError
from cone_perception.geometry.calib import load_calibration
from cone_perception.pipeline import Pipeline
from cone_perception.records import boxes_from_arrays

from rosutil import ros  # noqa: F401 (a fixture)

CALIB = load_calibration("example_mainhoop")
STRIP = CropSpec(370, 466, 0, 1920, 1)


def test_the_crop_is_a_square_of_twice_the_box_height_around_it():
    img = np.zeros((200, 300, 3), np.uint8)
    img[90:110, 140:150] = (0, 0, 255)  # a red box 10 x 20 px
    p = crop_patch(img, (140, 90, 150, 110))
    assert p.shape == (SIDE, SIDE, 3)
    red = p[:, :, 2] > 128
    rows, cols = np.flatnonzero(red.any(1)), np.flatnonzero(red.any(0))
    # 40 px of image on 32 px: the 20 px box spans about 16 rows, 8 columns, in the middle
    assert 14 <= len(rows) <= 18 and 6 <= len(cols) <= 10
    assert abs(rows.mean() - 15.5) < 1.0 and abs(cols.mean() - 15.5) < 1.0
    # near the image's edge the edge rows are repeated, not black
    edge = np.full((50, 50, 3), 80, np.uint8)
    assert crop_patch(edge, (0, 0, 10, 10)).min() == 80


class _Fixed(vf.BoxVerifier):
    """The verifier's thresholds with a network double: a box's probability is its left column / 1000."""

    def __init__(self):
        super().__init__(None, verify_below=0.7, min_p=0.1, min_px=6.0, max_px=60.0)
        self.asked = []

    def probabilities(self, img, xyxy):
        self.asked.append(np.array(xyxy))
        return xyxy[:, 0] / 1000.0


def _boxes(rows):
    a = np.array([r[:4] for r in rows], np.float32)
    return boxes_from_arrays(a, np.array([r[4] for r in rows], np.float32), np.zeros(len(rows), np.uint8))


def test_only_doubtful_small_boxes_are_asked_and_those_without_a_cone_dropped():
    v = _Fixed()
    b = _boxes([
        (50, 400, 60, 420, 0.5),     # asked, p 0.05: dropped
        (500, 400, 510, 420, 0.5),   # asked, p 0.5: kept
        (60, 400, 70, 420, 0.9),     # scored above verify_below: not asked, kept
        (70, 400, 72, 404, 0.3),     # 4 px: below min_px, kept
        (80, 300, 120, 380, 0.3),    # 80 px: above max_px, kept
    ])
    out = b[~v.drops(np.zeros((96, 1920, 3), np.uint8), b, 0, 370)]
    assert out["u1"].tolist() == [500, 60, 70, 80]
    assert v.counts == {"checked": 2, "dropped": 1}
    # the boxes are asked about in the strip's own px (row 400 of the image = row 30 of the strip)
    assert v.asked[0][:, 1].tolist() == [30.0, 30.0]


class _Strip:
    """A strip detector double: two boxes, one the verifier keeps (u1 900) and one it drops (u1 50)."""

    timing = {"preprocess_ms": 0.0, "forward_ms": 0.0, "postprocess_ms": 0.0}

    def detect(self, bgr, crop):
        return _boxes([(50, 400, 60, 420, 0.4), (900, 400, 910, 420, 0.4)])


class _Band:
    timing = {"preprocess_ms": 0.0, "forward_ms": 0.0, "postprocess_ms": 0.0}

    def detect(self, bgr, crop):
        return _boxes([])


def test_the_strip_with_a_verifier_drops_and_counts_in_the_pipeline(ros):
    frame = np.zeros((1080, 1920, 3), np.uint8).tobytes()
    pipe = Pipeline(CALIB, _Band(), "fixed", far=FarBand(STRIP, _Strip(), verifier=_Fixed()))
    for i in range(3):
        res = pipe.process_raw("bgr8", 1920, 1080, 5760, frame, stamp_ns=i)
        assert res.boxes["u1"].tolist() == [900]
    assert pipe.strip_counts == {"frames": 3, "clamped": 0, "verifier_dropped": 3}
    plain = Pipeline(CALIB, _Band(), "fixed", far=FarBand(STRIP, _Strip()))
    assert len(plain.process_raw("bgr8", 1920, 1080, 5760, frame, stamp_ns=0).boxes) == 2
    assert "verifier_dropped" not in plain.strip_counts


def test_tile_frames_get_the_second_look_too(ros):
    """far_every 2 with tiles: the frames between run the tiles around the last frame's far cones; their boxes in the
    strip's rows are judged as the whole strip's are (the strip is cut on those frames too), and counted."""
    from cone_perception.detector.fartiles import TILE_MARGIN_PX, FarTiles

    class _Tile:  # the mosaic's network: the cone kept on the strip's frame, where its window puts it
        timing = _Strip.timing

        def detect(self, bgr, crop):  # full-image rows; the mosaic's columns (the window of u 900 starts at 0)
            return _boxes([(TILE_MARGIN_PX, 400, TILE_MARGIN_PX + 10, 420, 0.4)])

    frame = np.zeros((1080, 1920, 3), np.uint8).tobytes()
    ver = _Fixed()
    pipe = Pipeline(CALIB, _Band(), "fixed", far=FarBand(STRIP, _Strip(), verifier=ver), far_every=2,
                    far_tiles=FarTiles({256: _Tile(), 512: _Tile(), 1152: _Tile()}))
    kept = [pipe.process_raw("bgr8", 1920, 1080, 5760, frame, stamp_ns=i).boxes["u1"].tolist() for i in range(2)]
    assert pipe.strip_counts["tiles"] == 1  # frame 1 ran as tiles
    assert kept == [[900], [900]]  # the strip's frame: the box at u1 50 dropped; the tile frame: its cone kept
    assert [a[:, 0].tolist() for a in ver.asked] == [[50, 900], [900]]  # the tile frame's box was asked about too
    ver.probabilities = lambda img, xyxy: np.zeros(len(xyxy))  # now it sees no cone anywhere
    assert len(pipe.process_raw("bgr8", 1920, 1080, 5760, frame, stamp_ns=2).boxes) == 0  # a strip frame
    assert len(pipe.process_raw("bgr8", 1920, 1080, 5760, frame, stamp_ns=3).boxes) == 0  # tiles (frame 1's cone)
    assert pipe.strip_counts["verifier_dropped"] == 4 and pipe.strip_counts["tiles"] == 2


def test_the_shipped_verifier_keeps_rendered_cones_and_drops_bare_road():
    from cone_perception.synth.config import SynthConfig
    from cone_perception.synth.scene import random_pose

    v = vf.load_verifier("auto")
    assert v is not None and v.source.endswith("cone_verifier.pt")
    assert (v.verify_below, v.min_p) == (0.7, 0.1)
    cfg = SynthConfig(width=1920, height=1080, seed=7, jitter=False)
    renderer, rng = cfg.renderer(), np.random.default_rng(7)
    cones, road = [], []
    for i in range(4):
        track, look = cfg.track(i, rng), renderer.new_look(rng)
        img, truth = renderer.render(track, random_pose(track, rng, False), look, rng)
        boxes = np.array([t.box for t in truth if t.visible_fraction >= 0.8 and 10 <= t.box[3] - t.box[1] <= 40])
        if len(boxes):
            cones.append(v.probabilities(img, boxes))
        allb = np.array([t.box for t in truth]).reshape(-1, 4)
        for _ in range(30):  # boxes of a small cone's size on the ground ahead, far from every cone
            h = rng.uniform(10, 30)
            cx, cy = rng.uniform(100, 1820), rng.uniform(600, 1000)
            if len(allb) and ((allb[:, 0] - 3 * h < cx) & (cx < allb[:, 2] + 3 * h)
                              & (allb[:, 1] - 3 * h < cy) & (cy < allb[:, 3] + 3 * h)).any():
                continue
            road.append(v.probabilities(img, np.array([[cx - h / 3, cy - h / 2, cx + h / 3, cy + h / 2]]))[0])
    cones = np.concatenate(cones)
    assert len(cones) >= 20 and len(road) >= 20
    assert (cones >= v.min_p).mean() >= 0.95, cones
    assert (np.array(road) < v.min_p).mean() >= 0.8, road


def test_bad_verifier_files_are_refused_naming_the_option_and_the_file(tmp_path):
    import torch

    assert vf.load_verifier("none") is None and vf.load_verifier("") is None
    assert vf.verifier_path_for(None) is None  # issue 41: off unless asked for (auto = the shipped one)
    assert vf.verifier_path_for("auto") == vf.default_verifier_path()
    with pytest.raises(ConfigError, match=r"--far-verifier: .*nope\.pt: no such verifier file"):
        vf.load_verifier(str(tmp_path / "nope.pt"), "--far-verifier")
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a torch file")
    with pytest.raises(ConfigError, match="cannot read it as a verifier file"):
        vf.load_verifier(str(junk), "--far-verifier")
    with pytest.raises(ConfigError, match="not a cone verifier file"):  # a detector checkpoint, say
        vf.load_verifier("models/cone_detector_far.pt", "parameter far_verifier")
    d = torch.load("models/cone_verifier.pt", weights_only=True)
    other = tmp_path / "other.pt"
    torch.save({**d, "side": 48}, other)
    with pytest.raises(ConfigError, match="cut for 48 px crops"):
        vf.load_verifier(str(other))
    wrong = tmp_path / "wrong.pt"
    torch.save({**d, "state_dict": {k: (v[:1] if v.dim() else v) for k, v in d["state_dict"].items()}}, wrong)
    with pytest.raises(ConfigError, match="do not fit the verifier network"):
        vf.load_verifier(str(wrong))


def test_verifier_crops_and_training_write_a_verifier_the_pipeline_loads(tmp_path, capsys):
    import cv2

    from cone_perception.cli import main

    root = tmp_path / "synth"
    (root / "images" / "train").mkdir(parents=True)
    real = tmp_path / "real"
    (real / "images").mkdir(parents=True)
    (real / "labels").mkdir()
    rng = np.random.default_rng(0)
    cam = {"K": [[1000.0, 0, 960], [0, 1000.0, 540], [0, 0, 1]], "dist_coeffs": [],
           "mount": {"x_m": 0.5, "y_m": 0.0, "height_m": 1.2, "pitch_deg": 5.0, "roll_deg": 0.0, "yaw_deg": 0.0}}
    preds, recs = [], []
    for k in range(3):
        img = rng.integers(90, 110, (1080, 1920, 3), dtype=np.uint8)
        cones = []
        for j in range(6):  # yellow "cones" with a dark band, in the strip's rows
            u, v = 200 + 250 * j, 400
            img[v:v + 16, u:u + 10] = (0, 200, 230)
            img[v + 6:v + 10, u:u + 10] = 20
            cones.append({"class_id": 1, "box": [u, v, u + 10, v + 16], "visible_fraction": 1.0})
        name = f"images/train/{k:06d}.jpg"
        cv2.imwrite(str(root / name), img)
        recs.append({"image": name, "width": 1920, "height": 1080, "camera": cam, "cones": cones})
        boxes = [[*c["box"], 0.6, 1] for c in cones] + [[1000 + 30 * j, 410, 1010 + 30 * j, 426, 0.4, 1] for j in range(3)]
        preds.append({"image": name, "width": 1920, "height": 1080, "boxes": boxes})
        small = cv2.resize(img, (640, 360), interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(real / "images" / f"r{k}.jpg"), small)
        (real / "labels" / f"r{k}.txt").write_text("".join(
            f"3 {(c['box'][0] + 5) / 1920:.5f} {(c['box'][1] + 8) / 1080:.5f} {10 / 1920:.5f} {16 / 1080:.5f}\n" for c in cones))
    (root / "gt.jsonl").write_text("".join(json.dumps(r) + "\n" for r in recs))
    (tmp_path / "pred.jsonl").write_text("".join(json.dumps(p) + "\n" for p in preds))
    crops = tmp_path / "crops.npz"
    assert main(["data", "verifier-crops", str(crops), "--rendered", str(root), str(tmp_path / "pred.jsonl"),
                 "--real", str(real), "--no-progress"]) == 0
    z = np.load(crops)
    assert z["X"].shape[1:] == (SIDE, SIDE, 3)
    # 18 detections on cones, 9 on no cone, random boxes of the road (no cone), a share of the 18 cones, 3 x 18 real
    assert int((z["y"] == 0).sum()) >= 9 and int(((z["y"] == 1) & (z["src"] == 1)).sum()) >= 18
    assert int((z["src"] == 2).sum()) == 3 * 18 and z["y"][z["src"] == 2].all()
    out = tmp_path / "run"
    assert main(["train", "--data", str(crops), "--out", str(out), "--epochs", "1", "--no-progress"]) == 0
    v = vf.load_verifier(str(out / "verifier.pt"))
    assert (v.verify_below, v.min_p, v.min_px, v.max_px) == (0.7, 0.1, 6.0, 60.0)
    assert v.probabilities(np.zeros((96, 1920, 3), np.uint8), np.array([[10, 10, 20, 30]])).shape == (1,)
    capsys.readouterr()
    assert main(["data", "verifier-crops", str(crops), "--no-progress"]) == 2
    assert "--rendered: needs at least one rendered set" in capsys.readouterr().err
