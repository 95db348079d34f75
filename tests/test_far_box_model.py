"""Each network's boxes through its own box model (issue 26f): the far strip's model draws its boxes differently
from the band's model, so the image fit reads the strip's boxes through the far model's box model (or rendered
table) and the band's through the band model's; which boxes are the strip's follows them through the merge."""

from __future__ import annotations

import numpy as np
import pytest

from cone_perception.attitude import BoxModel, ImageAttitudeConfig
from cone_perception.attitude.box_files import attitude_config_for, far_reading_for, write_box_model
from cone_perception.attitude.boxes import FAR_MODEL_TOP_BIAS_EXTRA_PX, BoxReading
from cone_perception.detector.farband import FarBand, drawn_by_far, far_band_crop, merge_boxes
from cone_perception.mapping import ConeMapper
from cone_perception.pipeline import Pipeline
from cone_perception.records import boxes_from_arrays
from cone_perception.resources import default_far_model_path, default_model_path

from test_attitude import CONES_CLS, CONES_XY, _calib, _cone_boxes, _tilted_camera
from test_box_model import _shrunk

PITCH, ROLL = 0.8, -0.4
FAR = CONES_XY[:, 0] >= 12.0  # the cones the strip's network draws
#: the strip's network: tops 6 % of the height low, bottoms 2 % high (the band's: exact)
FAR_BM = BoxModel(height_ratio=(0.92,) * 4, top_low=(0.06,) * 4, bottom_high=(0.02,) * 4, counts=(1, 1, 1, 1),
                  sigma_rel=0.03, input_scale=1.0, source="measured")
EXACT_BM = BoxModel(counts=(1, 1, 1, 1), sigma_rel=0.03, source="measured")  # no shift: the band's boxes are the labels


def _labels() -> np.ndarray:
    return _cone_boxes(_tilted_camera(PITCH, ROLL), CONES_XY, CONES_CLS)


def _boxes() -> np.ndarray:
    """The band's exact boxes of the near cones and the strip network's shrunk boxes of the far ones."""
    labels = _labels()
    return np.where(FAR[:, None], _shrunk(labels, 0.06, 0.02), labels)


def _estimator(far_reading):
    return ConeMapper(_calib()).image_attitude(ImageAttitudeConfig(box_model=EXACT_BM, far_reading=far_reading))


def test_fit_reads_the_strip_boxes_through_the_far_model_box_model():
    boxes = _boxes()
    on_labels = _estimator(None).fit(_labels(), CONES_CLS)[0]  # the fit on the labelled cones themselves
    assert abs(on_labels[0] - PITCH) < 0.15
    off = {}
    for name, reading, far in (("own", BoxReading(FAR_BM), FAR), ("band's", None, FAR), ("unmarked", BoxReading(FAR_BM), None),
                               ("swapped", BoxReading(FAR_BM), ~FAR)):
        res = _estimator(reading).fit(boxes, CONES_CLS, far=far)
        off[name] = abs(res[0][0] - on_labels[0])
    assert off["own"] < 1e-6  # each box through its network's box model: as if the labels had been seen
    # read through the band's box model (no far reading, or the strip's boxes not marked) the far model's low
    # tops pull the pitch off by 0.2 degree; the wrong boxes marked, by a third of that
    assert off["band's"] == off["unmarked"] > 0.15 and off["swapped"] > 0.03


def test_rendered_readings_apply_each_network_its_own_table():
    """With rendered tables (no measured box model) the strip's tops move by the far table, the band's by the band's."""
    est = ConeMapper(_calib()).image_attitude(ImageAttitudeConfig(far_reading=BoxReading(None, ((10.0, -0.5), (50.0, -0.5)))))
    boxes = np.array([[100.0, 500.0, 112.0, 520.0], [300.0, 500.0, 312.0, 520.0]])
    _, extra, rel, scatter, read = est._read(boxes, np.array([False, True]))
    assert read.all()
    band = est.cfg.top_bias_extra_px
    assert extra[0] == pytest.approx(np.interp(20.0, [h for h, _ in band], [v for _, v in band])) and extra[0] > 0
    assert extra[1] == pytest.approx(-0.5)
    np.testing.assert_array_equal(rel, est.cfg.sigma_rel)
    np.testing.assert_array_equal(scatter, 0.0)  # tables: nothing to average over frames


def test_each_box_carries_its_network_box_model_spread():
    """Measured box models: the per-cone sigma and the frame-to-frame scatter the size averaging takes are the
    box model's of the network that drew the box."""
    wide = BoxModel(counts=(1, 1, 1, 1), sigma_rel=0.085, input_scale=1.0, source="measured")
    est = ConeMapper(_calib()).image_attitude(ImageAttitudeConfig(box_model=EXACT_BM, far_reading=BoxReading(wide)))
    boxes = np.array([[100.0, 500.0, 112.0, 520.0], [300.0, 500.0, 312.0, 520.0]])
    _, extra, rel, scatter, read = est._read(boxes, np.array([False, True]))
    assert read.all()
    np.testing.assert_allclose(scatter, [0.03, 0.085])
    np.testing.assert_allclose(rel, [max(est.cfg.sigma_rel, 0.03), 0.085])
    np.testing.assert_array_equal(extra, 0.0)  # measured box models: no rendered table


def test_merge_keeps_track_of_the_strip_boxes():
    band = boxes_from_arrays(np.array([[100, 400, 110, 415], [500, 400, 510, 414], [900, 300, 940, 360]]),
                             np.array([0.9, 0.3, 0.8]), np.array([0, 1, 0]))
    far = boxes_from_arrays(np.array([[100.5, 400.4, 110.2, 415.3], [500.2, 400.1, 510.4, 414.2], [1500, 400, 1508, 411]]),
                            np.array([0.6, 0.9, 0.5]), np.array([0, 1, 1]))
    merged = merge_boxes(band, far)
    mask = drawn_by_far(merged, far)
    # whatever the merge rule keeps of each pair: a box is the strip's where it is one of the strip's boxes; the
    # lone 40 px band box and the lone strip box are kept as they are
    fields = ("u1", "v1", "u2", "v2", "score")
    def same(a, b):
        return all(np.isclose(a[f], b[f]) for f in fields) and a["class_id"] == b["class_id"]
    expect = [any(same(m, f) for f in far) for m in merged]
    assert list(mask) == expect and any(expect) and not all(expect)
    lone = {round(float(b["u1"]), 1): bool(m) for b, m in zip(merged, mask)}
    assert lone[900.0] is False and lone[1500.0] is True
    assert not drawn_by_far(merged, far[:0]).any() and len(drawn_by_far(merged[:0], far)) == 0


def test_strip_boxes_are_found_whatever_their_padding_bytes():
    """A record copied field by field may carry other bytes in BOX_DTYPE's 3 padding bytes: the strip's boxes are
    recognised by their fields (the first version compared raw bytes and missed such copies)."""
    far = boxes_from_arrays(np.array([[10, 400, 18, 412], [40, 402, 47, 413]]), np.array([0.5, 0.6]), np.array([0, 1]))
    copied = np.frombuffer(bytearray(b"\xff" * far.dtype.itemsize * 3), dtype=far.dtype).copy()
    for name in far.dtype.names:
        copied[name][:2] = far[name]
    copied[2] = far[0]
    copied["u1"][2] += 1.0  # a box of another place
    assert copied.tobytes() != np.concatenate([far, far[:1]]).tobytes()  # the padding differs
    np.testing.assert_array_equal(drawn_by_far(copied, far), [True, True, False])


class _Fixed:
    """A detector that returns the same boxes every frame."""

    timing: dict = {}

    def __init__(self, boxes: np.ndarray, cls: np.ndarray):
        self.boxes = boxes_from_arrays(boxes, np.full(len(boxes), 0.9), cls)

    def detect(self, bgr, crop):
        return self.boxes.copy()


def test_pipeline_reads_the_strip_boxes_through_the_far_model_box_model():
    """Through the Pipeline: band and strip detectors, the merge, the image attitude. With the far model's box
    model the first frame's pitch is the one of the labelled boxes; read as the band's, it is pulled off."""
    calib = _calib()
    boxes = _boxes()
    v0 = int(np.floor(boxes[FAR, 1].min())) - 8
    crop = far_band_crop((v0, v0 + max(32, int(np.ceil(boxes[FAR, 3].max())) + 8 - v0)), calib.image_width,
                         calib.image_height, calib.crop)
    frame = np.zeros((calib.image_height, calib.image_width, 3), np.uint8)
    pitch = {}
    for name, reading, far_boxes in (("labels", None, _labels()[FAR]), ("own", BoxReading(FAR_BM), boxes[FAR]),
                                     ("band's", None, boxes[FAR])):
        far = FarBand(crop, _Fixed(far_boxes, CONES_CLS[FAR]))
        pipe = Pipeline(calib, _Fixed(boxes[~FAR], CONES_CLS[~FAR]), "image", far=far,
                        attitude_config=ImageAttitudeConfig(box_model=EXACT_BM, far_reading=reading))
        res = pipe.process_raw("bgr8", calib.image_width, calib.image_height, 3 * calib.image_width, frame.tobytes())
        assert len(res.boxes) == len(boxes)
        pitch[name] = res.attitude.pitch_deg
    assert abs(pitch["labels"] - PITCH) < 0.15
    assert abs(pitch["own"] - pitch["labels"]) < 1e-6 and abs(pitch["band's"] - pitch["labels"]) > 0.15


def test_far_reading_follows_the_box_model_choice(tmp_path, caplog):
    band = default_model_path()
    assert far_reading_for("auto", None, band, True)[0] is None  # no strip
    assert far_reading_for("model", band, band, False)[0] is None  # the strip runs the band's model
    far = default_far_model_path()
    r, what = far_reading_for("auto", far, band, True)  # a synthetic camera: the far model's rendered table
    assert r.box_model is None and r.table == FAR_MODEL_TOP_BIAS_EXTRA_PX and "rendered" in what
    r, what = far_reading_for("model", far, band, True)  # measured: the band model's box model reads them by default
    assert r is None and "far_box_model: band" in what
    r, what = far_reading_for("model", far, band, True, "own")  # opt-in: its own (models/cone_detector_far.pt.box_model.yaml)
    assert r.box_model is not None and r.box_model.source == "measured" and r.box_model.input_scale == 1.0
    other = tmp_path / "m.pt"
    other.write_bytes(b"")
    r, what = far_reading_for("rendered", other, band, False)  # no table of its own: the band's, as before
    assert r is None and "band's rendered table" in what
    # ... and the fit's words say so (a candidate scored under another file name reads as the band's: session 17)
    words = attitude_config_for("rendered", band, other, True)[1]
    assert "far strip: the band's rendered table (m.pt has none of its own)" in words
    with caplog.at_level("WARNING"):
        r, what = far_reading_for("model", other, band, False, "own")  # no box model: the conservative default, warned
    assert r.box_model.source == "default" and "m.pt has no box model" in caplog.text
    write_box_model(tmp_path / "m.pt.box_model.yaml", FAR_BM)
    assert far_reading_for("auto", other, band, False, "own")[0].box_model == FAR_BM
    assert far_reading_for("auto", other, band, False)[0] is None  # the default: the band's box model
    with pytest.raises(ValueError, match="unknown box model choice"):
        far_reading_for("nope", far, band, False)
    with pytest.raises(ValueError, match="unknown far box model"):
        far_reading_for("model", far, band, False, "mine")


#: a far model measured only on small boxes (8-24 px at its input), as the shipped one on 640x360 video
SMALL_ONLY_BM = BoxModel(height_ratio=(0.92,) * 4, top_low=(0.06,) * 4, bottom_high=(0.02,) * 4, counts=(50, 40, 0, 0),
                         sigma_rel=0.03, input_scale=1.0, source="measured")


def test_a_bucket_without_measurements_is_unknown_not_exact():
    """Issue 41: a box whose height falls in a bucket with no measured cones is not read through that bucket's values
    (nor the nearest measured one's, held): it goes through the band's box model where that one has measured its size,
    else it is left out of the fit; both are counted."""
    np.testing.assert_array_equal(SMALL_ONLY_BM.measured(np.array([4.0, 10.0, 20.0, 23.9, 24.0, 30.0, 60.0])),
                                  [True, True, True, True, False, False, False])
    np.testing.assert_array_equal(SMALL_ONLY_BM.measured(np.array([20.0, 60.0]), input_scale=0.5), [True, False])
    assert BoxModel().measured(np.array([5.0, 500.0])).all()  # the default stand-in: every size alike, by design
    boxes = np.array([[100.0, 500.0, 110.0, 520.0],    # 20 px, the strip's: measured by its own model
                      [300.0, 500.0, 315.0, 530.0],    # 30 px, the strip's: unmeasured there -> the band's
                      [500.0, 500.0, 530.0, 560.0]])   # 60 px, the band's own
    far = np.array([True, True, False])
    est = ConeMapper(_calib()).image_attitude(ImageAttitudeConfig(box_model=_shrunk_bm(0.0), far_reading=BoxReading(SMALL_ONLY_BM)))
    out, _, _, _, read = est._read(boxes, far)
    assert read.all()
    np.testing.assert_allclose(out[0], SMALL_ONLY_BM.correct(boxes[:1])[0])  # its own model
    np.testing.assert_allclose(out[1], boxes[1])  # the band's (exact) model, not the far one's held 12-24 px values
    assert est.counts.read_by_band == 1 and est.counts.unmeasured == 0
    # the band's model has measured only small boxes too: the 30 px strip box and the band's 60 px box are left out
    est = ConeMapper(_calib()).image_attitude(ImageAttitudeConfig(box_model=_shrunk_bm(0.0, (5, 5, 0, 0), 1.0),
                                                                  far_reading=BoxReading(SMALL_ONLY_BM)))
    _, _, _, _, read = est._read(boxes, far)
    np.testing.assert_array_equal(read, [True, False, False])
    assert est.counts.unmeasured == 2 and est.counts.read_by_band == 0
    assert est.counts.as_dict()["boxes_unmeasured_size"] == 2


def _shrunk_bm(top_low: float, counts=(1, 1, 1, 1), input_scale: float = 0.5) -> BoxModel:
    return BoxModel(top_low=(top_low,) * 4, counts=counts, sigma_rel=0.03, input_scale=input_scale, source="measured")


def test_real_behaviour_takes_the_far_model_rendered_offset_out_first():
    """``replay --box-behaviour real`` on a rendered drive: the far model's rendered boxes already stand below the
    cones' tips (its rendered table); its box model, measured against labels, holds all of its offset on real frames.
    The behaviour takes the rendered offset out before moving the box by the box model, so the fit reading the boxes
    through that box model finds the attitude; without it the offset counts twice and pulls the pitch."""
    from cone_perception.records import boxes_from_arrays, boxes_to_arrays
    from cone_perception.synth.boxlook import BoxBehaviour, real_box_behaviour

    table = ((10.0, -0.6), (60.0, -0.6))  # the far model's rendered tops 0.6 px below the cones' (full px)
    labels = _labels()
    rendered = labels.copy()
    rendered[FAR, 1] += 0.6  # the strip network's rendered boxes
    n = int(FAR.sum())
    recs = boxes_from_arrays(rendered[FAR], [0.9] * n, CONES_CLS[FAR])
    look = BoxBehaviour(FAR_BM, top_jitter=0.0, rendered_table=table)
    np.testing.assert_allclose(boxes_to_arrays(look(recs))[0], FAR_BM.detected(labels[FAR]), atol=1e-6)
    twice = boxes_to_arrays(BoxBehaviour(FAR_BM, top_jitter=0.0)(recs))[0]  # as before: the offset counted twice
    assert np.all(twice[:, 1] - FAR_BM.detected(labels[FAR])[:, 1] > 0.55)

    on_labels = _estimator(None).fit(labels, CONES_CLS)[0]
    fits = {}
    for name, behaviour in (("taken out", look), ("twice", BoxBehaviour(FAR_BM, top_jitter=0.0))):
        boxes = labels.copy()
        boxes[FAR] = boxes_to_arrays(behaviour(recs))[0]
        fits[name] = abs(_estimator(BoxReading(FAR_BM)).fit(boxes, CONES_CLS, far=FAR)[0][0] - on_labels[0])
    assert fits["taken out"] < 0.01 and fits["twice"] > 0.03, fits

    class Fake:  # a detector and a far strip holding one
        def detect(self, img, crop):
            return recs

    strip = Fake()
    strip.detector = Fake()
    _, far = real_box_behaviour(Fake(), strip, EXACT_BM, 0.0, FAR_BM, far_rendered_table=table)
    np.testing.assert_allclose(boxes_to_arrays(far.detector.detect(None, None))[0], FAR_BM.detected(labels[FAR]), atol=1e-6)


def test_far_strip_boxes_have_their_own_range_cut():
    """A cone 24 m away (its box says 20.8 m, the box covering the base plate too): too far for the band's halved
    input (``max_range_m`` 20), but the far strip's network sees it at full resolution (``far_max_range_m`` 25);
    None: the band's cut for all."""
    xy = np.array([[24.0, 1.5], [24.0, -1.5], [10.0, 1.5]])
    cls = np.array([CONES_CLS[0], CONES_CLS[1], CONES_CLS[0]])
    boxes = _cone_boxes(_tilted_camera(0.0, 0.0), xy, cls)
    far = np.array([True, False, False])
    est = ConeMapper(_calib()).image_attitude(ImageAttitudeConfig())
    assert est.cfg.max_range_m == 20.0 and est.cfg.far_max_range_m == 25.0
    np.testing.assert_array_equal(est._select(boxes, cls, far=far), [True, False, True])
    np.testing.assert_array_equal(est._select(boxes, cls), [False, False, True])  # no strip boxes marked
    same = ConeMapper(_calib()).image_attitude(ImageAttitudeConfig(far_max_range_m=None))
    np.testing.assert_array_equal(same._select(boxes, cls, far=far), [False, False, True])


def test_far_range_cut_holds_when_sizes_are_averaged():
    """With sizes averaged over frames the cut is by the feet (not the scattered heights): the strip's boxes of cones
    21-24 m away go into the fit, the band's of the same cones do not."""
    xy = np.array([[x, s * 1.8] for x in (6.0, 9.0, 12.0, 15.0, 21.0, 22.5, 24.0) for s in (-1, 1)])
    cls = np.array([CONES_CLS[0] if y > 0 else CONES_CLS[1] for _, y in xy])
    boxes = _cone_boxes(_tilted_camera(0.0, 0.0), xy, cls)
    far = xy[:, 0] > 20.0
    used = {}
    for name, mask in (("strip", far), ("band", None)):
        est = ConeMapper(_calib()).image_attitude(ImageAttitudeConfig(box_model=EXACT_BM, far_reading=BoxReading(EXACT_BM)))
        res = est.fit(boxes, cls, sizes=est.sizes, far=mask)
        used[name] = res[2]
    assert used["band"] == 8 and used["strip"] == 14, used


def test_far_box_model_measured_at_another_scale_is_read_at_the_strip_scale(tmp_path):
    """A box model's buckets are px at the model input. A far model's box model measured at another scale than the
    strip's (here the car-sized frames run at downscale 2, input scale 0.5: where one model-input px is one px of
    the real clips' own detail) is read at the strip's full resolution: a strip box 20 px tall is 20 px at the far
    model's input and gets the 12-24 px bucket's offsets, not those of the 8-12 px bucket its own scale would give."""
    from cone_perception.evaluation.boxfit import measure_box_model
    from cone_perception.evaluation.groundtruth import EvalImage

    rng = np.random.default_rng(5)
    images = []
    for _ in range(10):
        h = rng.uniform(17.0, 46.0, 12)  # image px: 8.5-23 px at the model input (scale 0.5)
        u, v = rng.uniform(50, 1800, 12), rng.uniform(300, 400, 12)
        labels = np.column_stack([u, v, u + 0.7 * h, v + h])
        top = np.where(h * 0.5 < 12.0, 0.10, 0.02)  # tops 10 % low under 12 px at the input, 2 % above
        preds = labels.copy()
        preds[:, 1] += top * h
        cls = rng.integers(0, 4, 12)
        images.append(EvalImage("f.jpg", 1920, 1080, labels, cls, np.zeros(12, bool), None, preds, np.full(12, 0.9), cls, 0.5))
    bm = measure_box_model(images, band=(240, 600))
    assert bm.input_scale == 0.5 and bm.counts[0] > 20 and bm.counts[1] > 20
    np.testing.assert_allclose(bm.top_low[:2], (0.10, 0.02), atol=1e-9)
    far = tmp_path / "far.pt"
    far.write_bytes(b"")
    write_box_model(tmp_path / "far.pt.box_model.yaml", bm)
    r, what = far_reading_for("model", far, default_model_path(), False, "own")
    assert r.box_model.input_scale == 1.0 and "measured at input scale 0.5, read at the strip's 1" in what
    box = np.array([[100.0, 300.0, 114.0, 320.0]])  # 20 px tall in the strip = 20 px at the far model's input
    np.testing.assert_allclose(r.box_model.at(np.array([20.0]))[1], 0.02)
    assert bm.at(np.array([20.0]))[1][0] == pytest.approx(0.10)  # at its own scale: the 8-12 px bucket
    label_h = 20.0 / r.box_model.at(np.array([20.0]))[0][0]
    assert r.box_model.correct(box)[0, 1] == pytest.approx(300.0 - 0.02 * label_h)


def test_shipped_far_box_model_covers_the_strip_cone_sizes():
    """With far_box_model own, on the car the strip's cones are 8-21 px at the far model's input (full resolution): the shipped far box
    model has measured cones in its 8-12 and 12-24 px buckets (measured where one model-input px is one px of the
    real clips' own detail, not on the clips upscaled 3x, where no cone is under 18 px)."""
    r, _ = far_reading_for("model", default_far_model_path(), default_model_path(), False, "own")
    assert r.box_model.source == "measured" and r.box_model.counts[0] >= 30 and r.box_model.counts[1] >= 30
