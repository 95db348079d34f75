"""Issue 27, items 2 and 5: the image fit on a distorted lens (box feet and tops undistorted before the fit), and
rendered drives with the real frames' detector behaviour (synth/boxlook.py: the box model's medians and spread
put onto a detector's boxes; ``replay --box-behaviour real``)."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from cone_perception.attitude import ImageAttitudeConfig
from cone_perception.attitude.box_files import read_box_model
from cone_perception.classes import BLUE, YELLOW
from cone_perception.errors import ConfigError
from cone_perception.mapping import ConeMapper
from cone_perception.records import boxes_from_arrays, boxes_to_arrays
from cone_perception.resources import default_model_path
from cone_perception.synth.boxlook import BehavingDetector, BoxBehaviour, real_box_behaviour
from cone_perception.synth.config import SynthConfig
from cone_perception.synth.scene import CarPose, SceneCamera

from test_attitude import CONES_CLS, CONES_XY, _calib, _cone_boxes, _tilted_camera

#: the held-out camera's radial distortion (issue 27)
K1 = -0.126
#: cones near the centre line and out to the side: feet and tops away from the image centre too
WIDE_XY = np.array([[x, s * w] for x in np.arange(4.0, 19.0, 2.0) for s in (-1, 1) for w in (1.8, 0.35 * x + 1.5)])
WIDE_CLS = np.array([BLUE if y > 0 else YELLOW for _, y in WIDE_XY])


@pytest.mark.parametrize("pitch, roll", [(0.0, 0.0), (1.2, 0.0), (-1.0, 0.8), (0.6, -1.0)])
def test_fit_on_a_distorted_lens_undistorts_feet_and_tops(pitch, roll):
    """Exact boxes of cones seen through a lens with k1 = -0.126: the fit (which undistorts each box's foot and
    top with the calibration's dist_coeffs) finds the attitude as well as on an ideal lens; the same fit taking
    the distorted pixels as they are is off by more than 0.2 degree of pitch."""
    cfg = SynthConfig(seed=0, k1=K1)
    assert cfg.calibration().dist_coeffs[0] == K1
    boxes = _cone_boxes(SceneCamera(cfg.camera(), CarPose(0.0, 0.0, 0.0, pitch, roll)), WIDE_XY, WIDE_CLS)
    mapper = ConeMapper(cfg.calibration())
    theta, _, n = mapper.image_attitude().fit(boxes, WIDE_CLS)
    assert n >= 30
    assert abs(theta[0] - pitch) < 0.15 and abs(theta[1] - roll) < 0.1, theta
    blind = mapper.image_attitude()
    blind.dist = None  # the lens ignored
    theta_blind, _, _ = blind.fit(boxes, WIDE_CLS)
    assert abs(theta_blind[0] - pitch) > 0.2 and abs(theta_blind[0] - pitch) > abs(theta[0] - pitch) + 0.1


def _shipped_box_model():
    bm = read_box_model(default_model_path())
    assert bm is not None and bm.source == "measured"
    return bm


def test_detected_is_the_inverse_of_correct():
    bm = _shipped_box_model()
    labels = _cone_boxes(_tilted_camera(0.0, 0.0), CONES_XY, CONES_CLS)
    det = bm.detected(labels)
    h = labels[:, 3] - labels[:, 1]
    # the shipped model's tops 1-6 % of the height low: the detected boxes are shorter, tops lower
    assert np.all(det[:, 1] > labels[:, 1]) and np.median((det[:, 1] - labels[:, 1]) / h) > 0.01
    np.testing.assert_allclose(det[:, [0, 2]], labels[:, [0, 2]])
    np.testing.assert_allclose(bm.correct(det), labels, atol=0.02 * h.max())


def _records(boxes):
    n = len(boxes)
    return boxes_from_arrays(boxes, [0.9] * n, [BLUE] * n)


def test_box_behaviour_puts_the_medians_and_the_measured_spread_onto_the_boxes():
    bm = _shipped_box_model()
    rng = np.random.default_rng(1)
    v1 = rng.uniform(400, 600, 4000)
    h = rng.uniform(20, 80, 4000)  # 10-40 px at the model input
    boxes = np.column_stack([np.full(4000, 100.0), v1, np.full(4000, 130.0), v1 + h])
    medians = BoxBehaviour(bm, top_jitter=0.0)(_records(boxes))
    np.testing.assert_allclose(boxes_to_arrays(medians)[0], bm.detected(boxes), atol=1e-3)
    real = BoxBehaviour(bm, seed=3)(_records(boxes))
    b, _, _ = boxes_to_arrays(real)
    off = (b[:, 1] - boxes_to_arrays(medians)[0][:, 1]) / h
    assert abs(np.median(off)) < 0.01 and 0.9 * bm.sigma_rel < 1.4826 * np.median(np.abs(off)) < 1.1 * bm.sigma_rel
    np.testing.assert_allclose(b[:, 3], boxes_to_arrays(medians)[0][:, 3], atol=1e-3)  # bottoms: medians only
    again = BoxBehaviour(bm, seed=3)(_records(boxes))
    np.testing.assert_array_equal(again["v1"], real["v1"])  # same seed, same boxes
    with pytest.raises(ValueError, match="jitter"):
        BoxBehaviour(bm, top_jitter=-0.1)


def test_behaving_detector_changes_the_boxes_only():
    class Fake:
        conf, timing = 0.25, {"forward_ms": 1.0}

        def detect(self, band, crop):
            return _records(np.array([[10.0, 100.0, 30.0, 140.0]]))

    bm = _shipped_box_model()
    det, far = real_box_behaviour(Fake(), None, bm, top_jitter=0.0)
    assert isinstance(det, BehavingDetector) and far is None
    got = det.detect(None, None)
    np.testing.assert_allclose(boxes_to_arrays(got)[0], bm.detected(np.array([[10.0, 100.0, 30.0, 140.0]])))
    det.conf = 0.4  # a threshold set at run time reaches the detector itself
    assert det._detector.conf == 0.4 and det.timing == {"forward_ms": 1.0}
    with pytest.raises(ConfigError, match="--box-jitter"):
        real_box_behaviour(Fake(), None, bm, top_jitter=-1.0)


@pytest.mark.parametrize("pitch, roll", [(0.0, 0.0), (1.0, -0.5)])
def test_real_box_behaviour_biases_the_rendered_table_and_the_box_model_takes_it_out(pitch, roll):
    """What item 5 is for: boxes with the real frames' medians (tops low) read through the rendered drives' table
    pull the pitch by more than 0.1 degree; read through the detector's box model, the fit finds the attitude."""
    bm = _shipped_box_model()
    exact = _cone_boxes(_tilted_camera(pitch, roll), CONES_XY, CONES_CLS)
    real = bm.detected(exact)
    mapper = ConeMapper(_calib())
    table, _, _ = mapper.image_attitude().fit(real, CONES_CLS)
    model, _, _ = mapper.image_attitude(ImageAttitudeConfig(box_model=bm)).fit(real, CONES_CLS)
    assert abs(table[0] - pitch) > 0.1
    assert abs(model[0] - pitch) < 0.12 and abs(model[1] - roll) < 0.25, model


def test_replay_box_jitter_needs_real_box_behaviour():
    from cone_perception.replay.run import run_replay

    args = argparse.Namespace(calib="example_mainhoop", live=None, drop_detections=0.0, odom_topic=None,
                              track_conf=None, tracker=[], max_range=None, box_behaviour="as-is", box_jitter=0.05)
    with pytest.raises(ConfigError, match="--box-jitter"):
        run_replay(args)
    args.live, args.box_behaviour, args.box_jitter = "fused", "real", None
    with pytest.raises(ConfigError, match="offline only"):
        run_replay(args)


def test_replay_box_behaviour_real_on_a_synthetic_drive(tmp_path):
    """``replay --box-behaviour real``: the detector's boxes come out of the replay shorter, tops lower by about the
    box model's median (the spread scattered around it); ``--box-jitter 0`` the medians alone (the same boxes, in
    the same order: the behaviour acts after the detector)."""
    from cone_perception.cli import main
    from cone_perception.data import bagio
    from cone_perception.records import BOX_DTYPE, from_pointcloud2

    bag = tmp_path / "drive"
    assert main(["synth", "bag", "--seconds", "0.5", "--fps", "10", "--seed", "9", "--k1", "-0.126", "--out", str(bag),
                 "--no-progress"]) == 0
    boxes = {}
    for name, extra in (("as-is", []), ("real", ["--box-behaviour", "real"]),
                        ("medians", ["--box-behaviour", "real", "--box-jitter", "0"])):
        out = tmp_path / name
        assert main(["replay", str(bag), "--calib", str(tmp_path / "drive_calib.yaml"), "--attitude", "image",
                     "--no-progress", "--out", str(out), *extra]) == 0
        boxes[name] = np.concatenate([from_pointcloud2(m.msg, BOX_DTYPE) for m in bagio.read_messages(out, "/cone_boxes")])
    a, r, m = boxes["as-is"], boxes["real"], boxes["medians"]
    assert len(a) == len(r) == len(m) >= 20
    np.testing.assert_allclose(r["v2"], m["v2"], atol=1e-3)  # bottoms: the medians only
    h = a["v2"] - a["v1"]
    low_m, low_r = (m["v1"] - a["v1"]) / h, (r["v1"] - a["v1"]) / h
    bm = _shipped_box_model()
    assert np.median((m["v2"] - m["v1"]) / h) < 0.995 and 0.005 < np.median(low_m) < 0.08  # shorter, tops 1-6 % low
    assert 0.5 * bm.sigma_rel < np.std(low_r - low_m) < 1.5 * bm.sigma_rel
