"""``eval``: metrics whose right values are known by construction, both ground-truth formats, bad input."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cone_perception.classes import BLUE, LARGE_ORANGE, ORANGE, YELLOW
from cone_perception.cli import main
from cone_perception.data.predictions import read_predictions
from cone_perception.errors import ConfigError
from cone_perception.evaluation import PairDistanceReport, blue_yellow_pairs
from cone_perception.evaluation.groundtruth import load_ground_truth, pair_with_predictions
from cone_perception.evaluation.metrics import ImageDetections, coco_map, operating_point
from cone_perception.geometry import apply_homography
from cone_perception.geometry.calib import load_calibration
from cone_perception.mapping import ConeMapper
from cone_perception.records import CONE_DTYPE, boxes_from_arrays

W, H = 1920, 1080
# (class, x_m, y_m): a straight track 3 m wide, pairs at 3, 5.5, 10 and 18 m, plus two orange cones
CONES = [
    (BLUE, 3.0, 1.5), (YELLOW, 3.0, -1.5),
    (BLUE, 5.5, 1.5), (YELLOW, 5.5, -1.5),
    (BLUE, 10.0, 1.5), (YELLOW, 10.0, -1.5),
    (BLUE, 18.0, 1.5), (YELLOW, 18.0, -1.5),
    (ORANGE, 4.5, -2.5), (LARGE_ORANGE, 8.0, 2.6),
]


def scene_boxes(calib, cones=CONES) -> np.ndarray:
    """(N, 4) full-image boxes whose class foot point maps exactly to each cone's position."""
    mapper = ConeMapper(calib)
    cls = np.array([c for c, _, _ in cones])
    xy = np.array([[x, y] for _, x, y in cones], dtype=np.float64)
    foot = mapper.box_foot_of(xy, cls)
    w = 1200.0 / xy[:, 0]  # px, shrinking with range
    u1, u2 = mapper.box_u_range(foot[:, 0], w, cls)
    return np.column_stack([u1, foot[:, 1] - 1.3 * w, u2, foot[:, 1]])


def box_rows(boxes, classes, scores=None, scale=(1.0, 1.0)):
    s = np.ones(len(boxes)) if scores is None else scores
    b = np.asarray(boxes) * np.array([scale[0], scale[1], scale[0], scale[1]])
    return [[*map(float, bb), float(sc), int(c)] for bb, sc, c in zip(b, s, classes)]


@pytest.fixture(scope="module")
def calib():
    return load_calibration("example_mainhoop")


@pytest.fixture(scope="module")
def scene(calib):
    boxes = scene_boxes(calib)
    assert np.all(boxes[:, :2] >= 0) and np.all(boxes[:, 2] <= W) and np.all(boxes[:, 3] <= H)
    return boxes, np.array([c for c, _, _ in CONES])


def write_gt_jsonl(path: Path, frames: dict[str, tuple[np.ndarray, np.ndarray]], extra_small: bool = False) -> Path:
    with open(path, "w") as fh:
        for name, (boxes, classes) in frames.items():
            cones = [{"class_id": int(c), "x_m": x, "y_m": y, "distance_m": float(np.hypot(x, y)), "box": [float(v) for v in b],
                      "visible_fraction": 1.0} for b, (c, x, y) in zip(boxes, CONES)]
            if extra_small:  # a far cone the labels leave out: 3 px box
                cones.append({"class_id": BLUE, "x_m": 25.0, "y_m": 1.5, "distance_m": 25.04, "box": [1000.0, 500.0, 1003.0, 503.0],
                              "visible_fraction": 1.0})
            fh.write(json.dumps({"image": name, "width": W, "height": H, "track": {}, "pose": {}, "cones": cones}) + "\n")
    return path


def write_pred(path: Path, frames: dict[str, list], size=(W, H)) -> Path:
    with open(path, "w") as fh:
        for name, rows in frames.items():
            fh.write(json.dumps({"image": name, "width": size[0], "height": size[1], "boxes": rows}) + "\n")
    return path


def dets(gt_boxes, gt_cls, pred_boxes, pred_cls, scores=None, ignore=None):
    s = np.ones(len(pred_boxes)) if scores is None else np.asarray(scores, float)
    return ImageDetections(np.asarray(gt_boxes, float).reshape(-1, 4), np.asarray(gt_cls), np.asarray(pred_boxes, float).reshape(-1, 4),
                           s, np.asarray(pred_cls), None if ignore is None else np.asarray(ignore, bool))


# ------------------------------------------------------------------ metrics by construction


def test_perfect_predictions_give_map_one_and_diagonal_confusion(scene):
    boxes, cls = scene
    im = [dets(boxes, cls, boxes, cls)]
    m = coco_map(im)
    assert m.map50 == pytest.approx(1.0) and m.map50_95 == pytest.approx(1.0)
    assert set(m.ap50_per_class) == {"blue", "yellow", "orange", "large_orange"}
    op = operating_point(im)
    cm = op.confusion
    assert np.array_equal(np.diag(cm)[:4], [4, 4, 1, 1]) and cm.sum() == 10
    a = op.scores()["all"]
    assert (a["tp"], a["fp"], a["fn"], a["precision"], a["recall"], a["f1"]) == (10, 0, 0, 1.0, 1.0, 1.0)
    assert m.pr50_per_class["blue"][-1] == pytest.approx(1.0)


def test_one_missed_box_gives_known_recall_and_background_cell(scene):
    boxes, cls = scene
    keep = np.arange(len(cls)) != 2  # the blue cone at 5.5 m is missed
    op = operating_point([dets(boxes, cls, boxes[keep], cls[keep])])
    s = op.scores()
    assert s["blue"]["recall"] == pytest.approx(3 / 4) and s["blue"]["precision"] == 1.0
    assert s["all"]["recall"] == pytest.approx(9 / 10) and s["all"]["f1"] == pytest.approx(2 * 9 / (2 * 9 + 1))
    assert op.confusion[BLUE, -1] == 1 and op.confusion[BLUE, BLUE] == 3
    m = coco_map([dets(boxes, cls, boxes[keep], cls[keep])])
    assert m.ap50_per_class["blue"] == pytest.approx(0.75, abs=0.01)  # 101-point precision 1 up to recall 0.75


def test_class_swap_lands_in_its_confusion_cell(scene):
    boxes, cls = scene
    pred = cls.copy()
    pred[0] = YELLOW  # the first blue cone called yellow
    op = operating_point([dets(boxes, cls, boxes, pred)])
    assert op.confusion[BLUE, YELLOW] == 1 and op.confusion[BLUE, BLUE] == 3
    assert op.confusion[-1].sum() == 0 and op.confusion[:, -1].sum() == 0  # matched by box whatever the class
    assert (op.tp["blue"], op.fn["blue"], op.fp["yellow"], op.tp["yellow"]) == (3, 1, 1, 4)


def test_false_positive_threshold_and_ignore_regions(scene):
    boxes, cls = scene
    fp_box = [[10, 10, 60, 80]]
    ignore_box = [[1000, 500, 1003, 503]]
    gt_b, gt_c = np.r_[boxes, ignore_box], np.r_[cls, BLUE]
    ign = np.r_[np.zeros(len(cls), bool), True]
    # all right, plus: one FP at 0.9, one low-score FP at 0.1 (below conf), one detection on the ignore box
    pb = np.r_[boxes, fp_box, fp_box, [[999, 499, 1003, 503]]]
    pc = np.r_[cls, ORANGE, BLUE, BLUE]
    ps = np.r_[np.full(len(cls), 0.95), 0.9, 0.1, 0.95]
    im = [dets(gt_b, gt_c, pb, pc, ps, ign)]
    op = operating_point(im, conf=0.25)
    assert op.confusion[-1, ORANGE] == 1 and op.confusion[-1].sum() == 1  # only the 0.9 FP; ignore-box hit not counted
    assert op.fn["blue"] == 0 and op.scores()["all"]["precision"] == pytest.approx(10 / 11)
    m = coco_map(im)
    assert m.num_gt == 10
    assert m.ap50_per_class["blue"] == pytest.approx(1.0)  # the blue FP scores below every true blue
    assert m.ap50_per_class["orange"] == pytest.approx(1.0)  # the orange FP (0.9) ranks below the true orange (0.95)
    # a correct detection below conf is a miss at the operating point, but mAP keeps it
    ps2 = np.r_[np.full(len(cls) - 1, 0.95), 0.1]
    im2 = [dets(boxes, cls, boxes, cls, ps2)]
    assert operating_point(im2, conf=0.25).fn["large_orange"] == 1
    assert coco_map(im2).map50 == pytest.approx(1.0)


def test_blue_yellow_pairs_and_pair_error():
    truth = np.zeros(5, CONE_DTYPE)
    truth["x"], truth["y"] = [5, 5, 10, 10, 30], [1.5, -1.5, 1.5, -1.5, 1.5]
    truth["class_id"] = [BLUE, YELLOW, BLUE, YELLOW, BLUE]
    pairs = blue_yellow_pairs(truth)
    assert [(b, y) for b, y, _ in pairs] == [(0, 1), (2, 3)]  # the lone blue at 30 m has no yellow within 6 m
    assert pairs[0][2] == pytest.approx(3.0)
    pred = truth.copy()
    pred["y"][3] -= 0.5  # the yellow at 10 m measured 0.5 m too far right
    rep = PairDistanceReport()
    rep.add_frame(pred, truth, [(i, i, 0.0) for i in range(4)])  # cone 4 not detected
    s = rep.summary()
    assert s["groups"]["mid 4-7 m"]["median_err_m"] == pytest.approx(0.0)
    assert s["groups"]["far 7-15 m"]["median_err_m"] == pytest.approx(0.5)
    assert s["all"]["n_pairs"] == 2 and s["all"]["n_measured"] == 2


# ------------------------------------------------------------------ the command, both formats


def run_eval(*args) -> int:
    return main(["eval", "--no-progress", *map(str, args)])


def test_eval_gt_jsonl_perfect_predictions(tmp_path, calib, scene, capsys):
    boxes, cls = scene
    gt = write_gt_jsonl(tmp_path / "gt.jsonl", {"images/val/000000.jpg": (boxes, cls), "images/val/000001.jpg": (boxes, cls)}, extra_small=True)
    pred = write_pred(tmp_path / "pred.jsonl", {"000000.jpg": box_rows(boxes, cls), "val/000001.jpg": box_rows(boxes, cls)})
    out = tmp_path / "report"
    assert run_eval("--pred", pred, "--gt", gt, "--calib", "example_mainhoop", "--out", out) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["inputs"]["gt_boxes"] == 20 and m["inputs"]["gt_ignored_boxes"] == 2
    assert m["detection"]["map50"] == pytest.approx(1.0) and m["detection"]["map50_95"] == pytest.approx(1.0)
    groups = m["by_distance"]["groups"]
    assert [g["num_gt"] for g in groups.values()] == [4, 6, 6, 4]  # 3 m pair | 5.5 m pair + orange | 10 m pair + large | 18 m pair
    assert all(g["map50"] == pytest.approx(1.0) for g in groups.values())
    loc = m["localisation"]
    assert loc["all"]["recall"] == 1.0 and loc["all"]["median_err_m"] < 0.01  # boxes rounded to 0.01 px in the file
    pd = m["pair_distance"]
    assert pd["all"]["n_pairs"] == 8 and pd["all"]["n_measured"] == 8 and pd["all"]["median_abs_err_m"] < 0.01
    for f in ("report.md", "confusion_matrix.png", "pr_curves.png", "detection_by_distance.png", "localisation_boxplots.png", "pair_distance_error.png"):
        assert (out / f).stat().st_size > 1000, f
    report = (out / "report.md").read_text()
    assert "](pr_curves.png)" in report and "thesis metric" in report
    assert "mAP@0.5 1.000" in capsys.readouterr().out


def test_max_range_leaves_farther_cones_out_of_the_score(tmp_path, scene, capsys):
    boxes, cls = scene
    gt = write_gt_jsonl(tmp_path / "gt.jsonl", {"images/val/000000.jpg": (boxes, cls)})
    far = [i for i, (_, x, y) in enumerate(CONES) if np.hypot(x, y) > 15.0]
    assert len(far) == 2  # the 18 m pair
    keep = [i for i in range(len(CONES)) if i != far[0]]  # the blue 18 m cone missed, the yellow one found
    pred = write_pred(tmp_path / "pred.jsonl", {"000000.jpg": box_rows(boxes[keep], cls[keep])})
    assert run_eval("--pred", pred, "--gt", gt, "--calib", "example_mainhoop", "--out", tmp_path / "all") == 0
    m = json.loads((tmp_path / "all" / "metrics.json").read_text())
    assert m["inputs"]["gt_boxes"] == 10 and m["detection"]["map50"] < 0.99
    assert run_eval("--pred", pred, "--gt", gt, "--calib", "example_mainhoop", "--out", tmp_path / "near",
                    "--max-range", "15") == 0
    m = json.loads((tmp_path / "near" / "metrics.json").read_text())
    # the 18 m pair is an ignore region: its miss is no miss, its detection is not false
    assert m["inputs"]["gt_boxes"] == 8 and m["ground_truth"]["ignored_beyond_max_range"] == 2
    assert m["detection"]["map50"] == pytest.approx(1.0)
    op = m["detection"]["operating_point"]["per_class"]["all"]
    assert (op["tp"], op["fp"], op["fn"]) == (8, 0, 0)
    assert "beyond --max-range" in (tmp_path / "near" / "report.md").read_text()
    capsys.readouterr()
    # YOLO labels carry no cone positions: refused, naming the option
    root = tmp_path / "yolo"
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    (root / "images" / "000000.jpg").write_bytes(b"")
    (root / "labels" / "000000.txt").write_text("0 0.5 0.5 0.1 0.1\n")
    (root / "data.yaml").write_text("names: [blue, yellow, orange, large_orange, unknown]\n")
    assert run_eval("--pred", pred, "--gt", root, "--out", tmp_path / "yolo_out", "--max-range", "15") != 0
    assert "--max-range: the ground truth of 000000.jpg has no cone positions" in capsys.readouterr().err
    assert run_eval("--pred", pred, "--gt", gt, "--out", tmp_path / "bad", "--max-range", "0") != 0
    assert "--max-range: needs a range > 0 m, got 0" in capsys.readouterr().err


def test_eval_gt_jsonl_localisation_error_is_measured(tmp_path, calib, scene):
    boxes, cls = scene
    gt = write_gt_jsonl(tmp_path / "gt.jsonl", {"f0": (boxes, cls)})
    (tmp_path / "calib.yaml").write_text(Path(calib.source).read_text())  # found beside gt.jsonl
    moved = boxes.copy()
    moved[1, [1, 3]] += 20.0  # the yellow cone at 3 m: foot point 20 px lower -> nearer and still IoU > 0.5
    pred = write_pred(tmp_path / "pred.jsonl", {"f0": box_rows(moved, cls)})
    out = tmp_path / "r"
    assert run_eval("--pred", pred, "--gt", gt, "--out", out) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["inputs"]["calibration"].endswith("calib.yaml")
    mapper = ConeMapper(calib)  # where the car puts the true and the moved box
    c0 = mapper.map_boxes(boxes_from_arrays(boxes[1:2], [1.0], cls[1:2]))[0]
    c1 = mapper.map_boxes(boxes_from_arrays(moved[1:2], [1.0], cls[1:2]))[0]
    x0, y0, x1, y1 = float(c0["x"]), float(c0["y"]), float(c1["x"]), float(c1["y"])
    assert np.hypot(x0 - 3.0, y0 + 1.5) < 1e-3  # the true box maps onto the true cone
    want = float(np.hypot(x1 - x0, y1 - y0))
    near = m["localisation"]["groups"]["near 0-4 m"]
    assert near["n_matched"] == 2 and near["p90_err_m"] == pytest.approx(0.8 * want, abs=0.02)  # p90 of [0, want]
    pair = m["pair_distance"]["groups"]["near 0-4 m"]
    true_d, meas_d = 3.0, float(np.hypot(x1 - 3.0, y1 - 1.5))
    assert pair["median_err_m"] == pytest.approx(meas_d - true_d, abs=0.01)


def write_yolo(root: Path, frames: dict[str, tuple[np.ndarray, np.ndarray]], names: list[str] | None, size=(W, H)) -> Path:
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    ids = {c: i for i, c in enumerate([YELLOW, BLUE, LARGE_ORANGE, ORANGE])}  # the dataset's own order
    for name, (boxes, classes) in frames.items():
        (root / "images" / f"{name}.jpg").write_bytes(b"")  # only the name is used
        lines = []
        for (u1, v1, u2, v2), c in zip(boxes, classes):
            lines.append(f"{ids[c]} {(u1 + u2) / 2 / size[0]:.6f} {(v1 + v2) / 2 / size[1]:.6f} {(u2 - u1) / size[0]:.6f} {(v2 - v1) / size[1]:.6f}")
        (root / "labels" / f"{name}.txt").write_text("\n".join(lines) + "\n")
    if names:
        (root / "data.yaml").write_text(json.dumps({"names": names}))
    return root


def test_eval_yolo_folder_names_by_name_scaled_size_and_calib_distances(tmp_path, scene):
    boxes, cls = scene
    root = write_yolo(tmp_path / "ds", {"a": (boxes, cls), "b": (boxes, cls)}, ["yellow_cone", "blue_cone", "large_orange_cone", "orange_cone"])
    swapped = cls.copy()
    swapped[0] = YELLOW
    # predictions at half size (640x360 would squeeze; 960x540 keeps the aspect): labels scale with it
    pred = write_pred(tmp_path / "p.jsonl", {"a.jpg": box_rows(boxes, cls, scale=(0.5, 0.5)), "b.jpg": box_rows(boxes, swapped, scale=(0.5, 0.5))},
                      size=(W // 2, H // 2))
    out = tmp_path / "r"
    assert run_eval("--pred", pred, "--gt", root, "--calib", "example_mainhoop", "--out", out) == 0
    m = json.loads((out / "metrics.json").read_text())
    cm = np.array(m["detection"]["operating_point"]["confusion"]["rows_true_cols_pred"])
    assert cm[BLUE, YELLOW] == 1 and cm[BLUE, BLUE] == 7 and cm[YELLOW, YELLOW] == 8 and cm[ORANGE, ORANGE] == 2
    assert m["detection"]["operating_point"]["per_class"]["blue"]["recall"] == pytest.approx(7 / 8)
    assert "localisation" not in m  # YOLO labels carry no positions
    assert [g["num_gt"] for g in m["by_distance"]["groups"].values()] == [4, 6, 6, 4]  # from foot points: as from the true ranges
    assert m["by_distance"]["distance_from"].startswith("foot points")


def test_both_formats_give_the_same_detection_metrics(tmp_path, scene):
    boxes, cls = scene
    rng = np.random.default_rng(0)
    frames = {f"{k:03d}": (boxes, cls) for k in range(3)}
    gt = write_gt_jsonl(tmp_path / "gt.jsonl", frames)
    root = write_yolo(tmp_path / "ds", frames, ["yellow", "blue", "large_orange", "orange"])
    rows = {}
    for k, name in enumerate(frames):
        noisy = boxes + rng.normal(0, 4.0, boxes.shape)
        keep = rng.random(len(cls)) > 0.2
        rows[f"{name}.jpg"] = box_rows(noisy[keep], cls[keep], rng.uniform(0.3, 1.0, keep.sum()))
    pred = write_pred(tmp_path / "p.jsonl", rows)
    a, b = tmp_path / "a", tmp_path / "b"
    assert run_eval("--pred", pred, "--gt", gt, "--out", a) == 0
    assert run_eval("--pred", pred, "--gt", root, "--out", b) == 0
    ma, mb = (json.loads((d / "metrics.json").read_text())["detection"] for d in (a, b))
    assert 0.3 < ma["map50"] < 1.0
    assert ma["map50"] == pytest.approx(mb["map50"], abs=1e-4) and ma["map50_95"] == pytest.approx(mb["map50_95"], abs=1e-3)
    assert ma["operating_point"]["confusion"] == mb["operating_point"]["confusion"]


# ------------------------------------------------------------------ bad input


def test_bad_prediction_lines_name_file_and_line(tmp_path, scene, capsys):
    boxes, cls = scene
    gt = write_gt_jsonl(tmp_path / "gt.jsonl", {"x": (boxes, cls)})
    good = json.dumps({"image": "x", "width": W, "height": H, "boxes": []})
    cases = {
        "not json": "{oops",
        "keys": json.dumps({"image": "x", "boxes": []}),
        "row": json.dumps({"image": "x", "width": W, "height": H, "boxes": [[1, 2, 3], [4, 5, 6]]}),
        "class": json.dumps({"image": "x", "width": W, "height": H, "boxes": [[1, 2, 3, 4, 0.5, 9]]}),
        "size": json.dumps({"image": "x", "width": "big", "height": H, "boxes": []}),
    }
    for what, line in cases.items():
        p = tmp_path / f"{what.replace(' ', '_')}.jsonl"
        p.write_text("\n" + line + "\n" + good + "\n")
        assert run_eval("--pred", p, "--gt", gt, "--out", tmp_path / "o") == 2, what
        err = capsys.readouterr().err
        assert f"{p}: line 2:" in err, (what, err)


def test_predictions_and_ground_truth_for_different_images(tmp_path, scene, capsys):
    boxes, cls = scene
    gt = write_gt_jsonl(tmp_path / "gt.jsonl", {"a": (boxes, cls), "b": (boxes, cls)})
    stranger = write_pred(tmp_path / "s.jsonl", {"a": [], "zzz": []})
    assert run_eval("--pred", stranger, "--gt", gt, "--out", tmp_path / "o") == 2
    assert "s.jsonl: line 2: image 'zzz' is not in the ground truth" in capsys.readouterr().err
    twice = tmp_path / "t.jsonl"
    twice.write_text("".join(json.dumps({"image": n, "width": W, "height": H, "boxes": []}) + "\n" for n in ("a", "b", "a")))
    assert run_eval("--pred", twice, "--gt", gt, "--out", tmp_path / "o") == 2
    assert "line 3: image 'a' was already predicted on line 1" in capsys.readouterr().err
    partial = write_pred(tmp_path / "p.jsonl", {"a": box_rows(boxes, cls)})
    assert run_eval("--pred", partial, "--gt", gt, "--out", tmp_path / "o") == 2
    err = capsys.readouterr().err
    assert "has no line for 1 of 2 ground-truth images" in err and "(e.g. b)" in err and "--only-predicted" in err
    assert run_eval("--pred", partial, "--gt", gt, "--out", tmp_path / "o", "--only-predicted") == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["inputs"]["images"] == 1 and m["ground_truth"]["gt_images_not_predicted"] == 1


def test_missing_files_and_bad_ground_truth(tmp_path, scene, capsys):
    boxes, cls = scene
    gt = write_gt_jsonl(tmp_path / "gt.jsonl", {"a": (boxes, cls)})
    pred = write_pred(tmp_path / "p.jsonl", {"a": []})
    assert run_eval("--pred", tmp_path / "nope.jsonl", "--gt", gt, "--out", tmp_path / "o") == 2
    assert "nope.jsonl: prediction file not found" in capsys.readouterr().err
    assert run_eval("--pred", pred, "--gt", tmp_path / "nogt", "--out", tmp_path / "o") == 2
    assert "nogt: ground truth not found" in capsys.readouterr().err
    bad = tmp_path / "bad_gt.jsonl"
    bad.write_text(gt.read_text() + json.dumps({"image": "b", "width": W, "height": H, "cones": [{"class_id": 0, "box": [1, 2]}]}) + "\n")
    assert run_eval("--pred", pred, "--gt", bad, "--out", tmp_path / "o") == 2
    assert "bad_gt.jsonl: line 2: cones[0]:" in capsys.readouterr().err
    root = write_yolo(tmp_path / "ds", {"a": (boxes, cls)}, None)
    assert run_eval("--pred", pred, "--gt", root, "--out", tmp_path / "o") == 2
    assert "--gt-names" in capsys.readouterr().err
    assert run_eval("--pred", pred, "--gt", root, "--out", tmp_path / "o", "--gt-names", "yellow,blue,large_orange,orange") == 0
    assert run_eval("--pred", pred, "--gt", root, "--out", tmp_path / "o", "--gt-names", "yellow,purple,large_orange,orange") == 2
    assert "purple" in capsys.readouterr().err
    g = load_ground_truth(write_yolo(tmp_path / "ds2", {"a": (boxes, cls)}, ["yellow", "blue", "large_orange", "orange"]))
    g.images.append(g.images[0].__class__("images/other/a.jpg", None, None, g.images[0].boxes, g.images[0].class_ids, g.images[0].ignore))
    with pytest.raises(ConfigError, match="matches several"):
        pair_with_predictions(g, list(read_predictions(pred)), str(pred))


def test_eval_gt_jsonl_scaled_predictions_and_false_positive_group(tmp_path, calib, scene):
    """Predictions at half size still localise exactly; a detection on no cone is false only in its own group."""
    boxes, cls = scene
    gt = write_gt_jsonl(tmp_path / "gt.jsonl", {"f0": (boxes, cls)})
    fp_box = scene_boxes(calib, [(ORANGE, 2.5, 0.0)])  # an orange cone that is not there, 2.5 m ahead
    rows = box_rows(np.r_[boxes, fp_box], np.r_[cls, ORANGE], scale=(0.5, 0.5))
    pred = write_pred(tmp_path / "p.jsonl", {"f0": rows}, size=(W // 2, H // 2))
    out = tmp_path / "r"
    assert run_eval("--pred", pred, "--gt", gt, "--calib", calib.source, "--out", out) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["ground_truth"]["size_mismatch_scaled"] == 1
    groups = {k: g["operating_point"]["per_class"]["all"] for k, g in m["by_distance"]["groups"].items()}
    assert (groups["near 0-4 m"]["tp"], groups["near 0-4 m"]["fp"]) == (2, 1)
    assert all(g["fp"] == 0 and g["recall"] == 1.0 for k, g in groups.items() if k != "near 0-4 m")
    assert m["localisation"]["all"]["median_err_m"] < 0.02 and m["localisation"]["false_positives"] == 1


def test_yolo_folder_with_split_subfolders(tmp_path, scene, capsys):
    boxes, cls = scene
    names = ["yellow", "blue", "large_orange", "orange"]
    for split, frame in (("train", "t0"), ("val", "v0")):
        write_yolo(tmp_path / split, {frame: (boxes, cls)}, None)
    root = tmp_path / "ds"
    for sub in ("images", "labels"):
        for split in ("train", "val"):
            (root / sub).mkdir(parents=True, exist_ok=True)
            (tmp_path / split / sub).rename(root / sub / split)
    (root / "data.yaml").write_text(json.dumps({"names": names}))
    g = load_ground_truth(root)
    assert sorted(i.image for i in g.images) == ["images/train/t0.jpg", "images/val/v0.jpg"]
    pred = write_pred(tmp_path / "p.jsonl", {"val/v0.jpg": box_rows(boxes, cls)})
    assert run_eval("--pred", pred, "--gt", root, "--out", tmp_path / "o") == 2
    assert "images/train/t0.jpg" in capsys.readouterr().err
    assert run_eval("--pred", pred, "--gt", root, "--out", tmp_path / "o", "--only-predicted") == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["detection"]["map50"] == pytest.approx(1.0) and m["inputs"]["gt_boxes"] == 10
    assert "by_distance" not in m  # no positions, no calibration


def test_recall_by_box_height_at_the_model_input():
    from cone_perception.evaluation.groundtruth import EvalImage
    from cone_perception.evaluation.report import recall_by_box_height

    hs = np.array([12.0, 20.0, 40.0, 60.0, 120.0])  # image px; at input_scale 0.5: 6, 10, 20, 30, 60 px
    gt = np.column_stack([np.arange(5) * 200.0, np.full(5, 100.0), np.arange(5) * 200.0 + 40, 100.0 + hs])
    found = np.array([True, False, True, False, True])

    def image(scale):
        return EvalImage("a", W, H, gt, np.full(5, BLUE), np.zeros(5, bool), None, gt[found], np.ones(3), np.full(3, BLUE), scale)

    r = recall_by_box_height([image(0.5)], 0.25, 0.5)
    assert r["unit"] == "model input px"
    assert [(b["num_gt"], b["tp"]) for b in r["bins"].values()] == [(1, 1), (1, 0), (1, 1), (1, 0), (1, 1)]
    big = r["at_least_min_height"]
    assert (big["num_gt"], big["tp"], big["fn"]) == (3, 2, 1) and big["recall"] == pytest.approx(2 / 3)
    r = recall_by_box_height([image(None)], 0.25, 0.5)  # no input_scale: heights in image px
    assert r["unit"].startswith("image px")
    assert r["at_least_min_height"]["recall"] == pytest.approx(3 / 5)


def test_recall_by_box_height_in_image_px():
    """Issue 26: recall by box height at the ground-truth image's own scale (the unit names it), in the
    small-cone bins, whatever the prediction file's input_scale."""
    from cone_perception.evaluation.groundtruth import EvalImage
    from cone_perception.evaluation.report import IMAGE_HEIGHT_BINS, recall_by_box_height

    hs = np.array([5.0, 8.0, 10.0, 15.0, 30.0])
    gt = np.column_stack([np.arange(5) * 200.0, np.full(5, 100.0), np.arange(5) * 200.0 + 10, 100.0 + hs])
    found = np.array([True, False, True, False, True])
    im = EvalImage("a", W, H, gt, np.full(5, BLUE), np.zeros(5, bool), None, gt[found], np.ones(3), np.full(3, BLUE), 0.5)
    r = recall_by_box_height([im], 0.25, 0.5, IMAGE_HEIGHT_BINS, image_px=True)
    assert r["unit"] == f"image px of the {W}x{H} images"
    assert list(r["bins"]) == ["0-6 px", "6-9 px", "9-12 px", "12-20 px", ">= 20 px"]
    assert [(b["num_gt"], b["recall"]) for b in r["bins"].values()] == [(1, 1.0), (1, 0.0), (1, 1.0), (1, 0.0), (1, 1.0)]


def test_prediction_input_scale_round_trip_and_bad_value(tmp_path):
    from cone_perception.data.predictions import prediction_line

    boxes = boxes_from_arrays(np.array([[1.0, 2.0, 3.0, 4.0]]), np.array([0.9]), np.array([BLUE]))
    p = tmp_path / "p.jsonl"
    p.write_text(prediction_line("a.jpg", 640, 360, boxes, input_scale=1.5) + "\n" + prediction_line("b.jpg", 640, 360, boxes) + "\n")
    a, b = read_predictions(p)
    assert a.input_scale == pytest.approx(1.5) and b.input_scale is None
    p.write_text(json.dumps({"image": "a", "width": 4, "height": 4, "boxes": [], "input_scale": -1}) + "\n")
    with pytest.raises(ConfigError, match="line 1.*input_scale"):
        list(read_predictions(p))


def test_prediction_far_marks_round_trip_and_bad_values(tmp_path):
    """The `far` key (which boxes the far strip drew) survives a round trip; indices out of range, repeated or not
    integers are refused naming the line."""
    from cone_perception.data.predictions import prediction_line

    boxes = boxes_from_arrays(np.array([[1.0, 2.0, 3.0, 4.0]] * 3), np.array([0.9, 0.8, 0.7]), np.array([BLUE] * 3))
    p = tmp_path / "p.jsonl"
    p.write_text(prediction_line("a.jpg", 640, 360, boxes, far=np.array([False, True, True])) + "\n"
                 + prediction_line("b.jpg", 640, 360, boxes) + "\n")
    a, b = read_predictions(p)
    assert a.far.tolist() == [False, True, True] and b.far is None
    for bad in ([3], [1, 1], [0.5], "1", [True]):
        p.write_text(json.dumps({"image": "a", "width": 4, "height": 4, "boxes": [[1, 1, 2, 2, 0.9, 0]] * 3,
                                 "far": bad}) + "\n")
        with pytest.raises(ConfigError, match="line 1.*far"):
            list(read_predictions(p))


def test_eval_band_clips_cut_cones_and_ignores_those_outside(tmp_path, capsys):
    """`eval --band`: a detector that sees only the band, boxes clipped there as training clips them."""
    from cone_perception.evaluation.groundtruth import EvalImage, restrict_to_band

    band = (300, 700)
    gt = np.array([
        [100, 400, 140, 460],  # inside: found
        [300, 660, 360, 760],  # 40 % inside, cut by the band's bottom: found as its visible part (660-700)
        [500, 680, 560, 780],  # 20 % inside: not visible to the car -> ignore region
        [700, 800, 760, 880],  # wholly below the band -> ignore region
        [900, 500, 930, 540],  # inside: missed
    ], float)
    cls = np.full(5, BLUE)
    seen = np.array([[100, 400, 140, 460], [300, 660, 360, 700]], float)

    # library: clipped boxes and ignore flags
    im = EvalImage("a", W, H, gt, cls, np.zeros(5, bool), None, seen, np.ones(2), np.full(2, BLUE))
    (out,), n = restrict_to_band([im], band)
    assert n == 2 and out.gt_ignore.tolist() == [False, False, True, True, False]
    assert out.gt_boxes[1].tolist() == [300, 660, 360, 700] and out.gt_boxes[0].tolist() == gt[0].tolist()
    with pytest.raises(ValueError, match="band rows"):
        restrict_to_band([im], (700, 300))

    # command: without --band the cut cones are misses; with it, recall 2 / 3
    root = tmp_path / "ds"
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    (root / "images" / "a.jpg").write_bytes(b"")
    (root / "labels" / "a.txt").write_text("".join(
        f"0 {(b[0] + b[2]) / 2 / W:.6f} {(b[1] + b[3]) / 2 / H:.6f} {(b[2] - b[0]) / W:.6f} {(b[3] - b[1]) / H:.6f}\n" for b in gt))
    pred = write_pred(tmp_path / "p.jsonl", {"a.jpg": box_rows(seen, [BLUE, BLUE])})
    for extra, n_gt, recall in (([], 5, 1 / 5), (["--band", "300,700"], 3, 2 / 3)):
        out_dir = tmp_path / f"r{len(extra)}"
        assert run_eval("--pred", pred, "--gt", root, "--gt-names", "blue_cone", "--out", out_dir, *extra) == 0
        m = json.loads((out_dir / "metrics.json").read_text())
        assert m["inputs"]["gt_boxes"] == n_gt
        assert m["detection"]["operating_point"]["per_class"]["all"]["recall"] == pytest.approx(recall)
    assert m["ground_truth"]["band_rows"] == [300, 700] and m["ground_truth"]["ignored_outside_band"] == 2
    assert "outside the band" in (out_dir / "report.md").read_text()
    capsys.readouterr()
    with pytest.raises(SystemExit):
        run_eval("--pred", pred, "--gt", root, "--out", tmp_path / "bad", "--band", "700,300")
    assert "V0 < V1" in capsys.readouterr().err


def test_min_height_scores_cones_as_coco_scores_an_area_range():
    from cone_perception.evaluation.groundtruth import EvalImage, restrict_to_min_height

    # image px; input_scale 0.5 -> heights at the model input 30, 10, 25 px
    gt = np.array([[0, 0, 40, 60], [100, 0, 110, 20], [200, 0, 230, 50]], float)
    pred = np.array([
        [0, 0, 40, 60],       # big cone found
        [100, 0, 110, 20],    # on the small cone: dropped (its cone is ignored)
        [200, 2, 230, 48],    # 23 px at the input, cone 25 px: kept
        [500, 0, 505, 10],    # small, on nothing (an unlabelled far cone): dropped
        [200, 0, 230, 23.5],  # small (11.75 px), on the kept cone but IoU < 0.5: dropped
    ], float)
    im = EvalImage("a", W, H, gt, np.full(3, BLUE), np.zeros(3, bool), None, pred, np.ones(5), np.full(5, BLUE), 0.5)
    (out,), n_gt, n_pred = restrict_to_min_height([im], 24.0)
    assert out.gt_ignore.tolist() == [False, True, False] and n_gt == 1 and n_pred == 3
    assert out.pred_boxes.tolist() == [pred[0].tolist(), pred[2].tolist()]
    # a small detection that matches a kept cone is kept (COCO: matched before the range applies)
    im2 = replace(im, pred_boxes=pred[[0, 2]], pred_scores=np.ones(2), pred_classes=np.full(2, BLUE))
    (out2,), _, dropped = restrict_to_min_height([im2], 24.0)
    assert dropped == 0 and len(out2.pred_boxes) == 2
    (out3,), n_gt3, _ = restrict_to_min_height([replace(im, input_scale=None)], 24.0)  # image px
    assert out3.gt_ignore.tolist() == [False, True, False] and n_gt3 == 1
    with pytest.raises(ValueError, match="min_height"):
        restrict_to_min_height([im], 0)


def test_worst_frames_picture_ranks_frames_by_errors(tmp_path, scene):
    import cv2

    boxes, cls = scene
    root = write_yolo(tmp_path / "ds", {"good": (boxes, cls), "bad": (boxes, cls)}, ["yellow_cone", "blue_cone", "large_orange_cone", "orange_cone"])
    for name in ("good", "bad"):
        cv2.imwrite(str(root / "images" / f"{name}.jpg"), np.full((H // 4, W // 4, 3), 90, np.uint8))  # other size: boxes scale
    pred = write_pred(tmp_path / "p.jsonl", {"good.jpg": box_rows(boxes, cls), "bad.jpg": box_rows(boxes[:7], cls[:7]) + [[5, 5, 50, 50, 0.9, BLUE]]})
    out = tmp_path / "r"
    assert run_eval("--pred", pred, "--gt", root, "--out", out, "--worst", "3") == 0
    report = (out / "report.md").read_text()
    assert "| bad.jpg | 3 | 1 | 7 |" in report and "| good.jpg" not in report  # a frame without errors is not shown
    img = cv2.imread(str(out / "worst_frames.jpg"))
    assert img is not None and img.shape[1] == 2 * 960
    m = json.loads((out / "metrics.json").read_text())
    assert m["detection"]["operating_point"]["per_class"]["all"]["fn"] == 3
    assert run_eval("--pred", pred, "--gt", root, "--out", tmp_path / "r0", "--worst", "0") == 0
    assert not (tmp_path / "r0" / "worst_frames.jpg").exists()
    # --min-height through the command: 12 px at the (unscaled) image keeps every cone of this scene
    assert run_eval("--pred", pred, "--gt", root, "--out", tmp_path / "mh", "--min-height", "12", "--worst", "0") == 0
    mh = json.loads((tmp_path / "mh" / "metrics.json").read_text())
    assert mh["ground_truth"]["min_height_px"] == 12 and mh["inputs"]["gt_boxes"] == m["inputs"]["gt_boxes"]
    assert run_eval("--pred", pred, "--gt", root, "--out", tmp_path / "mh0", "--min-height", "0") == 2
