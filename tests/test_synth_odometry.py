"""``/odom`` of ``synth bag``: the true body twist with noise and bias (cone_perception/synth/odometry.py)."""

from __future__ import annotations

import numpy as np

from cone_perception.synth.odometry import ODOM_RATE_HZ, frame_twists, odometry_samples
from cone_perception.tracking import Motion2D, TwistBuffer


def _arc(n: int, fps: float, v: float, w: float) -> np.ndarray:
    """(n, 3) poses driving a circle at speed v (m/s) and yaw rate w (rad/s)."""
    t = np.arange(n) / fps
    R = v / w
    return np.c_[R * np.sin(w * t), R * (1 - np.cos(w * t)), w * t]


def test_frame_twists_of_a_circle_are_its_speed_and_yaw_rate() -> None:
    tw = frame_twists(_arc(20, 20.0, 8.0, 0.5), 20.0)
    np.testing.assert_allclose(tw, np.tile([8.0, 0.0, 0.5], (19, 1)), atol=1e-9)


def test_a_jump_back_to_the_start_of_the_course_repeats_the_twist_before() -> None:
    p = _arc(20, 20.0, 8.0, 0.5)
    p[10:] -= p[10] - p[0]  # the drive wraps: frame 10 is at the start again
    tw = frame_twists(p, 20.0)
    np.testing.assert_allclose(tw[9], tw[8])


def test_odometry_between_frames_gives_the_true_motion_within_its_noise() -> None:
    fps, n = 20.0, 200
    poses = _arc(n, fps, 8.0, 0.4)
    start = 1_000_000_000
    odom = odometry_samples(poses, fps, start, np.random.default_rng(3))
    assert len(odom) == int((n - 1) / fps * ODOM_RATE_HZ) + 1
    assert all(b.stamp_ns - a.stamp_ns == 20_000_000 for a, b in zip(odom, odom[1:]))
    buf = TwistBuffer(max_age_s=0.1, keep_s=100.0)
    for o in odom:
        assert buf.add(o.stamp_ns, *o.twist) is None
    err = []
    for i in range(1, n):
        t0, t1 = start + int(round((i - 1) * 1e9 / fps)), start + int(round(i * 1e9 / fps))
        m = buf.motion(t0, t1)
        x0, y0, a0 = poses[i - 1]
        c, s = np.cos(a0), np.sin(a0)
        d = poses[i, :2] - poses[i - 1, :2]
        true = Motion2D(c * d[0] + s * d[1], -s * d[0] + c * d[1], poses[i, 2] - a0)
        err.append(np.hypot(m.dx - true.dx, m.dy - true.dy) / true.translation_m)
    # noise 0.05 m/s and a bias of about 0.02 m/s at 8 m/s: about 0.5 % of the distance, never exact
    assert 0.0005 < np.median(err) < 0.02
    # the pose is the noisy twist integrated: it drifts, but stays near the truth over 10 s
    assert np.hypot(*(np.array(odom[-1].pose[:2]) - poses[-1, :2])) < 0.05 * 8.0 * (n - 1) / fps


def test_the_noise_comes_from_its_own_generator() -> None:
    poses = _arc(40, 20.0, 8.0, 0.4)
    a = odometry_samples(poses, 20.0, 0, np.random.default_rng(1))
    b = odometry_samples(poses, 20.0, 0, np.random.default_rng(1))
    c = odometry_samples(poses, 20.0, 0, np.random.default_rng(2))
    assert [x.twist for x in a] == [x.twist for x in b] != [x.twist for x in c]


def test_synth_bag_writes_odom_that_replay_reads(tmp_path) -> None:
    from cone_perception.data import bagio
    from cone_perception.data.bags import read_twists
    from cone_perception.synth.config import SynthConfig
    from cone_perception.synth.writers import ODOM_TOPIC, write_scene_bag

    bag = tmp_path / "drive"
    counts = write_scene_bag(SynthConfig(seed=7, jitter=False), 0.5, 10.0, bag, progress=False)
    assert counts[ODOM_TOPIC] == 21  # 0.4 s between the first and the last frame at 50 Hz
    msgs = list(bagio.read_messages(bag, ODOM_TOPIC))
    assert msgs[0].msgtype == bagio.ODOMETRY
    assert msgs[0].msg.header.frame_id == "odom" and msgs[0].msg.child_frame_id == "rear_axle"
    tw = read_twists(bag, ODOM_TOPIC)
    assert len(tw) == 21 and all(abs(vx - 8.0) < 0.5 for _, vx, _, _ in tw)
    assert [m.log_stamp_ns for m in msgs] == [t[0] for t in tw]
