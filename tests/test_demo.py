"""``cone-perception demo`` (what ``make demo`` runs): its rendered frames are read as rendered frames, by the
nodes and by ``--offline`` alike, and the far strip's model is the same for both (the 2026-12-02 regression: the
nodes read the rendered boxes through the box models measured on real frames; docs/benchmarks.md, "make demo:
rendered frames through the rendered tables")."""

from __future__ import annotations

import argparse
import json

from cone_perception.attitude.box_files import attitude_config_for
from cone_perception.attitude.boxes import RENDERED_TABLES
from cone_perception.geometry.calib import DEFAULT_CAMERA, load_calibration
from cone_perception.params import node_params as node_param_specs
from cone_perception.replay.demo import DEMO_BOX_MODEL, node_params, offline_attitude_config
from cone_perception.resources import default_far_model_path, default_model_path, far_model_for


def _node_default(name: str):
    return node_param_specs("pipeline")[name].default


def test_far_model_default_is_the_same_for_the_nodes_and_the_offline_tools():
    # the pipeline node resolves its far_model parameter's default; replay/demo --offline pass None
    assert far_model_for(_node_default("far_model"), None) == far_model_for(None, None)


def test_demo_nodes_and_offline_read_the_rendered_frames_through_the_rendered_tables():
    model, calib = default_model_path(), load_calibration(DEFAULT_CAMERA)
    assert calib.camera != "synth"  # the demo maps with a real camera's calibration: box_model auto would not do
    params = node_params(DEFAULT_CAMERA, model)
    far = far_model_for(_node_default("far_model"), None)  # what the pipeline node runs in its strip
    # what the pipeline node builds from the demo's parameters (nodes/_attitude.py declare_box_model)
    node_cfg, node_what = attitude_config_for(params["box_model"], params["model"], far, calib.camera == "synth")
    off_cfg, off_what = offline_attitude_config(model, far_model_for(None, model), calib)
    assert node_what == off_what
    for cfg in (node_cfg, off_cfg):
        assert cfg.box_model is None  # the band's boxes: the rendered table, not the measured real-frame model
        if default_far_model_path().is_file():
            assert cfg.far_reading is not None and cfg.far_reading.box_model is None
            assert cfg.far_reading.table == RENDERED_TABLES[default_far_model_path().name]
    assert DEMO_BOX_MODEL == "rendered"


def test_demo_offline_short_drive_is_accurate_at_7_15_m(tmp_path):
    """The demo's own offline run (shipped calibration, image attitude, the far model in the strip) on 2 s of its
    rendered drive: 7-15 m median error within 0.17 m and 15-25 m within 0.55 m (0.112 / 0.345 m with the
    rendered tables; the measured real-frame box models, what the nodes read before: 0.246 / 0.796 m;
    docs/benchmarks.md, "make demo: rendered frames through the rendered tables")."""
    from cone_perception.replay.demo import run_demo

    args = argparse.Namespace(out=tmp_path, seed=2026, seconds=2.0, fps=20.0, speed=8.0, jitter=True, mode="fused",
                              calib=DEFAULT_CAMERA, model=None, offline=True, no_progress=True)
    assert run_demo(args) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["box_model"] == "rendered"
    bands = summary["localisation"]["extra_groups"]
    assert bands["7-15 m"]["n_matched"] >= 150 and bands["15-25 m"]["n_matched"] >= 150
    assert bands["7-15 m"]["median_err_m"] <= 0.17
    assert bands["15-25 m"]["median_err_m"] <= 0.55


def test_replay_live_and_offline_read_the_boxes_alike():
    # replay --live gives the nodes the box_model the offline replay reads with: with --gt-topic (a rendered drive
    # with truth) the rendered tables even where the calibration is a real camera's (the nodes' auto: measured)
    from cone_perception.replay.run import box_model_choice

    def ns(**kw):
        return argparse.Namespace(**{"box_model": "auto", "gt_topic": None, "box_behaviour": "as-is", **kw})

    assert box_model_choice(ns(gt_topic="/cones_gt")) == "rendered"
    assert box_model_choice(ns(gt_topic="/cones_gt", box_behaviour="real")) == "model"
    assert box_model_choice(ns()) == "model"
    assert box_model_choice(ns(box_model="rendered")) == "rendered"
