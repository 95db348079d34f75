"""Renderer ground truth: reproducible, geometrically exact, boxes tight around the visible cone pixels."""

import numpy as np
import pytest

from cone_perception.classes import BLUE, YELLOW
from cone_perception.geometry import GroundMapper
from cone_perception.geometry.calib import load_calibration
from cone_perception.synth.config import SynthConfig
from cone_perception.synth.render import cone_vertices_W
from cone_perception.synth.scene import CarPose, SceneCamera, random_pose
from cone_perception.synth.track import Track, make_track

W, H = 640, 360


def _frames(cfg: SynthConfig, n: int, seed: int = 0):
    r = cfg.renderer()
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        tr = make_track(["autocross", "skidpad", "acceleration"][k % 3], 100 + k)
        look = r.new_look(rng)
        pose = random_pose(tr, rng, cfg.jitter)
        img, gt = r.render(tr, pose, look, rng)
        out.append((tr, pose, img, gt))
    return out


def test_same_seed_same_frames():
    cfg = SynthConfig(width=W, height=H)
    a, b = _frames(cfg, 2, seed=4), _frames(cfg, 2, seed=4)
    for (_, pa, ia, ga), (_, pb, ib, gb) in zip(a, b):
        assert pa == pb
        assert np.array_equal(ia, ib)
        assert [g.to_dict() for g in ga] == [g.to_dict() for g in gb]
    c = _frames(cfg, 1, seed=5)
    assert not np.array_equal(a[0][2], c[0][2])


@pytest.mark.parametrize("k1", [0.0, -0.12])
def test_foot_points_map_to_true_positions_within_2cm(tmp_path, k1):
    cfg = SynthConfig(width=W, height=H, jitter=False, k1=k1, nose_prob=0.0, photometric=False)
    calib = load_calibration(cfg.save_calibration(tmp_path / "calib.yaml"))
    mapper = GroundMapper(calib.H_F_B, 1e3, camera_matrix=calib.camera_matrix, dist_coeffs=calib.dist_coeffs)
    n_checked = 0
    for tr, pose, img, gt in _frames(cfg, 4):
        full = [g for g in gt if g.visible_fraction >= 0.999]
        if not full:
            continue
        foot = np.array([g.foot_px for g in full])
        xy, valid = mapper.map_pixels(foot)
        truth = np.array([[g.x_m, g.y_m] for g in full])
        assert np.all(valid)
        err = np.hypot(*(xy - truth).T)
        assert err.max() < 0.02, (err.max(), truth[np.argmax(err)])
        # the foot pixel lies in the cone's box
        for g, (u, v) in zip(full, foot):
            u1, v1, u2, v2 = g.box
            assert u1 - 0.5 <= u <= u2 + 0.5 and v1 - 0.5 <= v <= v2 + 0.5  # rasterisation of tiny far cones
        n_checked += len(full)
    assert n_checked >= 10


def test_jitter_moves_the_image_but_not_the_truth():
    base = CarPose(0.0, 0.0, 0.0)
    jit = CarPose(0.0, 0.0, 0.0, pitch_deg=1.0, roll_deg=-1.0)
    tr = Track("test", 0, 3.0, np.array([[10.0, 1.5], [10.0, -1.5]]), np.array([BLUE, YELLOW]), np.zeros((2, 2)))
    cfg = SynthConfig(width=W, height=H, photometric=False, nose_prob=0.0)
    r = cfg.renderer()
    look = r.new_look(np.random.default_rng(0))
    _, g0 = r.render(tr, base, look, np.random.default_rng(0))
    _, g1 = r.render(tr, jit, look, np.random.default_rng(0))
    g0, g1 = (sorted(g, key=lambda t: t.track_index) for g in (g0, g1))
    assert [(g.x_m, g.y_m) for g in g0] == [(g.x_m, g.y_m) for g in g1]
    dv = [abs(a.box[3] - b.box[3]) for a, b in zip(g0, g1)]
    assert min(dv) > 3  # 1 degree of pitch at f = 320 px moves the image by several pixels


def test_boxes_contain_projected_outlines_and_are_tight():
    cfg = SynthConfig(width=W, height=H, nose_prob=0.0, photometric=False)
    n = 0
    for tr, pose, img, gt in _frames(cfg, 3, seed=1):
        sc = SceneCamera(cfg.camera(), pose)
        for g in gt:
            if g.visible_fraction < 0.999:
                continue
            uv, _ = sc.project(cone_vertices_W(tr, g.track_index))
            u1, v1, u2, v2 = g.box
            assert uv[:, 0].min() >= u1 - 1.0 and uv[:, 0].max() <= u2 + 1.0
            assert uv[:, 1].min() >= v1 - 1.0 and uv[:, 1].max() <= v2 + 1.0
            # tight: each box edge within 1.5 px of the outline
            assert abs(uv[:, 0].min() - u1) < 1.5 and abs(uv[:, 0].max() - u2) < 1.5
            assert abs(uv[:, 1].min() - v1) < 1.5 and abs(uv[:, 1].max() - v2) < 1.5
            n += 1
    assert n >= 10


def test_occlusion_lowers_visible_fraction_and_box_stays_inside():
    # a small cone 1 m behind another on the same ray: the near one hides the far one's lower middle
    xy = np.array([[5.0, 0.0], [6.0, 0.0]])
    both = Track("test", 0, 3.0, xy, np.array([YELLOW, BLUE]), np.zeros((2, 2)))
    alone = Track("test", 0, 3.0, xy.copy(), np.array([YELLOW, BLUE]), np.zeros((2, 2)))
    alone.cones_xy_m[0] = [5.0, 20.0]  # near cone moved out of view
    cfg = SynthConfig(width=W, height=H, photometric=False, nose_prob=0.0)
    r = cfg.renderer()
    look = r.new_look(np.random.default_rng(1))
    _, gt = r.render(both, CarPose(0.0, 0.0, 0.0), look, np.random.default_rng(1))
    _, gt_alone = r.render(alone, CarPose(0.0, 0.0, 0.0), look, np.random.default_rng(1))
    near, far = sorted(gt, key=lambda g: g.distance_m)
    (far_alone,) = gt_alone
    assert near.visible_fraction == pytest.approx(1.0) and far_alone.visible_fraction == pytest.approx(1.0)
    assert 0.05 < far.visible_fraction < 0.9
    fa, fb = np.array(far_alone.box), np.array(far.box)
    assert np.all(fb[:2] >= fa[:2]) and np.all(fb[2:] <= fa[2:])
    assert fb[1] == fa[1]  # its tip is above the near cone and stays visible
    # the near cone's box covers the bottom centre of the far cone's unoccluded box
    u_mid, v_bot = (fa[0] + fa[2]) / 2, fa[3] - 1
    assert near.box[0] <= u_mid <= near.box[2] and near.box[1] <= v_bot <= near.box[3]


def test_cone_pixels_have_the_class_colour():
    cfg = SynthConfig(width=W, height=H, photometric=False, nose_prob=0.0)
    seen = {BLUE: 0, YELLOW: 0}
    for tr, pose, img, gt in _frames(cfg, 3, seed=2):
        for g in gt:
            u1, v1, u2, v2 = (int(x) for x in g.box)
            if g.class_id not in seen or v2 - v1 < 12 or g.visible_fraction < 0.9:
                continue
            b, gr, r = img[v1:v2, u1:u2].reshape(-1, 3).astype(float).mean(0)
            if g.class_id == BLUE:
                assert b > r + 20
            else:
                assert r > b + 20 and gr > b + 20
            seen[g.class_id] += 1
    assert seen[BLUE] >= 2 and seen[YELLOW] >= 2


def test_knocked_over_cones_lie_on_the_ground():
    from cone_perception.synth.render import CONE_MODELS

    xy = np.array([[6.0, 1.0], [6.0, -1.0]])
    up = Track("t", 0, 3.0, xy, np.array([BLUE, BLUE]), np.zeros((2, 2)))
    down = Track("t", 0, 3.0, xy.copy(), np.array([BLUE, BLUE]), np.zeros((2, 2)), cone_fallen=np.array([True, True]))
    for i in range(2):
        V = cone_vertices_W(down, i)
        assert V[:, 2].min() == pytest.approx(0.0, abs=1e-9)
        assert V[:, 2].max() < 0.75 * CONE_MODELS[BLUE].height_m  # lying: as high as its base is wide
        assert np.hypot(*(V[:, :2].mean(0) - xy[i])) < 0.15  # around its track position
    cfg = SynthConfig(width=W, height=H, photometric=False, nose_prob=0.0, jitter=False)
    r = cfg.renderer()
    look = r.new_look(np.random.default_rng(0))
    _, g_up = r.render(up, CarPose(0.0, 0.0, 0.0), look, np.random.default_rng(0))
    _, g_down = r.render(down, CarPose(0.0, 0.0, 0.0), look, np.random.default_rng(0))
    for a, b in zip(sorted(g_up, key=lambda t: t.track_index), sorted(g_down, key=lambda t: t.track_index)):
        assert (a.x_m, a.y_m) == (b.x_m, b.y_m) and b.visible_fraction == pytest.approx(1.0)
        assert b.box[1] > a.box[1] + 2  # no tip sticking up: the box top is lower
        assert (b.box[2] - b.box[0]) / (b.box[3] - b.box[1]) > (a.box[2] - a.box[0]) / (a.box[3] - a.box[1])  # flatter
    assert make_track("autocross", 1, knocked_frac=0.3).cone_fallen.mean() == pytest.approx(0.3, abs=0.1)


def _ground_paint(look) -> tuple[float, float]:
    """Shares of the near ground tiles painted yellow (red well above blue) and white (every channel well above
    the asphalt's median, grey)."""
    t = look.near_mosaic.astype(np.int16)
    lo = t.min(axis=2)
    white = (lo - np.median(lo) > 40) & (t.max(axis=2) - lo < 30)
    return float(((t[..., 2] - t[..., 0]) > 60).mean()), float(white.mean())


def test_paint_lines_forces_the_colour_and_random_keeps_every_seeds_look():
    looks = {}
    for mode in ("random", "yellow", "white"):
        r = SynthConfig(width=W, height=H, paint_lines=mode).renderer()
        rng = np.random.default_rng(11)
        looks[mode] = [r.new_look(rng) for _ in range(6)]
    # forced: every look has lines of that colour and none of the other
    for look in looks["yellow"]:
        yellow, white = _ground_paint(look)
        assert yellow > 1e-3 and yellow > 5 * white
    for look in looks["white"]:
        yellow, white = _ground_paint(look)
        assert white > 1e-3 and yellow < 1e-4
    # random: some looks without painted lines (about 30 %), as before the option existed
    shares = [_ground_paint(look) for look in looks["random"]]
    assert any(y < 1e-4 and w < 1e-4 for y, w in shares)
    # the default draws what the renderer drew before the option: the same seed, the same first look
    assert np.array_equal(looks["random"][0].near_mosaic,
                          SynthConfig(width=W, height=H).renderer().new_look(np.random.default_rng(11)).near_mosaic)


def test_paint_lines_unknown_value_is_refused():
    from cone_perception.errors import ConfigError
    with pytest.raises(ConfigError, match="--paint-lines"):
        SynthConfig(width=W, height=H, paint_lines="pink").validate()
