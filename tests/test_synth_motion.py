"""The synthetic car moves like a car (``synth bag --car-motion``): braking pitch, cornering roll,
bumps, grade changes; the bag carries ``/imu`` and ``/attitude_gt``; default bags are unchanged.
Replay with the attitude from the image recovers the attitude and keeps far cones in place."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cone_perception.attitude import ImuAttitude
from cone_perception.data import bagio
from cone_perception.data.bags import read_attitude_truth
from cone_perception.geometry.calib import load_calibration
from cone_perception.pipeline import Pipeline
from cone_perception.records import boxes_from_arrays
from cone_perception.replay import offline_replay
from cone_perception.synth.config import SynthConfig
from cone_perception.synth.motion import drive_motion, quat_from_rpy, rpy_matrix
from cone_perception.synth.track import make_track
from cone_perception.synth.writers import bag_side_paths, write_scene_bag


def test_drive_motion_follows_the_speed_profile():
    track = make_track("autocross", 7)
    n, fps = 400, 20.0
    d = drive_motion(track, n, fps, 8.0, np.random.default_rng(1), np.zeros((n, 2)))
    assert np.all(d.speed_mps > 0) and d.speed_mps.max() > 1.3 * d.speed_mps.min()
    load = d.body_pitch_deg  # no jitter: load transfer + bumps
    assert np.abs(load).max() <= 2.0 + 0.5 + 1e-9  # load transfer <= 2, bumps <= 0.5
    braking = d.accel_long < -1.0
    assert braking.any() and np.median(load[braking]) > 0  # braking: nose down
    accel = d.accel_long > 1.0
    assert accel.any() and np.median(load[accel]) < 0
    grade = d.pitch_deg - d.body_pitch_deg
    assert 0.3 < np.abs(grade).max() <= np.degrees(np.arctan(0.02)) + 1e-9
    # cornering: a left turn (lateral acceleration to the left) rolls the right side down
    left = d.accel_lat > 1.0
    assert left.any() and np.all(d.body_roll_deg[left] > 0)


def test_quaternion_matches_the_rotation():
    r, p, y = 0.02, -0.03, 1.2
    q = quat_from_rpy(r, p, y)
    x, yy, z, w = q
    R = np.array([
        [1 - 2 * (yy * yy + z * z), 2 * (x * yy - z * w), 2 * (x * z + yy * w)],
        [2 * (x * yy + z * w), 1 - 2 * (x * x + z * z), 2 * (yy * z - x * w)],
        [2 * (x * z - yy * w), 2 * (yy * z + x * w), 1 - 2 * (x * x + yy * yy)],
    ])
    np.testing.assert_allclose(R, rpy_matrix(r, p, y), atol=1e-12)


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    d = tmp_path_factory.mktemp("motion")
    small = dict(width=640, height=360, nose_prob=0.0, seed=4)
    write_scene_bag(SynthConfig(**small), 1.0, 10.0, d / "plain", progress=False)
    write_scene_bag(SynthConfig(**small), 1.0, 10.0, d / "plain_again", progress=False)
    write_scene_bag(SynthConfig(**small, car_motion=True), 2.0, 10.0, d / "car", progress=False)
    return d


def test_default_bags_are_reproducible_and_carry_attitude_and_imu(bags):
    a = [m.raw for m in bagio.read_messages(bags / "plain", "/camera/image_raw")]
    b = [m.raw for m in bagio.read_messages(bags / "plain_again", "/camera/image_raw")]
    assert a == b
    topics = bagio.bag_topics(bags / "car")
    assert topics["/imu"] == (bagio.IMU, 20) and topics["/attitude_gt"] == (bagio.VECTOR3_STAMPED, 20)
    truth = read_attitude_truth(bags / "car")
    gt = [json.loads(x) for x in bag_side_paths(bags / "car")[1].read_text().splitlines()]
    for g in gt:  # the bag's attitude truth is the gt.jsonl pose
        assert truth[g["stamp_ns"]] == pytest.approx((g["pose"]["pitch_deg"], g["pose"]["roll_deg"]), abs=1e-3)
    for m in bagio.read_messages(bags / "car", "/imu"):
        q = m.msg.orientation
        assert abs(np.linalg.norm([q.x, q.y, q.z, q.w]) - 1) < 1e-9
        assert 9.0 < m.msg.linear_acceleration.z < 10.5  # gravity seen as specific force


class _TruthDetector:
    """Exact boxes of the cones at least half visible, frame by frame from the bag's gt.jsonl."""

    timing: dict = {}

    def __init__(self, gt_path):
        self.frames = iter([json.loads(x) for x in gt_path.read_text().splitlines()])

    def detect(self, band, crop):
        cones = [c for c in next(self.frames)["cones"] if c["visible_fraction"] >= 0.5]
        return boxes_from_arrays(np.array([c["box"] for c in cones]).reshape(-1, 4), np.ones(len(cones)),
                                 np.array([c["class_id"] for c in cones], dtype=int))


def test_replay_with_the_image_attitude(bags, tmp_path):
    calib_path, gt_path = bag_side_paths(bags / "car")
    calib = load_calibration(calib_path)
    assert calib.mount_pose is not None
    res = {}
    for mode in ("fixed", "image", "fused"):
        imu = ImuAttitude() if mode == "fused" else None
        res[mode] = offline_replay(bags / "car", Pipeline(calib, _TruthDetector(gt_path), mode, imu), out=tmp_path / mode,
                                   gt_topic="/cones_gt")
    far = {m: r.localisation["groups"]["far 7-15 m"]["median_err_m"] for m, r in res.items()}
    assert "/cones/attitude" not in bagio.bag_topics(tmp_path / "fixed")
    assert res["fixed"].localisation["attitude"]["frames_by_source"] == {"fixed": 20}
    assert far["fixed"] > 0.25  # the fixed H: far cones a quarter metre off and more
    att = res["image"].localisation["attitude"]
    assert bagio.bag_topics(tmp_path / "image")["/cones/attitude"] == (bagio.VECTOR3_STAMPED, 20)
    assert res["image"].pipeline_attitude["fitted"] >= 15
    assert att["median_abs_err_pitch_deg"] < 0.25 and att["median_abs_err_roll_deg"] < 0.5
    assert far["image"] < 0.5 * far["fixed"] and far["image"] < 0.25  # 640x360: 3x coarser pixels than full HD
    # the covariance (attitude included) covers the error of most far cones
    assert att["groups"]["far 7-15 m"]["within_2sigma"] > 0.8
    # the picture of it
    import cv2

    from cone_perception.evaluation.attitude import attitude_plot

    stamps = sorted(res["image"].attitude)
    png = attitude_plot(tmp_path / "att.png", stamps, [res["image"].attitude[s] for s in stamps],
                        read_attitude_truth(bags / "car"), "car")
    assert cv2.imread(str(png)).shape[1] > 500
    fused = res["fused"].localisation["attitude"]
    assert fused["frames_by_source"] == {"fused": 20} and res["fused"].pipeline_attitude["imu_used"] == 20
    assert fused["median_abs_err_pitch_deg"] < 0.2
    assert far["fused"] < 0.5 * far["fixed"]
