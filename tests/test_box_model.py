"""The detector's box model (issue 27): measured from matched boxes (eval --box-model-out), stored beside
the model file, read by the image fit; the fit's fallback to the calibration's H; map --boxes over a
prediction file of many frames."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
import yaml

from cone_perception.attitude import DEFAULT_BOX_MODEL, BoxModel, ImageAttitudeConfig
from cone_perception.detector.model_files import box_model_or_default, box_model_path, read_box_model, write_box_model
from cone_perception.errors import ConfigError
from cone_perception.evaluation.boxfit import measure_box_model
from cone_perception.evaluation.groundtruth import EvalImage
from cone_perception.geometry.calib import save_calibration
from cone_perception.mapping import ConeMapper

from test_attitude import CONES_CLS, CONES_XY, _calib, _cone_boxes, _tilted_camera

TOP, BOTTOM = 0.03, 0.01  # the constructed detector: tops 3 % of the height low, bottoms 1 % high


def _shrunk(labels: np.ndarray, top: float = TOP, bottom: float = BOTTOM) -> np.ndarray:
    """Detector boxes that stand for ``labels``: tops ``top``, bottoms ``bottom`` of the height inside."""
    d = np.array(labels, dtype=np.float64)
    h = d[:, 3] - d[:, 1]
    d[:, 1] += top * h
    d[:, 3] -= bottom * h
    return d


def _image(labels: np.ndarray, classes: np.ndarray, preds: np.ndarray, scale: float = 0.5) -> EvalImage:
    n = len(labels)
    return EvalImage("f.jpg", 1920, 1080, labels, classes, np.zeros(n, bool), None, preds, np.full(len(preds), 0.9),
                     classes[: len(preds)], scale)


def test_measurement_recovers_a_known_shrink():
    rng = np.random.default_rng(3)
    images = []
    for _ in range(20):
        n = 12
        h = rng.uniform(18.0, 160.0, n)  # image px; model input px is half of it
        u = rng.uniform(50, 1800, n)
        v = rng.uniform(150, 600, n)
        labels = np.column_stack([u, v, u + 0.7 * h, v + h])
        cls = rng.integers(0, 4, n)
        images.append(_image(labels, cls, _shrunk(labels)))
    # a cone cut by the band (its top above row 96) and matched: left out of the measurement
    cut = np.array([[100.0, 60.0, 140.0, 160.0]])
    images.append(_image(cut, np.array([0]), _shrunk(cut, 0.3, 0.0)))
    bm = measure_box_model(images, conf=0.25, iou=0.5, band=(96, 672))
    have = np.asarray(bm.counts) > 0
    whole = sum(int(((im.gt_boxes[:, 1] > 97) & (im.gt_boxes[:, 3] < 671)).sum()) for im in images)
    assert have.sum() >= 3 and 150 < sum(bm.counts) == whole - 0  # the cut cone is not whole: not among them
    np.testing.assert_allclose(np.asarray(bm.height_ratio)[have], 1 - TOP - BOTTOM, atol=1e-9)
    np.testing.assert_allclose(np.asarray(bm.top_low)[have], TOP, atol=1e-9)
    np.testing.assert_allclose(np.asarray(bm.bottom_high)[have], BOTTOM, atol=1e-9)
    assert bm.input_scale == 0.5 and bm.source == "measured" and bm.sigma_rel < 0.01
    # its correction turns the detector's boxes back into the labels
    labels, preds = images[0].gt_boxes, images[0].pred_boxes
    np.testing.assert_allclose(bm.correct(preds), labels, atol=1e-6)


def test_measurement_without_matches_says_so():
    labels = np.array([[100.0, 200.0, 130.0, 240.0]])
    far_off = labels + [500.0, 0.0, 500.0, 0.0]
    with pytest.raises(ValueError, match="nothing to measure"):
        measure_box_model([_image(labels, np.array([0]), far_off)])


def test_sidecar_round_trip_default_and_bad_file(tmp_path, caplog):
    model = tmp_path / "m.pt"
    bm = BoxModel(height_ratio=(0.9, 0.95, 0.97, 1.0), top_low=(0.05, 0.03, 0.02, 0.0), bottom_high=(0.05, 0.02, 0.01, 0.0),
                  counts=(3, 30, 20, 2), sigma_rel=0.07, input_scale=0.5, source="measured", note="test")
    write_box_model(box_model_path(model), bm, "cone-perception eval ...")
    assert read_box_model(model) == bm
    assert read_box_model(tmp_path / "m.onnx") == bm  # an export of m.pt finds m.pt's
    with caplog.at_level(logging.WARNING):
        assert box_model_or_default(tmp_path / "other.pt") is DEFAULT_BOX_MODEL
    assert "no box model" in caplog.text and "--box-model-out" in caplog.text
    box_model_path(model).write_text("box_model:\n  buckets_px: [8, 12]\n  height_ratio: [0.9]\n")
    with pytest.raises(ConfigError, match="height_ratio"):
        read_box_model(model)


@pytest.mark.parametrize("field, value, why", [
    ("buckets_px", [8.0, 8.0, 24.0, 48.0], "strictly increasing"),
    ("buckets_px", [0.0, 12.0, 24.0, 48.0], "positive"),
    ("counts", [3, 30, 20], "list of 4"),
    ("counts", [3, -1, 20, 2], "whole numbers >= 0"),
    ("counts", [3, 1.5, 20, 2], "whole numbers >= 0"),
    ("counts", [0, 0, 0, 0], "no bucket was measured"),
])
def test_a_box_model_whose_buckets_or_counts_do_not_fit_is_refused_naming_the_field(tmp_path, field, value, why):
    """Issue 41: a box model file whose buckets or counts do not fit is refused at load, naming the file and field."""
    model = tmp_path / "m.pt"
    bm = BoxModel(counts=(3, 30, 20, 2), sigma_rel=0.07, input_scale=0.5, source="measured")
    write_box_model(box_model_path(model), bm)
    doc = yaml.safe_load(box_model_path(model).read_text())
    doc["box_model"][field] = value
    box_model_path(model).write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=f"m.pt.box_model.yaml.*box_model.{field}.*{why}"):
        read_box_model(model)


@pytest.mark.parametrize("name", ["cone_detector.pt", "cone_detector_n.pt", "cone_detector_mnv2.pt"])
def test_shipped_models_have_a_measured_box_model(name):
    from cone_perception.resources import models_dir

    bm = read_box_model(models_dir() / name)
    assert bm is not None and bm.source == "measured" and sum(bm.counts) > 300
    assert all(0.85 < r < 1.05 for r in bm.height_ratio)


def _estimator(**cfg):
    return ConeMapper(_calib()).image_attitude(ImageAttitudeConfig(**cfg))


def test_box_model_takes_the_shrink_out_of_the_fit():
    """Label-like boxes of a tilted camera, shrunk as a detector does: without the box model the fit's top-row
    residuals at the true attitude are biased and the fit is pulled off; with it, neither."""
    pitch, roll = 0.8, -0.4
    labels = _cone_boxes(_tilted_camera(pitch, roll), CONES_XY, CONES_CLS)
    det = _shrunk(labels, 0.06, 0.02)
    bm = BoxModel(height_ratio=(0.92,) * 4, top_low=(0.06,) * 4, bottom_high=(0.02,) * 4, counts=(1, 1, 1, 1),
                  sigma_rel=0.03, source="measured")
    plain, modelled = _estimator(top_bias_extra_px=()), _estimator(box_model=bm)

    def residuals(est, boxes):
        b = boxes if est.cfg.box_model is None else est.cfg.box_model.correct(boxes)
        sel = est._select(b, CONES_CLS)
        rays, v_top, cls = est._prepare(b[sel], CONES_CLS[sel])
        return est.residuals(np.array([pitch, roll]), rays, v_top, cls)

    exact = np.nanmedian(residuals(plain, labels))
    biased = np.nanmedian(residuals(plain, det))
    fixed = np.nanmedian(residuals(modelled, det))
    assert biased - exact < -1.0  # tops low: the observed top row lies below the predicted one
    assert abs(fixed - exact) < 0.2
    err_plain = abs(plain.fit(det, CONES_CLS)[0][0] - pitch)
    err_model = abs(modelled.fit(det, CONES_CLS)[0][0] - pitch)
    assert err_model < 0.15 < err_plain


def test_untrusted_fits_fall_back_to_the_calibration_and_are_counted():
    est = _estimator()
    boxes = _cone_boxes(_tilted_camera(1.0, 0.0), CONES_XY, CONES_CLS)
    a = est.single_frame(boxes, CONES_CLS)
    assert a.source == "image" and est.counts.calibration == 0
    # boxes whose tops disagree with any attitude: residuals far beyond the cone model's spread
    rng = np.random.default_rng(1)
    noisy = boxes.copy()
    noisy[:, 1] += rng.normal(0.0, 15.0, len(boxes))
    b = est.single_frame(noisy, CONES_CLS)
    assert est.last_scale > est.cfg.trust_max_scale
    assert b.source == "calibration" and b.is_zero and est.counts.calibration == 1
    # a fit from too few cones for the decision
    few = _estimator(trust_min_cones=20).single_frame(boxes, CONES_CLS)
    assert few.source == "calibration"


def test_map_boxes_of_a_prediction_file_runs_one_filter_in_order(tmp_path, capsys):
    from cone_perception.cli import main

    cal_path = save_calibration(_calib(), tmp_path / "cal.yaml")
    near = slice(0, 12)
    lines = []
    for k in range(6):
        b = _cone_boxes(_tilted_camera(1.0, 0.0), CONES_XY[near], CONES_CLS[near])
        if k == 3:
            b = b[:2]  # a frame with too few cones: the filter holds
        rows = [[*map(float, bb), 0.9, int(c)] for bb, c in zip(b, CONES_CLS[near])]
        rows.append([10.0, 500.0, 12.0, 503.0, 0.05, 0])  # below --conf: not mapped
        lines.append(json.dumps({"image": f"f{k}", "width": 1920, "height": 1080, "boxes": rows}))
    pred = tmp_path / "p.jsonl"
    pred.write_text("\n".join(lines) + "\n")
    assert main(["map", "--calib", str(cal_path), "--boxes", str(pred), "--attitude", "fixed"]) == 0
    fixed = np.array([[float(v) for v in line.split(",")[1:3]] for line in capsys.readouterr().out.splitlines()[-12:]])
    assert main(["map", "--calib", str(cal_path), "--boxes", str(pred), "--attitude", "image", "--box-model", "rendered"]) == 0
    cap = capsys.readouterr()
    out = [line.split(",") for line in cap.out.splitlines()]
    assert [o[0] for o in out] == [f"f{k}" for k in range(6) for _ in range(2 if k == 3 else 12)]
    err = [line for line in cap.err.splitlines() if line.startswith("f")]
    assert len(err) == 6 and "hold" in err[3]  # the held frame keeps the filter's estimate (one filter)
    assert float(err[5].split("pitch ")[1].split()[0]) == pytest.approx(1.0, abs=0.2)
    assert "6 frames" in cap.err and "fitted 5, too_few_cones 1" in cap.err
    xy = np.array([[float(o[1]), float(o[2])] for o in out[-12:]])
    err_image, err_fixed = (np.median(np.hypot(*(p - CONES_XY[near]).T)) for p in (xy, fixed))
    assert err_image < 0.2 and err_fixed > 3 * err_image


def _two_models(tmp_path, far_top: float):
    """A band model file whose box model shifts nothing and a far model file whose boxes' tops stand ``far_top`` of
    the height low (sidecars only: the fit reads nothing else of them)."""
    band, far = tmp_path / "band.pt", tmp_path / "far.pt"
    for path, top in ((band, 0.0), (far, far_top)):
        path.write_bytes(b"")
        write_box_model(box_model_path(path), BoxModel(height_ratio=(1.0 - top,) * 4, top_low=(top,) * 4,
                                                       bottom_high=(0.0,) * 4, counts=(9, 9, 9, 9), sigma_rel=0.03,
                                                       input_scale=1.0, source="measured"), "test")
    return band, far


def test_map_boxes_reads_the_far_strips_boxes_through_the_far_model(tmp_path, capsys):
    """A prediction file's `far` key (the boxes the far strip drew, as `detect` writes it) makes `map --boxes
    --far-box-model own` read those boxes through the far model's box model, as the node does with far_box_model own:
    boxes of a far network whose tops stand 6 % low, marked, give the pitch that exact boxes give through the band's
    model; unmarked (read as the band model's), a pitch pulled off; marked but with the default far_box_model band,
    read through the band model's too, as pulled off (issue 41: the far model's own box model is opt-in)."""
    from cone_perception.cli import main

    band, far = _two_models(tmp_path, 0.06)
    cal_path = save_calibration(_calib(), tmp_path / "cal.yaml")
    exact = _cone_boxes(_tilted_camera(0.6, 0.0), CONES_XY, CONES_CLS)

    def pitch_of(boxes, marked, reading="own"):
        rows = [[*map(float, b), 0.9, int(c)] for b, c in zip(boxes, CONES_CLS)]
        doc = {"width": 1920, "height": 1080, "boxes": rows, **({"far": list(range(len(rows)))} if marked else {})}
        pred = tmp_path / "p.jsonl"
        pred.write_text("\n".join(json.dumps({**doc, "image": f"f{k}"}) for k in range(4)) + "\n")
        assert main(["map", "--calib", str(cal_path), "--boxes", str(pred), "--attitude", "image",
                     "--model", str(band), "--far-model", str(far), "--far-box-model", reading]) == 0
        err = capsys.readouterr().err
        assert f"{4 * len(rows) if marked else 0} boxes of the far strip kept" in err
        return float([ln for ln in err.splitlines() if ln.startswith("f3")][0].split("pitch ")[1].split()[0])

    reference = pitch_of(exact, False)
    assert reference == pytest.approx(0.6, abs=0.1)
    far_boxes = _shrunk(exact, 0.06, 0.0)
    assert pitch_of(far_boxes, True) == pytest.approx(reference, abs=0.02)
    assert abs(pitch_of(far_boxes, False) - reference) > 0.2
    assert abs(pitch_of(far_boxes, True, "band") - reference) > 0.2  # not through the far model's box model


def test_map_boxes_drops_what_the_node_drops(tmp_path, capsys):
    """`map --boxes` runs the node's steps after the detector: a second box of one cone in another class goes
    (one_box_per_cone), and the count of what went is printed."""
    from cone_perception.cli import main

    cal_path = save_calibration(_calib(), tmp_path / "cal.yaml")
    boxes = _cone_boxes(_tilted_camera(0.0, 0.0), CONES_XY[:4], CONES_CLS[:4])
    rows = [[*map(float, b), 0.9, int(c)] for b, c in zip(boxes, CONES_CLS[:4])]
    rows.append([*map(float, boxes[0]), 0.5, 1 - int(CONES_CLS[0])])  # blue <-> yellow on the same spot
    pred = tmp_path / "p.jsonl"
    pred.write_text(json.dumps({"image": "f0", "width": 1920, "height": 1080, "boxes": rows}) + "\n")
    assert main(["map", "--calib", str(cal_path), "--boxes", str(pred), "--attitude", "fixed"]) == 0
    cap = capsys.readouterr()
    assert len(cap.out.splitlines()) == 4 and "second_box 1" in cap.err
    assert main(["map", "--calib", str(cal_path), "--boxes", str(pred), "--min-height-ratio", "2"]) == 2
    assert "--min-height-ratio" in capsys.readouterr().err


def test_eval_reads_each_networks_boxes_through_its_box_model(tmp_path, capsys):
    """`eval --attitude image` reads the predictions as `map --boxes` and the node do: the band model's boxes through
    --model's box model, those the file marks as the far strip's through --far-model's. Far-network boxes whose tops
    stand 6 % low, marked: the 7-15 m cones are placed as exact boxes place them; unmarked: worse."""
    from cone_perception.cli import main

    band, far = _two_models(tmp_path, 0.06)
    cal_path = save_calibration(_calib(), tmp_path / "cal.yaml")
    exact = _cone_boxes(_tilted_camera(0.6, 0.0), CONES_XY, CONES_CLS)
    cones = [{"class_id": int(c), "x_m": float(x), "y_m": float(y), "distance_m": float(np.hypot(x, y)),
              "box": [float(v) for v in b], "visible_fraction": 1.0} for b, c, (x, y) in zip(exact, CONES_CLS, CONES_XY)]
    (tmp_path / "gt.jsonl").write_text(json.dumps({"image": "f0.jpg", "width": 1920, "height": 1080, "track": {},
                                                   "pose": {}, "cones": cones}) + "\n")
    err = {}
    for name, boxes, marked in (("exact", exact, False), ("marked", _shrunk(exact, 0.06, 0.0), True),
                                ("unmarked", _shrunk(exact, 0.06, 0.0), False)):
        doc = {"image": "f0.jpg", "width": 1920, "height": 1080,
               "boxes": [[*map(float, b), 0.9, int(c)] for b, c in zip(boxes, CONES_CLS)]}
        if marked:
            doc["far"] = list(range(len(boxes)))
        (tmp_path / "pred.jsonl").write_text(json.dumps(doc) + "\n")
        assert main(["eval", "--pred", str(tmp_path / "pred.jsonl"), "--gt", str(tmp_path / "gt.jsonl"), "--calib",
                     str(cal_path), "--out", str(tmp_path / name), "--attitude", "image", "--box-model", "model",
                     "--model", str(band), "--far-model", str(far), "--far-box-model", "own", "--worst", "0",
                     "--no-progress"]) == 0
        assert "image attitude: box model measured (band.pt.box_model.yaml" in capsys.readouterr().out
        loc = json.loads((tmp_path / name / "metrics.json").read_text())["localisation"]
        err[name] = loc["groups"]["far 7-15 m"]["median_err_m"]
    assert err["marked"] == pytest.approx(err["exact"], abs=0.02)
    assert err["unmarked"] > err["exact"] + 0.1, err
