"""The cone tracker (core, ROS-free): association, Kalman fusion, certainty, ids, bad input, ego-motion."""

from __future__ import annotations

import numpy as np
import pytest

from cone_perception.classes import BLUE, LARGE_ORANGE, UNKNOWN, YELLOW
from cone_perception.errors import FrameError
from cone_perception.records import CONE_DTYPE, TRACKED_CONE_DTYPE
from cone_perception.tracking import (
    ConeTracker, FieldOfView, Motion2D, TrackerConfig, TwistBuffer, from_twist, register_cones,
)
from cone_perception.tracking.tracker import _mahalanobis2

DT_NS = 50_000_000  # 20 Hz


def cones(xy, cls, sigma=0.05, score=0.8) -> np.ndarray:
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    out = np.zeros(len(xy), CONE_DTYPE)
    out["x"], out["y"] = xy[:, 0], xy[:, 1]
    out["class_id"] = np.broadcast_to(cls, len(xy))
    out["score"] = score
    out["cov_xx"] = out["cov_yy"] = np.broadcast_to(np.asarray(sigma) ** 2, len(xy))
    return out


def box_fov() -> FieldOfView:
    """Sees x in [2, 20] m, |y| <= 5 m: 'pixels' are (y, x) in metres, band u -5..5, v 2..20."""
    return FieldOfView(lambda xy: np.asarray(xy)[:, ::-1], (-5.0, 2.0, 5.0, 20.0), 30.0, margin_frac=0.0)


WORLD = np.array([[x, s * 2.0] for x in np.arange(0.0, 120.0, 4.0) for s in (1, -1)])
WORLD_CLS = np.array([BLUE, YELLOW] * (len(WORLD) // 2))


def drive(tracker, n, rng, motion=Motion2D(0.4, 0.0, 0.0), drop=0.0, sigma=0.03, give_motion=False, start=0):
    """Drive straight through WORLD; returns per frame (local truth, output, info)."""
    frames = []
    x = start * motion.dx
    for k in range(start, start + n):
        local = WORLD - (x, 0.0)
        vis = box_fov().visible(local) & (rng.random(len(local)) >= drop)
        z = local[vis] + rng.normal(0, sigma, (vis.sum(), 2))
        info = tracker.update(k * DT_NS, cones(z, WORLD_CLS[vis], sigma), motion if give_motion and k > start else None)
        frames.append((local, tracker.output(), info))
        x += motion.dx
    return frames


def nearest_err(out, local):
    d = np.hypot(out["x"][:, None] - local[None, :, 0], out["y"][:, None] - local[None, :, 1])
    return d.min(axis=1), d.argmin(axis=1)


def test_static_cones_fused_better_than_one_measurement_with_stable_ids():
    rng = np.random.default_rng(0)
    trk = ConeTracker(TrackerConfig(process_std_m=0.01), fov=box_fov())  # exact motion, independent noise
    frames = drive(trk, 60, rng, sigma=0.05, give_motion=True)
    local, out, _ = frames[-1]
    assert out.dtype == TRACKED_CONE_DTYPE and out["track_id"].dtype == np.uint32
    err, _ = nearest_err(out, local)
    assert len(out) >= 8
    assert np.median(err) < 0.03  # one measurement: 0.05 * sqrt(2) * 0.83 ~ 0.06 m median
    # the same world cone keeps its id from frame to frame
    ids_by_cone = {}
    for local, out, _ in frames[5:]:
        e, j = nearest_err(out, local)
        for tid, jj, ee in zip(out["track_id"], j, e):
            assert ee < 0.2
            ids_by_cone.setdefault(int(jj) + 0, set())
    ids_by_world = {}
    x = 0.0
    for k, (local, out, _) in enumerate(frames):
        _, j = nearest_err(out, local)
        for tid, jj in zip(out["track_id"], j):
            ids_by_world.setdefault(int(jj), set()).add(int(tid))
    assert all(len(s) == 1 for s in ids_by_world.values())
    # ids never reused: all ids ever published are distinct per world cone
    all_ids = [next(iter(s)) for s in ids_by_world.values()]
    assert len(set(all_ids)) == len(all_ids)


def test_missed_detections_are_bridged_and_certainty_decays_only_in_view():
    rng = np.random.default_rng(1)
    cfg = TrackerConfig()
    trk = ConeTracker(cfg, fov=box_fov())
    xy = [[10.0, 2.0], [10.0, -2.0]]
    for k in range(5):
        trk.update(k * DT_NS, cones(xy, [BLUE, YELLOW]), Motion2D() if k else None)
    c_before = trk.certainty.copy()
    # frame 5: only the first cone seen; the other is in view -> decays, still published
    trk.update(5 * DT_NS, cones(xy[:1], [BLUE]), Motion2D())
    out = trk.output()
    assert len(out) == 2
    lr = cfg.miss_likelihood_ratio
    assert trk.certainty[1] == pytest.approx(c_before[1] * lr / (c_before[1] * lr + 1 - c_before[1]))
    # more misses in view: deleted after a few frames, id 2 never comes back
    for k in range(6, 20):
        trk.update(k * DT_NS, cones(xy[:1], [BLUE]), Motion2D())
    assert list(trk.ids) == [1]
    trk.update(20 * DT_NS, cones(xy, [BLUE, YELLOW]), Motion2D())
    assert sorted(trk.ids) == [1, 3]
    # out of view (x < 2 m: beside the car): no decay while unseen
    trk2 = ConeTracker(cfg, fov=box_fov())
    for k in range(4):
        trk2.update(k * DT_NS, cones([[3.0, 2.0]], [BLUE]), Motion2D() if k else None)
    c = trk2.certainty[0]
    for k in range(4, 30):
        trk2.update(k * DT_NS, cones(np.zeros((0, 2)), []), Motion2D(0.5, 0.0, 0.0))
        if trk2.xy[0, 0] < 2.0:
            break
    assert trk2.xy[0, 0] < 2.0 and len(trk2) == 1
    c_out = trk2.certainty[0]
    for k in range(k + 1, k + 11):
        trk2.update(k * DT_NS, cones(np.zeros((0, 2)), []), Motion2D(0.0, 0.0, 0.0))
    assert trk2.certainty[0] == c_out < c
    # far behind the car: deleted
    trk2.update((k + 1) * DT_NS, cones(np.zeros((0, 2)), []), Motion2D(10.0, 0.0, 0.0))
    assert len(trk2) == 0


def test_recall_with_20_percent_dropped_and_estimated_motion():
    rng = np.random.default_rng(2)
    trk = ConeTracker(fov=box_fov())
    frames = drive(trk, 150, rng, drop=0.2, sigma=0.03)
    n_true = n_found = n_false = 0
    for local, out, info in frames[10:]:
        r = np.hypot(local[:, 0], local[:, 1])
        want = box_fov().visible(local) & (r <= 15)
        d = np.hypot(out["x"][:, None] - local[None, want, 0], out["y"][:, None] - local[None, want, 1])
        n_true += int(want.sum())
        n_found += int((d.min(axis=0) < 0.3).sum()) if len(out) else 0
        near = np.hypot(out["x"], out["y"]) <= 15
        dd = np.hypot(out["x"][:, None] - local[None, :, 0], out["y"][:, None] - local[None, :, 1]).min(axis=1)
        n_false += int((near & (dd > 0.5)).sum())
        assert info.motion_source == "registration"
        assert abs(info.motion.dx - 0.4) < 0.05
    assert n_found / n_true >= 0.98
    assert n_false / len(frames[10:]) <= 0.2


def test_class_probabilities_fused_over_frames():
    trk = ConeTracker(fov=box_fov())
    for k in range(6):
        trk.update(k * DT_NS, cones([[8.0, 1.0]], [BLUE]), Motion2D() if k else None)
    trk.update(6 * DT_NS, cones([[8.0, 1.0]], [YELLOW], score=0.6), Motion2D())
    trk.update(7 * DT_NS, cones([[8.0, 1.0]], [UNKNOWN]), Motion2D())
    out = trk.output()
    assert len(out) == 1 and out["class_id"][0] == BLUE and out["track_id"][0] == 1
    assert trk.class_p[0, BLUE] > 0.8
    # many yellow detections win in the end (no lock-in)
    for k in range(8, 20):
        trk.update(k * DT_NS, cones([[8.0, 1.0]], [YELLOW]), Motion2D())
    assert trk.output()["class_id"][0] == YELLOW


def test_one_to_one_assignment_keeps_two_close_cones_apart():
    trk = ConeTracker(fov=box_fov())
    xy = np.array([[6.0, -0.3], [6.0, 0.3]])  # timekeeping pair, 0.6 m apart
    rng = np.random.default_rng(3)
    for k in range(30):
        trk.update(k * DT_NS, cones(xy + rng.normal(0, 0.03, (2, 2)), LARGE_ORANGE, 0.03), Motion2D() if k else None)
    out = trk.output()
    assert sorted(out["track_id"]) == [1, 2]
    assert np.allclose(np.sort(out["y"]), [-0.3, 0.3], atol=0.05)


def test_bad_stamps_not_fused_and_counted_gap_lowers_certainty():
    trk = ConeTracker(fov=box_fov())
    xy = [[8.0, 2.0], [8.0, -2.0], [12.0, 2.0], [12.0, -2.0]]
    cls = [BLUE, YELLOW, BLUE, YELLOW]
    for k in range(5):
        trk.update(k * DT_NS, cones(xy, cls), Motion2D() if k else None)
    before = (trk.xy.copy(), trk.hits.copy())
    for stamp, reason in ((4 * DT_NS, "stamp_repeated"), (2 * DT_NS, "stamp_backwards")):
        with pytest.raises(FrameError) as e:
            trk.update(stamp, cones([[5.0, 0.0]], [BLUE]))
        assert e.value.reason == reason
    assert np.array_equal(trk.xy, before[0]) and np.array_equal(trk.hits, before[1])
    assert trk.events["stamp_repeated"] == 1 and trk.events["stamp_backwards"] == 1
    c = trk.certainty.copy()
    # 2 s gap; the car moved 3 m: the tracks are predicted with a widened gate and re-found
    moved = np.asarray(xy) - (3.0, 0.0)
    info = trk.update(4 * DT_NS + 2_000_000_000, cones(moved, cls), None)
    assert trk.events["gap"] == 1
    assert info.matched == 4 and info.new == 0
    assert info.motion.dx == pytest.approx(3.0, abs=0.05)
    c_gap = c * np.exp(-2.0 / trk.config.gap_tau_s)
    assert np.allclose(trk.certainty, trk._hit(c_gap, np.full(4, 0.8)))  # lowered by the gap, then one hit


def test_bad_cones_left_out_and_counted():
    trk = ConeTracker(fov=box_fov())
    c = cones([[8.0, 2.0], [np.nan, 1.0], [9.0, -2.0]], BLUE)
    info = trk.update(0, c)
    assert info.new == 2 and trk.events["bad_cone"] == 1


def test_registration_recovers_motion_with_outliers_and_fails_with_too_few():
    rng = np.random.default_rng(4)
    trk_xy = rng.uniform([2, -6], [20, 6], (25, 2))
    trk_cls = rng.integers(0, 2, 25)
    true = Motion2D(0.45, 0.02, 0.03)
    det = true.to_current(trk_xy) + rng.normal(0, 0.01, (25, 2))
    det_cls = trk_cls.copy()
    det[:6] = rng.uniform([2, -6], [20, 6], (6, 2))  # 6 outliers
    reg = register_cones(det, det_cls, trk_xy, trk_cls, prior=Motion2D(0.2, 0.0, 0.0))
    assert reg.ok and reg.inliers >= 17
    assert reg.motion.dx == pytest.approx(0.45, abs=0.01)
    assert reg.motion.dy == pytest.approx(0.02, abs=0.01)
    assert reg.motion.dyaw == pytest.approx(0.03, abs=0.002)
    # class-aware: with the classes of the detections swapped nothing pairs up
    assert not register_cones(det, 1 - det_cls, trk_xy, trk_cls, prior=Motion2D()).ok
    few = register_cones(det[6:8], det_cls[6:8], trk_xy, trk_cls, prior=Motion2D(0.3, 0, 0))
    assert not few.ok and few.motion == Motion2D(0.3, 0, 0)


def test_failed_registration_predicts_from_last_motion_and_is_counted():
    rng = np.random.default_rng(5)
    trk = ConeTracker(fov=box_fov())
    drive(trk, 20, rng, sigma=0.01)
    info = trk.update(20 * DT_NS, cones(np.zeros((0, 2)), []))
    assert trk.events["registration_failed"] == 1
    assert info.motion_source == "prior" and info.motion.dx == pytest.approx(0.4, abs=0.03)


def test_motion_and_twist_buffer():
    m = Motion2D(1.0, 0.5, 0.3)
    p = np.array([[3.0, -1.0], [0.0, 2.0]])
    assert np.allclose(m.to_previous(m.to_current(p)), p)
    # a quarter circle of radius 2 at 1 m/s
    q = from_twist(1.0, 0.0, 0.5, np.pi)
    assert (q.dx, q.dy, q.dyaw) == pytest.approx((2.0, 2.0, np.pi / 2))
    assert m.compose(Motion2D()).dx == m.dx
    buf = TwistBuffer(max_age_s=0.1)
    for k in range(11):
        assert buf.add(k * 10_000_000, 2.0, 0.0, 0.1) is None
    assert buf.add(50_000_000, 2.0, 0.0, 0.1) == "twist_stamp"
    assert buf.add(200_000_000, float("nan"), 0.0, 0.0) == "twist_nan"
    got = buf.motion(0, 100_000_000)
    want = from_twist(2.0, 0.0, 0.1, 0.1)
    assert (got.dx, got.dy, got.dyaw) == pytest.approx((want.dx, want.dy, want.dyaw), abs=1e-9)
    assert buf.motion(100_000_000, 250_000_000) is None  # newest twist 150 ms old at the frame: stale


def test_mahalanobis_matches_direct_formula():
    rng = np.random.default_rng(6)
    z, xy = rng.normal(size=(3, 2)), rng.normal(size=(4, 2))
    A, B = rng.normal(size=(3, 2, 2)), rng.normal(size=(4, 2, 2))
    Rz, P = A @ A.transpose(0, 2, 1) + np.eye(2), B @ B.transpose(0, 2, 1) + np.eye(2)
    d2 = _mahalanobis2(z, Rz, xy, P)
    for i in range(3):
        for j in range(4):
            e = z[i] - xy[j]
            assert d2[i, j] == pytest.approx(e @ np.linalg.inv(Rz[i] + P[j]) @ e)


def test_field_of_view_from_calibration():
    from cone_perception.geometry.calib import load_calibration

    fov = FieldOfView.from_calibration(load_calibration())
    pts = np.array([[8.0, 0.0], [0.5, 0.0], [-5.0, 0.0], [8.0, 40.0], [500.0, 0.0]])
    assert fov.visible(pts).tolist() == [True, False, False, False, False]


def test_low_confidence_detections_are_not_published():
    """The certainty follows the detections' scores: a cone seen again and again with score 0.3 (the
    typical false detection) never goes out, one seen with 0.8 goes out at once."""
    trk = ConeTracker(fov=box_fov())
    for k in range(10):
        trk.update(k * DT_NS, np.concatenate([cones([[8.0, 2.0]], BLUE, score=0.3), cones([[8.0, -2.0]], YELLOW, score=0.8)]),
                   Motion2D() if k else None)
        out = trk.output()
        assert out["class_id"].tolist() == [YELLOW] and out["track_id"].tolist() == [2]
    doubtful = trk.ids != 2
    assert np.all(trk.certainty[doubtful] < trk.config.publish_min_certainty)


def test_robust_update_lets_an_outlier_pull_less():
    """robust_chi2: a detection far (in its covariance) from its track is fused with a widened covariance."""
    moved = {}
    for robust in (0.0, 1.0):
        t = ConeTracker(TrackerConfig(robust_chi2=robust, register=False, process_std_m=0.0))
        for k in range(5):
            t.update(k * DT_NS, cones([[10.0, 2.0]], BLUE, sigma=0.05), Motion2D())
        t.update(5 * DT_NS, cones([[10.2, 2.0]], BLUE, sigma=0.05), Motion2D())  # 0.2 m off: inside the gate, d2 well above 1
        assert len(t) == 1
        moved[robust] = t.xy[0, 0] - 10.0
    assert 0.0 < moved[1.0] < 0.5 * moved[0.0]
    # a detection near its track is fused the same with or without
    same = []
    for robust in (0.0, 1.0):
        t = ConeTracker(TrackerConfig(robust_chi2=robust, register=False))
        t.update(0, cones([[10.0, 2.0]], BLUE, sigma=0.05), Motion2D())
        t.update(DT_NS, cones([[10.01, 2.0]], BLUE, sigma=0.05), Motion2D())
        same.append(t.xy[0].copy())
    np.testing.assert_allclose(same[0], same[1])


# ---- a frame-common attitude error (issue 16 with attitude image / fused) -------------------------
CAM_H_M = 1.2


def pitch_jacobian(xy) -> np.ndarray:
    """(N, 2) m -> (N, 2, 2) m/deg: a flat-ground camera's pitch moves a ground point along its ray by
    (r^2 + h^2) / h per radian (column 1, roll: none here)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    r = np.hypot(xy[:, 0], xy[:, 1])
    J = np.zeros((len(xy), 2, 2))
    J[:, :, 0] = -(xy / r[:, None]) * ((r**2 + CAM_H_M**2) / CAM_H_M * np.pi / 180)[:, None]
    return J


def attitude_drive(give_attitude: bool, seed: int = 0, frames: int = 300, sigma_deg: float = 0.15, tau_s: float = 0.5,
                   register: bool = False) -> dict[str, tuple[float, float]]:
    """Drive 0.4 m a frame past two rows of cones; each frame's cones share one pitch error (AR(1), 1-sigma
    ``sigma_deg``, correlation time ``tau_s``) on top of independent noise growing with range, and carry
    its covariance ``J S J^T`` as the mapping gives it. Returns per range group (raw, tracked) median error.
    Spawning is as it was when these margins were set (spawn_max_m inf): this drive measures the attitude
    treatment, not which detections start tracks."""
    rng = np.random.default_rng(seed)
    xs = np.arange(3.0, 3.0 + 0.4 * frames + 25, 4.0)
    world = np.concatenate([np.c_[xs, np.full_like(xs, 1.6)], np.c_[xs + 2, np.full_like(xs, -1.6)]])
    trk = ConeTracker(TrackerConfig(spawn_max_m=float("inf")))
    a, rho = 0.0, np.exp(-0.05 / tau_s)
    S = np.diag([sigma_deg**2, 0.0])
    raw, out = [], []
    for k in range(frames):
        a = rho * a + np.sqrt(1 - rho**2) * sigma_deg * rng.standard_normal()
        xy = world - (0.4 * k, 0.0)
        r = np.hypot(xy[:, 0], xy[:, 1])
        vis = (xy[:, 0] > 1.5) & (r <= 18.0)
        xy, r = xy[vis], r[vis]
        J = pitch_jacobian(xy)
        s_ind = 0.01 * (1 + (r / 8) ** 2)
        z = xy + J[:, :, 0] * a + rng.standard_normal(xy.shape) * s_ind[:, None]
        c = cones(z, BLUE, score=0.9)
        R = J @ S @ np.transpose(J, (0, 2, 1)) + s_ind[:, None, None] ** 2 * np.eye(2)
        c["cov_xx"], c["cov_xy"], c["cov_yy"] = R[:, 0, 0], R[:, 0, 1], R[:, 1, 1]
        motion = None if register or k == 0 else Motion2D(0.4, 0.0, 0.0)
        trk.update(k * DT_NS, c, motion, *((pitch_jacobian, S) if give_attitude else (None, None)))
        raw += list(zip(r, np.hypot(*(z - xy).T)))
        if k > 20:
            d = np.hypot(trk.xy[:, None, 0] - xy[None, :, 0], trk.xy[:, None, 1] - xy[None, :, 1])
            out += list(zip(r, d.min(axis=0)))
    raw, out = np.array(raw), np.array(out)
    groups = {}
    for name, lo, hi in (("4-7", 4, 7), ("7-15", 7, 15)):
        groups[name] = tuple(float(np.median(e[(e[:, 0] >= lo) & (e[:, 0] < hi), 1])) for e in (raw, out))
    return groups


def test_frame_common_attitude_error_is_not_averaged_as_independent():
    """A frame's attitude error moves all its cones together and lasts a few frames: fused as independent
    noise, the track keeps older, farther detections whose error the same attitude made larger, and ends up
    worse than the raw cones (the bug seen with `replay --attitude fused`); given the attitude's covariance
    and Jacobian, the tracker treats that part as common and correlated and comes out better."""
    for register in (False, True):
        old = attitude_drive(False, register=register)
        new = attitude_drive(True, register=register)
        assert old["7-15"][1] > 1.1 * old["7-15"][0]  # the independent treatment: worse than raw
        assert new["7-15"][1] < 0.95 * old["7-15"][1]
        assert new["4-7"][1] < 0.98 * old["4-7"][1]


def test_registration_does_not_take_a_common_attitude_error_for_motion():
    """A pitch error common to the frame moves far cones along their rays much more than near ones; the
    rigid registration alone turns part of that into a wrong translation, the joint one (attitude as a
    nuisance with its prior) keeps the motion."""
    rng = np.random.default_rng(3)
    prev = np.array([[x, s * 1.6] for x in np.arange(3.0, 19.0, 2.0) for s in (1, -1)])
    true = Motion2D(0.4, 0.0, 0.0)
    cur = true.to_current(prev)
    J = pitch_jacobian(cur)
    S = np.diag([0.1**2, 1e-6])
    det = cur + J[:, :, 0] * 0.1 + rng.normal(0, 0.01, cur.shape)
    cls = np.full(len(cur), BLUE)
    cov_ind = np.broadcast_to(np.eye(2) * 0.01**2, (len(cur), 2, 2))
    cov_full = cov_ind + J @ S @ np.transpose(J, (0, 2, 1))
    trk_cov = np.broadcast_to(np.eye(2) * 0.01**2, (len(cur), 2, 2))
    plain = register_cones(det, cls, prev, cls, true, cov_full, trk_cov, inlier_m=1.0)
    joint = register_cones(det, cls, prev, cls, true, cov_ind, trk_cov, inlier_m=1.0, det_att_jac=J, att_cov_deg2=S)
    assert plain.ok and joint.ok
    err = lambda m: np.hypot(m.dx - true.dx, m.dy - true.dy)  # noqa: E731
    assert err(plain.motion) > 0.01  # 2.5 % of the distance travelled: the attitude taken for motion
    assert err(joint.motion) < 0.6 * err(plain.motion)


def test_stage_hands_the_frame_attitude_to_the_tracker_and_the_jacobian_matches_the_mapping():
    """With a mount pose the stage takes d(x, y)/d(pitch, roll) from the mapping: J S J^T is the attitude
    part the mapping added to each cone's covariance; tracks then carry their error's cross-covariance
    with the attitude (none with ``attitude_common`` off, none for the fixed attitude)."""
    from cone_perception.attitude import Attitude
    from cone_perception.geometry.calib import calibration_from_dict
    from cone_perception.mapping import ConeMapper
    from cone_perception.records import boxes_from_arrays
    from cone_perception.synth.config import SynthConfig
    from cone_perception.tracking import TrackingStage

    calib = calibration_from_dict(SynthConfig(seed=0).calibration().to_dict(), "synth.yaml")
    mapper = ConeMapper(calib)
    xy = np.array([[5.0, 1.5], [9.0, -1.8], [14.0, 2.0]])
    uv = mapper.ground_to_pixels(xy)
    boxes = boxes_from_arrays(np.column_stack([uv[:, 0] - 10, uv[:, 1] - 30, uv[:, 0] + 10, uv[:, 1]]),
                              np.full(3, 0.9), np.full(3, BLUE))
    att = Attitude(0.0, 0.0, 0.3, 0.2, "image", 3)
    with_att, without = mapper.map_boxes(boxes, att), mapper.map_boxes(boxes)
    J = mapper.attitude_jacobian(np.c_[with_att["x"], with_att["y"]])
    added = J @ att.covariance_deg2() @ np.transpose(J, (0, 2, 1))
    # the mapping takes J at the foot point, 0.15 m nearer than the cone's centre: J there is a few % smaller
    np.testing.assert_allclose(with_att["cov_xx"] - without["cov_xx"], added[:, 0, 0], rtol=0.15)
    np.testing.assert_allclose(with_att["cov_yy"] - without["cov_yy"], added[:, 1, 1], rtol=0.15, atol=1e-5)
    assert added[2, 0, 0] > 10 * added[0, 0, 0]  # far cones: the attitude dominates
    for common, attitude, expect in ((True, att, True), (False, att, False), (True, Attitude(), False)):
        stage = TrackingStage(calib, TrackerConfig(attitude_common=common))
        stage.process(DT_NS, with_att, attitude)
        assert (np.abs(stage.tracker.C).max() > 0) == expect


def test_weak_detections_confirm_a_recurring_cone_and_keep_a_track_alive():
    """Issue 26, item 3: a detection below the /cones threshold (strong_score) is weak. One at one ground
    position frame after frame becomes a published cone after a few frames (not at once); weak detections
    on a confirmed track keep it published where, without them, misses in view remove it; a lone weak
    detection that does not recur is never published."""
    cfg = TrackerConfig(strong_score=0.25)
    assert 1.0 < cfg.weak_likelihood_ratio
    trk = ConeTracker(cfg, fov=box_fov())
    published = []
    for k in range(6):
        z = [cones([[12.0, 2.0]], BLUE, score=0.12)]
        if k == 0:
            z.append(cones([[15.0, -2.0]], YELLOW, score=0.12))  # seen once, never again
        trk.update(k * DT_NS, np.concatenate(z), Motion2D() if k else None)
        published.append(trk.output()["class_id"].tolist())
    assert published[0] == [] and published[1] == []  # one or two weak sightings: not yet a cone
    assert published[-1] == [BLUE]  # recurring: confirmed
    assert trk.events["weak_spawn"] == 2 and trk.events["weak_hit"] == 5
    out = trk.output()
    assert out["score"][0] < 0.8 and out["cov_xx"][0] > 0  # certainty says how sure

    # a strong track kept alive by weak detections, against one left without detections
    def run(weak: bool) -> list[int]:
        t = ConeTracker(TrackerConfig(strong_score=0.25), fov=box_fov())
        counts = []
        for k in range(12):
            z = cones([[10.0, 2.0]], BLUE, score=0.8) if k < 2 else (cones([[10.0, 2.0]], BLUE, score=0.1) if weak else cones([], BLUE))
            t.update(k * DT_NS, z, Motion2D() if k else None)
            counts.append(len(t.output()))
        return counts

    assert run(True)[-1] == 1 and run(False)[-1] == 0


def test_without_strong_score_a_low_score_still_lowers_the_certainty():
    """strong_score 0 (the default): every detection is strong, low scores count against a cone as before."""
    assert TrackerConfig().strong_score == 0.0
    trk = ConeTracker(fov=box_fov())
    for k in range(6):
        trk.update(k * DT_NS, cones([[12.0, 2.0]], BLUE, score=0.12), Motion2D() if k else None)
    assert len(trk.output()) == 0 and "weak_hit" not in trk.events


def test_weak_detections_do_not_steer_the_registration():
    """Weak detections are left out of the ego-motion registration: with too few strong cones it fails
    (counted) however many weak ones there are."""
    trk = ConeTracker(TrackerConfig(strong_score=0.25), fov=box_fov())
    pts = [[6.0, 2.0], [6.0, -2.0], [10.0, 2.0], [10.0, -2.0], [14.0, 2.0]]
    trk.update(0, cones(pts, BLUE, score=0.9))
    trk.update(DT_NS, cones(pts, BLUE, score=0.1))
    assert trk.events["registration_failed"] == 1
    trk.update(2 * DT_NS, cones(pts, BLUE, score=0.9))
    assert trk.events["registration_failed"] == 1


def test_spawn_max_m_gives_the_next_far_cone_of_a_row_its_own_track():
    """Two cones of a row 4.5 m apart at 30 m, each with a covariance metres long along the ray: inside
    spawn_chi2 of each other, so without spawn_max_m (inf) only the first gets a track; with spawn_max_m 2
    (the default since issue 26e) the second starts its own (they are farther apart than that) and both
    are kept apart afterwards."""

    def far(xy):
        c = cones(xy, BLUE, score=0.9)
        c["cov_xx"], c["cov_yy"] = 2.5**2, 0.2**2
        return c

    def run(**kw) -> list[list[int]]:
        trk = ConeTracker(TrackerConfig(max_range_m=40.0, **kw))
        trk.update(0, far([[30.0, 2.0]]))
        ids = []
        for k in range(1, 8):
            trk.update(k * DT_NS, far([[30.0, 2.0], [34.5, 2.0]]), Motion2D())
            ids.append(trk.output()["track_id"].tolist())
        return ids

    assert all(i == [1] for i in run(spawn_max_m=float("inf")))
    assert all(i == [1, 2] for i in run(spawn_max_m=2.0))  # the same two ids every frame: not merged, not respawned
    assert run() == run(spawn_max_m=2.0)  # the default


def far_fov(max_range_m: float) -> FieldOfView:
    """Sees x in [2, 60] m, |y| <= 5 m, to ``max_range_m`` (the calibration's range)."""
    return FieldOfView(lambda xy: np.asarray(xy)[:, ::-1], (-5.0, 2.0, 5.0, 60.0), max_range_m, margin_frac=0.0)


def test_far_cones_are_tracked_to_the_calibrations_range_at_the_defaults():
    """Issue 26e: the tracker has no range of its own by default; the calibration's (the field of view's)
    decides. A cone at 32 m (beyond the old 20 m) is tracked and published; one at 45 m, beyond the
    calibration's 40 m, is not; an own max_range_m below the calibration's still cuts."""

    def run(config: TrackerConfig, x: float) -> int:
        trk = ConeTracker(config, fov=far_fov(40.0))
        for k in range(6):
            trk.update(k * DT_NS, cones([[x, 1.5], [x, -1.5]], [BLUE, YELLOW]), Motion2D() if k else None)
        return len(trk.output())

    assert TrackerConfig().max_range_m == float("inf")
    assert ConeTracker(TrackerConfig(), fov=far_fov(40.0)).max_range_m == 40.0
    assert run(TrackerConfig(), 32.0) == 2
    assert run(TrackerConfig(), 45.0) == 0
    assert run(TrackerConfig(max_range_m=20.0), 32.0) == 0
    assert run(TrackerConfig(max_range_m=20.0), 12.0) == 2


def test_a_far_track_out_of_the_calibrations_range_is_not_counted_missed():
    """A track beyond the field of view's range loses no certainty when it is not seen."""
    trk = ConeTracker(fov=far_fov(40.0))
    for k in range(4):
        trk.update(k * DT_NS, cones([[38.0, 1.5]], BLUE), Motion2D() if k else None)
    c = trk.certainty.copy()
    trk.update(4 * DT_NS, cones([], BLUE), Motion2D(-3.0, 0.0, 0.0))  # the car backs off: the cone is at 41 m
    assert trk.xy[0, 0] == pytest.approx(41.0, abs=0.2) and trk.certainty[0] == pytest.approx(c[0])
    trk.update(5 * DT_NS, cones([], BLUE), Motion2D(3.0, 0.0, 0.0))  # back at 38 m, in range and not seen
    assert trk.certainty[0] < c[0]


def test_a_track_seen_once_is_not_kept_once_it_leaves_the_view_by_its_side():
    """A cone placed once at the view's edge (a far cone on the track's other side, placed metres off by a wrong
    first attitude) and never seen again: out of view no miss can lower its certainty, so kept it stayed on
    /cones/tracked until the car had passed it (27-30 frames on `1080-nojitter`). With one hit it goes as it leaves
    the view by its side or below it; with two it is kept there (a cone beside the car); beyond the view's far end
    it is kept too (it may come into view: test_field_of_view_reaches_the_bands_top_with_the_cones_height)."""
    motion = Motion2D(0.4, 0.0, 0.0)
    for hits, kept in ((1, False), (2, True)):
        trk = ConeTracker(TrackerConfig(), fov=box_fov())
        for k in range(hits):  # at the side edge, then out of view (|y| > 5 m)
            trk.update(k * DT_NS, cones([[10.0 - 0.4 * k, 4.9]], BLUE), motion if k else None)
        trk.update(hits * DT_NS, cones(np.zeros((0, 2)), BLUE), Motion2D(0.4, -0.3, 0.0))  # the car turns away
        assert (len(trk.output()) == 1) is kept, hits
        assert trk.events["out_of_view_dropped"] == (0 if kept else 1)
    off = ConeTracker(TrackerConfig(out_of_view_min_hits=0), fov=box_fov())
    off.update(0, cones([[10.0, 4.9]], BLUE))
    off.update(DT_NS, cones(np.zeros((0, 2)), BLUE), Motion2D(0.4, -0.3, 0.0))
    assert len(off.output()) == 1  # the rule turned off: as before


def test_field_of_view_reaches_the_bands_top_with_the_cones_height():
    """The band's top cuts a cone off where its tip lies above it, not three margins below its foot: with the far
    strip /cones reaches 40 m, where the old margin (64 px on a 1080 p band) ended the view at 20 m, so tracks of
    far cones never missed were never removed."""
    from cone_perception.geometry.calib import calibration_from_dict
    from cone_perception.synth.config import SynthConfig
    from cone_perception.tracking.view import FieldOfView as View

    calib = calibration_from_dict(SynthConfig(seed=0).calibration().to_dict(), "test.yaml")
    fov = View.from_calibration(calib)
    old = View(fov.ground_to_pixels, (calib.crop.u0, calib.crop.v0, calib.crop.u1, calib.crop.v1), calib.max_range_m)
    ahead = np.array([[x, 0.0] for x in (5.0, 15.0, 25.0, 30.0, 35.0)])
    assert old.visible(ahead).tolist() == [True, True, False, False, False]
    assert fov.visible(ahead).all()
    # a cone's tip above the band's top is out of view: the tip row computed from the foot row and the horizon
    uv = fov.ground_to_pixels(ahead)
    horizon = fov.ground_to_pixels(ahead * 1e3)[:, 1]
    tip = uv[:, 1] - (uv[:, 1] - horizon) * fov.cone_height_frac
    assert np.all(tip >= fov.v0) and fov.cone_height_frac == pytest.approx(0.505 / calib.mount_pose.height_m)
    # seen once, then missed: beyond the far end (the range cut) it is kept, below the view (passed) it goes
    for x0, dx, kept in ((calib.max_range_m - 0.5, -1.0, True), (calib.max_range_m - 0.5, 0.0, True), (3.0, 2.5, False)):
        trk = ConeTracker(TrackerConfig(), fov=fov)
        trk.update(0, cones([[x0, 0.0]], BLUE))
        trk.update(DT_NS, cones(np.zeros((0, 2)), BLUE), Motion2D(dx, 0.0, 0.0))
        assert (len(trk.output()) == 1) is kept, (x0, dx)
