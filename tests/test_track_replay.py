"""Tracking in replay and its evaluation: replay --track / --drop-detections on a synthetic drive,
odometry from a bag, and the tracking metrics (IDF1, id switches, ego-motion) on hand-made cases."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cone_perception.classes import BLUE, YELLOW
from cone_perception.data import bagio
from cone_perception.data.bags import TRACKED_TOPIC, read_twists
from cone_perception.detector import Detector, default_model_path
from cone_perception.errors import ConfigError
from cone_perception.evaluation.tracking import TrackingReport, idf1, load_drive_truth
from cone_perception.geometry.calib import load_calibration
from cone_perception.pipeline import Pipeline
from cone_perception.records import CONE_DTYPE, TRACKED_CONE_DTYPE, from_pointcloud2
from cone_perception.replay import ReplayTracking, drive_truth_beside, offline_replay
from cone_perception.synth.config import SynthConfig
from cone_perception.synth.writers import bag_side_paths, write_scene_bag
from cone_perception.tracking import Motion2D

SEED = 31337  # not a training seed


@pytest.fixture(scope="module")
def drive(tmp_path_factory) -> Path:
    bag = tmp_path_factory.mktemp("track") / "drive"
    write_scene_bag(SynthConfig(seed=SEED, jitter=False), 2.0, 10.0, bag, speed_mps=6.0, progress=False)
    return bag


def test_replay_track_writes_tracked_cones_and_fills_dropped_detections(drive, tmp_path):
    calib = load_calibration(bag_side_paths(drive)[0])
    det = Detector.load_for_band(default_model_path(), (calib.crop.out_width, calib.crop.out_height))
    tracking = ReplayTracking(calib, True, 0.3, 0, drive_truth_beside(drive))
    out = tmp_path / "out"
    # attitude fixed: a still drive (no jitter), where the fixed H is exact; the tracker alone is under test
    res = offline_replay(drive, Pipeline(calib, det, "fixed"), out=out, gt_topic="/cones_gt", tracking=tracking)
    s = res.tracking
    assert s["dropped_detections"] > 0
    # the tracker bridges the dropped detections: more of the visible cones within 15 m than raw /cones
    assert s["tracked"]["recall"] > s["raw"]["recall"] + 0.1
    assert s["tracked"]["false_per_frame"] <= 0.5
    assert s["tracked"]["ego_median_err_frac"] < 0.05
    msgs = list(bagio.read_messages(out, TRACKED_TOPIC))
    assert len(msgs) == len(res.tracked) == 20
    first = from_pointcloud2(msgs[-1].msg, TRACKED_CONE_DTYPE)
    assert len(first) > 5 and first["track_id"].dtype == np.uint32
    assert msgs[-1].msg.header.frame_id == calib.frame_id
    stamps = [bagio.stamp_ns(m.msg.header) for m in msgs]
    assert stamps == sorted(res.cones)  # the capture stamps of the frames
    # eval --tracked scores the output bag to the same figures (but the ego-motion, not in the bag)
    from cone_perception.cli import main

    assert main(["eval", "--tracked", str(out), "--gt", str(bag_side_paths(drive)[1]), "--out", str(tmp_path / "ev")]) == 0
    m = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    raw_bands, s_raw = s["raw"]["bands"], {k: v for k, v in s["raw"].items() if k != "bands"}
    assert {k: v for k, v in m["raw"].items() if k != "bands"} == pytest.approx(s_raw, nan_ok=True)
    for kind, bands in (("raw", raw_bands), ("tracked", s["tracked"]["bands"])):  # the range bands (issue 26) alike
        assert list(bands) == ["0-7 m", "7-15 m", "15-25 m", "25-40 m"]
        for name, b in bands.items():
            assert m[kind]["bands"][name] == pytest.approx(b, nan_ok=True), (kind, name)
    for k in ("recall", "false_per_frame", "median_err_0_7_m", "id_switches", "id_switches_all", "idf1",
              "err_7_15_ratio_to_raw"):
        assert m["tracked"][k] == pytest.approx(s["tracked"][k], nan_ok=True), k
    for name, g in s["tracked"]["groups"].items():
        assert m["tracked"]["groups"][name] == pytest.approx(g, nan_ok=True), name
    assert m["tracked"]["ego_frames"] == 0 and m["messages"] == {"/cones": 20, "/cones/tracked": 20}
    assert "IDF1" in (tmp_path / "ev" / "report.md").read_text()


def test_replay_cli_refuses_drop_and_odometry_live(drive, capsys):
    from cone_perception.cli import main

    assert main(["replay", str(drive), "--live", "fused", "--track", "--drop-detections", "0.2"]) != 0
    assert "offline only" in capsys.readouterr().err
    assert main(["replay", str(drive), "--live", "fused", "--track", "--odom-topic", "/odom"]) != 0
    assert "offline only" in capsys.readouterr().err


def test_replay_weak_detections_reach_the_tracker_only(drive, tmp_path, capsys):
    """Issue 26: with --track-conf the detector runs at the lower score; /cones, its scoring and the boxes
    stay those of --conf (the same as without), the detections in between go to the tracker (counted in
    its events), and --tracker sets TrackerConfig fields."""
    from cone_perception.cli import main

    base = ["replay", str(drive), "--calib", str(bag_side_paths(drive)[0]), "--gt-topic", "/cones_gt", "--track",
            "--attitude", "fixed", "--no-progress", "--tracker", "max_range_m=40", "--tracker", "spawn_max_m=2"]
    assert main(base + ["--json", str(tmp_path / "a.json")]) == 0
    assert main(base + ["--track-conf", "0.05", "--json", str(tmp_path / "b.json")]) == 0
    a, b = (json.loads((tmp_path / f"{k}.json").read_text()) for k in "ab")
    assert a["localisation"] == b["localisation"]  # /cones unchanged by the weak detections
    assert set(a["boxes_dropped"]) == {"second_box", "off_ground", "flat", "one_ray"}  # every dropped box, by cause
    assert "weak_hit" not in a["tracking"]["events"]
    assert b["tracking"]["events"].get("weak_hit", 0) + b["tracking"]["events"].get("weak_spawn", 0) > 0
    assert list(b["tracking"]["tracked"]["bands"]) == ["0-7 m", "7-15 m", "15-25 m", "25-40 m"]
    capsys.readouterr()
    for extra, word in ((["--tracker", "nonsense=1"], "TrackerConfig field"), (["--tracker", "max_range_m=far"], "float"),
                        (["--track-conf", "0.5"], "--track-conf"), (["--max-range", "-3"], "--max-range"),
                        (["--min-height-ratio", "1.5"], "--min-height-ratio")):
        assert main(base + extra) == 2, extra
        assert word in capsys.readouterr().err, extra
    assert main(["replay", str(drive), "--track-conf", "0.1"]) == 2  # needs --track
    assert main(["replay", str(drive), "--live", "fused", "--track", "--tracker", "max_range_m=40"]) == 2
    assert "offline only" in capsys.readouterr().err


@pytest.mark.parametrize("mode", ["fused", "separate"])
def test_live_replay_tracks_through_the_nodes(drive, tmp_path, capsys, mode):
    """replay --live --track: the pipeline node with track: true, or a cone_tracker node after the three
    nodes; every frame's /cones/tracked comes back under its capture stamp, ids stay, it is scored."""
    from cone_perception.cli import main

    out = tmp_path / "live"
    args = ["replay", str(drive), "--live", mode, "--track", "--calib", str(bag_side_paths(drive)[0]),
            "--gt-topic", "/cones_gt", "--out", str(out), "--json", str(tmp_path / "s.json"), "--no-progress",
            "--model", str(default_model_path())]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "20 /cones/tracked received" in text and "/cones/tracked within 15 m over 20 frames" in text
    s = json.loads((tmp_path / "s.json").read_text())["tracking"]
    # a margin of 3 of the 78 cones within 15 m: with the far model in the strip (issue 26f) the live fused run's
    # tracked recall is 0.962 against /cones' 0.987 (its boxes read through the band's table: 0.974; the offline
    # replay of this drive: 0.987 = raw); the live tracker's odometry and timing differ from the offline one's
    assert s["tracked"]["recall"] >= s["raw"]["recall"] - 0.04 and s["tracked"]["id_switches"] == 0
    msgs = [from_pointcloud2(m.msg, TRACKED_CONE_DTYPE) for m in bagio.read_messages(out, TRACKED_TOPIC)]
    stamps = [bagio.stamp_ns(m.msg.header) for m in bagio.read_messages(out, TRACKED_TOPIC)]
    assert stamps == [bagio.stamp_ns(m.msg.header) for m in bagio.read_messages(out, "/cones")]
    assert len(msgs) == 20 and len(msgs[-1]) > 5
    assert len(set(msgs[-1]["track_id"]) & set(msgs[-5]["track_id"])) >= 3  # the same cones keep their ids


def _write_odometry_bag(path: Path, twists, kind: str) -> None:
    ts = bagio.TYPESTORE.types
    V3 = ts["geometry_msgs/msg/Vector3"]
    Tw = ts["geometry_msgs/msg/Twist"]
    msgs = []
    for stamp, vx, vy, wz in twists:
        tw = Tw(linear=V3(x=vx, y=vy, z=0.0), angular=V3(x=0.0, y=0.0, z=wz))
        if kind == "odom":
            m = ts["nav_msgs/msg/Odometry"](
                header=bagio.header(stamp, "odom"), child_frame_id="rear_axle",
                pose=ts["geometry_msgs/msg/PoseWithCovariance"](
                    pose=ts["geometry_msgs/msg/Pose"](position=ts["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                                      orientation=ts["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
                    covariance=np.zeros(36)),
                twist=ts["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=np.zeros(36)))
            msgs.append(("/odom", stamp, m))
        else:
            msgs.append(("/twist", stamp, ts["geometry_msgs/msg/TwistStamped"](header=bagio.header(stamp, "rear_axle"), twist=tw)))
    topic, ty = ("/odom", "nav_msgs/msg/Odometry") if kind == "odom" else ("/twist", "geometry_msgs/msg/TwistStamped")
    bagio.write_bag(path, {topic: ty}, msgs)


@pytest.mark.parametrize("kind", ["odom", "twist"])
def test_odometry_from_a_bag_moves_the_tracks(tmp_path, kind):
    twists = [(k * 10_000_000, 8.0, 0.0, 0.0) for k in range(60)]
    twists[30] = (30 * 10_000_000, float("nan"), 0.0, 0.0)
    _write_odometry_bag(tmp_path / "bag", twists, kind)
    got = read_twists(tmp_path / "bag", "/odom" if kind == "odom" else "/twist")
    assert len(got) == 60 and got[1] == (10_000_000, 8.0, 0.0, 0.0)
    rt = ReplayTracking(load_calibration(), True, twists=got)
    world = np.array([[8.0, 2.0], [8.0, -2.0], [12.0, 2.0], [12.0, -2.0]])
    for k, stamp in enumerate(range(0, 600_000_000, 50_000_000)):
        local = world - (0.4 * k, 0.0)
        c = np.zeros(len(local), CONE_DTYPE)
        c["x"], c["y"], c["class_id"], c["score"] = local[:, 0], local[:, 1], [BLUE, YELLOW] * 2, 0.8
        c["cov_xx"] = c["cov_yy"] = 0.01
        _, tracked = rt.frame(stamp, c)
        if k:
            assert rt.stage.last_info.motion_source == "odometry"
            assert rt.stage.last_info.motion.dx == pytest.approx(0.4, abs=1e-6)
    assert rt.stage.events["twist_nan"] == 1
    assert sorted(tracked["track_id"]) == [1, 2, 3, 4]
    # odometry that stops: stale at the next frame, counted, the cones take over
    _, _ = rt.frame(900_000_000, c)
    assert rt.stage.events["odom_stale"] == 1 and rt.stage.last_info.motion_source != "odometry"


def test_eval_tracked_needs_a_drive_truth_and_a_replay_bag(drive, tmp_path):
    from cone_perception.cli import main

    gt = bag_side_paths(drive)[1]
    # the synth bag itself has neither /cones nor /cones/tracked
    assert main(["eval", "--tracked", str(drive), "--gt", str(gt), "--out", str(tmp_path / "a")]) != 0
    assert main(["eval", "--tracked", str(drive), "--gt", str(drive), "--out", str(tmp_path / "b")]) != 0
    with pytest.raises(SystemExit):  # --pred and --tracked together
        main(["eval", "--tracked", str(drive), "--pred", str(gt), "--gt", str(gt), "--out", str(tmp_path / "c")])


def test_drop_share_checked():
    with pytest.raises(ConfigError, match="drop-detections"):
        ReplayTracking(load_calibration(), True, 1.5)


# ---- metrics on hand-made cases ----------------------------------------------------------------
def test_idf1_hand_made():
    # truth cone A seen 4 frames: track 1 for 3 of them, then track 2; truth B: track 3 in 2 frames;
    # the tracker also reported track 4 once (false). n_truth = 6, n_tracked = 7.
    pairs = {(0, 1): 3, (0, 2): 1, (1, 3): 2}
    f1, idtp = idf1(pairs, 6, 7)
    assert idtp == 5  # A-1 (3) + B-3 (2); A-2 cannot also count
    assert f1 == pytest.approx(2 * 5 / 13)
    assert idf1({}, 0, 0)[0] != idf1({}, 0, 0)[0]  # nan: nothing to score


def _truth_file(path: Path, frames) -> Path:
    with open(path, "w") as f:
        for stamp, pose, cones in frames:
            f.write(json.dumps({"stamp_ns": stamp, "pose": {"x_m": pose[0], "y_m": pose[1], "yaw_deg": pose[2]},
                                "cones": [{"class_id": c, "x_m": x, "y_m": y} for x, y, c in cones]}) + "\n")
    return path


def test_tracking_report_counts_switches_false_cones_and_ego_error(tmp_path):
    # the car drives 1 m per frame along x; two cones at world (10, +-2)
    frames = [(k, (float(k), 0.0, 0.0), [(10.0 - k, 2.0, BLUE), (10.0 - k, -2.0, YELLOW)]) for k in range(4)]
    truth = load_drive_truth(_truth_file(tmp_path / "gt.jsonl", frames))
    assert len(truth.world_xy_m) == 2
    assert truth.motion(0, 1) == Motion2D(1.0, 0.0, 0.0)
    rep = TrackingReport(truth)

    def rec(xy, ids):
        r = np.zeros(len(xy), TRACKED_CONE_DTYPE)
        r["x"], r["y"] = np.asarray(xy, float).reshape(-1, 2).T
        r["track_id"] = ids
        return r

    rep.add_frame(0, rec([[10.0, 2.0], [10.0, -2.0]], [1, 2]))
    rep.add_frame(1, rec([[9.0, 2.0], [9.0, -2.0]], [1, 2]), Motion2D(1.02, 0.0, 0.0))
    rep.add_frame(2, rec([[8.0, 2.0], [8.0, -2.05], [5.0, 0.0]], [1, 7, 9]), Motion2D(0.99, 0.0, 0.0))  # switch 2 -> 7, one false
    rep.add_frame(3, rec([[7.0, 2.0]], [1]), Motion2D(1.0, 0.0, 0.0))  # yellow missed
    s = rep.summary()
    assert s["id_switches"] == 1 and s["id_switches_all"] == 1
    assert s["false_per_frame"] == pytest.approx(1 / 4)
    assert s["recall"] == pytest.approx(7 / 8)
    assert s["ego_median_err_m"] == pytest.approx(0.01)
    assert s["idf1"] == pytest.approx(2 * 6 / (8 + 8))  # IDTP: cone A-1 4, B-2 2


def test_a_cone_back_in_range_under_a_new_id_is_no_switch_while_in_range(tmp_path):
    # the car stands still, then jumps 20 m back (the cone leaves the 15 m range) and returns
    poses = [0.0, 0.0, -20.0, 0.0]
    frames = [(k, (x, 0.0, 0.0), [(10.0 - x, 2.0, BLUE)] if x == 0.0 else []) for k, x in enumerate(poses)]
    truth = load_drive_truth(_truth_file(tmp_path / "gt.jsonl", frames))
    rep = TrackingReport(truth)
    rec = np.zeros(1, TRACKED_CONE_DTYPE)
    rec["x"], rec["y"] = 10.0, 2.0
    for k, tid in zip(range(4), (1, 1, None, 5)):
        if tid is None:
            rep.add_frame(k, np.zeros(0, TRACKED_CONE_DTYPE))
            continue
        rec["track_id"] = tid
        rep.add_frame(k, rec)
    s = rep.summary()
    assert s["id_switches"] == 0 and s["id_switches_all"] == 1
