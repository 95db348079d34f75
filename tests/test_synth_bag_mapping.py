"""A synthetic bag drives the core adapter + mapping stages with its own calibration (no ROS nodes)."""

import json

import numpy as np

from cone_perception.adapter import DriverAdapter
from cone_perception.data import bagio
from cone_perception.geometry.calib import load_calibration
from cone_perception.mapping import ConeMapper
from cone_perception.records import CONE_DTYPE, boxes_from_arrays, from_pointcloud2
from cone_perception.synth.config import SynthConfig
from cone_perception.synth.writers import bag_side_paths, write_scene_bag


def test_bag_frames_through_adapter_and_mapping(tmp_path):
    bag = tmp_path / "drive"
    cfg = SynthConfig(width=1280, height=720, jitter=False, nose_prob=0.0, seed=2)
    write_scene_bag(cfg, 0.3, 10.0, bag, progress=False)
    calib_path, gt_path = bag_side_paths(bag)
    calib = load_calibration(calib_path)
    adapter = DriverAdapter(calib.crop, calib.image_width, calib.image_height)
    mapper = ConeMapper(calib)
    truth = {bagio.stamp_ns(m.msg.header): from_pointcloud2(m.msg, CONE_DTYPE) for m in bagio.read_messages(bag, "/cones_gt")}
    gt = {g["stamp_ns"]: g for g in map(json.loads, gt_path.read_text().splitlines())}
    errors = []
    for m in bagio.read_messages(bag, "/camera/image_raw"):
        msg = m.msg
        stamp = bagio.stamp_ns(msg.header)
        cropped = adapter.from_raw(msg.encoding, msg.width, msg.height, msg.step, msg.data)
        assert cropped.shape == (calib.crop.out_height, calib.crop.out_width, 3)
        # exact boxes of fully visible cones within 15 m, mapped with the class foot-point rule
        near = [c for c in gt[stamp]["cones"] if c["visible_fraction"] >= 0.999 and c["distance_m"] <= 15.0]
        assert near
        rec = boxes_from_arrays(np.array([c["box"] for c in near]), np.ones(len(near)), np.array([c["class_id"] for c in near]))
        cones = mapper.map_boxes(rec)
        assert len(cones) == len(near)
        t = truth[stamp]
        for c in cones:  # nearest true cone of the same class
            same = t[t["class_id"] == c["class_id"]]
            errors.append(np.hypot(same["x"] - c["x"], same["y"] - c["y"]).min())
    errors = np.array(errors)
    # the foot-point rule (box corner / bottom centre instead of the cone centre) costs a few decimetres
    assert len(errors) >= 6 and np.median(errors) < 0.35 and errors.max() < 0.6
