"""Synthetic tracks: reproducible from the seed, and the FS driverless rules hold."""

import numpy as np
import pytest

from cone_perception.classes import BLUE, LARGE_ORANGE, ORANGE, YELLOW
from cone_perception.synth.track import STEP_M, make_track


def _circumradius(c: np.ndarray, spacing_pts: int) -> np.ndarray:
    """Radius through points spaced ``spacing_pts`` samples apart along a polyline."""
    a, b, d = c[: -2 * spacing_pts], c[spacing_pts:-spacing_pts], c[2 * spacing_pts :]
    ab, bd, da = (np.hypot(*(p - q).T) for p, q in ((a, b), (b, d), (d, a)))
    cross = np.abs((b - a)[:, 0] * (d - a)[:, 1] - (b - a)[:, 1] * (d - a)[:, 0])
    with np.errstate(divide="ignore"):
        return ab * bd * da / (2 * cross)


def _lateral(track, xy: np.ndarray) -> np.ndarray:
    """Signed lateral offset (m, + = left of the driving direction) of points from the nearest centre-line point."""
    c = track.centerline_m
    t = np.gradient(c, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    out = []
    for p in xy:
        j = int(np.argmin(np.hypot(*(c - p).T)))
        d = p - c[j]
        out.append(t[j, 0] * d[1] - t[j, 1] * d[0])
    return np.array(out)


@pytest.mark.parametrize("kind", ["autocross", "skidpad", "acceleration"])
def test_same_seed_same_track_other_seed_other_track(kind):
    a, b, c = make_track(kind, 11, stray=2), make_track(kind, 11, stray=2), make_track(kind, 12, stray=2)
    assert np.array_equal(a.cones_xy_m, b.cones_xy_m) and np.array_equal(a.cone_class, b.cone_class)
    assert np.array_equal(a.centerline_m, b.centerline_m)
    assert not np.array_equal(a.cones_xy_m, c.cones_xy_m)


@pytest.mark.parametrize("seed", range(12))
def test_autocross_follows_the_rules(seed):
    tr = make_track("autocross", seed)
    assert 3.0 <= tr.width_m <= 5.0
    assert tr.length_m > 150
    # at most 5 m between consecutive cones of one boundary
    for bound in tr.boundaries:
        assert np.hypot(*np.diff(bound, axis=0).T).max() <= 5.0 + 1e-9
    # blue left, yellow right of the driving direction, about half a track width out
    lat = _lateral(tr, tr.cones_xy_m)
    blue, yellow = tr.cone_class == BLUE, tr.cone_class == YELLOW
    assert np.all(lat[blue] > 0) and np.all(lat[yellow] < 0)
    assert np.allclose(np.abs(lat[blue | yellow]), tr.width_m / 2, atol=0.15)
    # turns no tighter than 9 m diameter at the inner boundary (radius from the centre-line geometry)
    R = _circumradius(tr.centerline_m, int(1.0 / STEP_M))
    assert np.nanmin(R) - tr.width_m / 2 >= 4.5 - 0.05
    # straights up to 80 m, large orange cones at start and finish
    assert max(tr.straights_m) <= 80.0 + 1e-9
    assert np.count_nonzero(tr.cone_class == LARGE_ORANGE) == 8
    # the line does not cross itself: far-apart parts of the centre line stay a track width + margin apart
    c = tr.centerline_m[::8]
    d = np.hypot(*(c[:, None, :] - c[None, :, :]).transpose(2, 0, 1))
    idx = np.arange(len(c))
    far_along = np.abs(idx[:, None] - idx[None, :]) * 8 * STEP_M > 3 * (tr.width_m + 4.0)
    assert d[far_along].min() > tr.width_m + 1.0


def test_autocross_has_varied_elements_across_seeds():
    # tight turns near the minimum radius (hairpins) and long straights both occur
    min_r, long_straight = [], []
    for seed in range(12):
        tr = make_track("autocross", seed)
        min_r.append(np.nanmin(_circumradius(tr.centerline_m, 4)) - tr.width_m / 2)
        long_straight.append(max(tr.straights_m))
    assert min(min_r) < 5.5
    assert max(long_straight) > 40


def test_skidpad_geometry():
    tr = make_track("skidpad", 0)
    xy, cls = tr.cones_xy_m, tr.cone_class
    for cy in (-9.125, 9.125):
        r = np.hypot(xy[:, 0], xy[:, 1] - cy)
        inner = np.isclose(r, 7.625, atol=1e-6)
        outer = np.isclose(r, 10.625, atol=1e-6)
        assert inner.sum() >= 14 and outer.sum() >= 10
        # driving clockwise on the right circle (y < 0): inner boundary on the right = yellow
        inner_cls = YELLOW if cy < 0 else BLUE
        assert np.all(cls[inner] == inner_cls)
        assert np.all(cls[outer & (np.abs(xy[:, 1]) > 3)] == (BLUE if cy < 0 else YELLOW))
    assert np.count_nonzero(cls == LARGE_ORANGE) == 4
    assert np.count_nonzero(cls == ORANGE) > 0
    # the driving line passes the crossing and lies on the 9.125 m circles
    r_right = np.hypot(tr.centerline_m[:, 0], tr.centerline_m[:, 1] + 9.125)
    assert np.sum(np.isclose(r_right, 9.125, atol=0.01)) > 100


def test_acceleration_straight():
    tr = make_track("acceleration", 3)
    lo = tr.cone_class == LARGE_ORANGE
    assert np.count_nonzero(lo) == 8
    lines_x = np.unique(np.round(tr.cones_xy_m[lo, 0]))
    assert lines_x.min() == pytest.approx(0.0, abs=1.0) and lines_x.max() == pytest.approx(75.0, abs=1.0)
    assert np.all(np.abs(tr.centerline_m[:, 1]) < 1e-9)
    for bound in tr.boundaries:
        assert np.hypot(*np.diff(bound, axis=0).T).max() <= 5.0 + 1e-9


def test_missing_and_stray_cones():
    full = make_track("autocross", 5)
    holes = make_track("autocross", 5, missing_frac=0.2)
    stray = make_track("autocross", 5, stray=4)
    assert len(holes.cone_class) < len(full.cone_class)
    assert np.count_nonzero(holes.cone_class == LARGE_ORANGE) == 8  # timing cones are never dropped
    assert len(stray.cone_class) == len(full.cone_class) + 4
    lat = np.abs(_lateral(stray, stray.cones_xy_m[-4:]))
    assert np.all(lat > stray.width_m / 2 + 1.5)
