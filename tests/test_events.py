"""Collision, close-call and large-stray geometry (thesis section 5.11.2; docs/design.md, "Physics
decisions")."""

import math
from functools import lru_cache

import numpy as np
import pytest
from scipy.spatial import cKDTree

from nearsub.common.physics import hull
from nearsub.common.physics import proximity as events

REMUS_L, REMUS_D = 1.33, 0.191  # Prestero (2001): REMUS 100 length and diameter
R = hull.R_SUB


@lru_cache(maxsize=1)
def _dense_hull():
    """Upper hull as a dense point cloud, uniform in x plus clustering at the blunt ends."""
    s = np.r_[
        np.linspace(0.0, hull.L_SUB, 400001),
        hull.L_SUB * (1 - np.cos(np.linspace(0, np.pi, 20001))) / 2,
    ]
    pts = np.column_stack([hull.SUB_CB_FROM_NOSE - s, hull.suboff_radius(s)])
    return cKDTree(pts)


def _brute_clearance(x, y, psi, length=REMUS_L, diameter=REMUS_D):
    """Independent check: dense point clouds of both outlines; negative when they overlap."""
    tree = _dense_hull()
    ox, oy = hull.uuv_outline(x, y, psi, length, diameter, 800)
    gap = tree.query(np.column_stack([ox, np.abs(oy)]))[0].min()
    overlap = np.any(np.abs(oy) < hull.submarine_half_width(ox))
    return -gap if overlap else gap


def _bow_normal(s):
    """Upper hull point s metres behind the nose and its outward unit normal."""
    h = 1e-6
    slope = (hull.suboff_radius(s + h) - hull.suboff_radius(s - h)) / (2 * h)
    normal = np.array([slope, 1.0]) / math.hypot(slope, 1.0)
    return np.array([hull.SUB_CB_FROM_NOSE - s, float(hull.suboff_radius(s))]), normal


def test_hull_signed_distance_simple_points():
    d = events.hull_signed_distance(
        [0.0, 0.0, 0.0, hull.SUB_BOW_X + 2.0, hull.SUB_STERN_X - 3.0],
        [R + 1.5, -R - 0.5, 1.0, 0.0, 0.0],
    )
    np.testing.assert_allclose(d, [1.5, 0.5, -(R - 1.0), 2.0, 3.0], atol=1e-6)


def test_hull_signed_distance_matches_brute_force():
    """The grids' error, by distance from the hull: under 1 mm within 1 m (where collisions and
    close calls are decided), 5 mm within 5 m, a few cm beyond; exact inside and at contact."""
    tree = _dense_hull()
    rng = np.random.default_rng(7)
    x_near = rng.uniform(hull.SUB_STERN_X - 1.5, hull.SUB_BOW_X + 1.5, 6000)
    q = np.vstack(
        [
            np.column_stack([rng.uniform(-55, 48, 3000), rng.uniform(0, 12, 3000)]),
            np.column_stack([x_near, np.abs(hull.submarine_half_width(x_near) + rng.uniform(-0.3, 1.2, 6000))]),
            np.column_stack([rng.uniform(-110, 100, 3000), rng.uniform(0, 45, 3000)]),
        ]
    )
    expected = tree.query(q)[0]
    inside = q[:, 1] < hull.submarine_half_width(q[:, 0])
    expected = np.where(inside, -expected, expected)
    got = events.hull_signed_distance(q[:, 0], q[:, 1])
    for low, high, tolerance in ((-np.inf, 0.01, 3e-4), (0.01, 1.0, 1e-3), (1.0, 5.0, 5e-3), (5.0, np.inf, 6e-2)):
        band = (expected >= low) & (expected < high)
        assert band.sum() > 100
        np.testing.assert_allclose(got[band], expected[band], atol=tolerance, err_msg=f"distances {low}..{high} m")
    # The reference the grids are built from is the exact polyline distance itself.
    np.testing.assert_allclose(events._exact_signed_distance(q[:, 0], q[:, 1]), expected, atol=3e-4)


def test_grids_agree_with_the_exact_distance_where_events_are_decided():
    """Contact and close-call decisions read the exact distance or the finest grid: over the poses
    of many UUVs near the hull, classify matches the exact polyline distance."""
    rng = np.random.default_rng(5)
    x = rng.uniform(hull.SUB_STERN_X - 2, hull.SUB_BOW_X + 2, 3000)
    y = hull.submarine_half_width(x) + rng.uniform(-0.2, 1.0, 3000)
    psi = rng.uniform(-0.5, 0.5, 3000)
    ox, oy = hull.uuv_outline(x, y, psi, REMUS_L, REMUS_D)
    exact = events._exact_signed_distance(ox.ravel(), np.abs(oy.ravel())).reshape(ox.shape).min(axis=-1)
    found = events.classify(x, y, psi, REMUS_L, REMUS_D)
    assert found.collision.tolist() == (exact <= 0).tolist()
    undecided = np.abs(exact - REMUS_D) < 1e-3  # within the finest grid's error of the threshold
    expected = (exact > 0) & ((exact <= REMUS_D) | events.ahead_or_astern(x, y, REMUS_D))
    assert found.close_call[~undecided].tolist() == expected[~undecided].tolist()


def test_parallel_uuv_beside_the_middle_body():
    gap = np.array([0.15, 1e-3, -1e-3])
    y = R + REMUS_D / 2 + gap
    d = events.closest_distance(0.0, y, 0.0, REMUS_L, REMUS_D)
    np.testing.assert_allclose(d, gap, atol=1e-6)
    ev = events.classify(np.zeros(3), -y, np.zeros(3), REMUS_L, REMUS_D)  # mirrored side
    assert ev.collision.tolist() == [False, False, True]
    assert ev.close_call.tolist() == [True, True, False]
    assert ev.large_stray is None


@pytest.mark.parametrize("s", [3.0, 10.0, 18.0])
def test_uuv_pointing_at_the_bow_taper(s):
    """A UUV nose-on to the bow along the hull normal, at an angle to the axis: the clearance is
    the nose gap."""
    point, normal = _bow_normal(s)
    psi = math.atan2(-normal[1], -normal[0])
    cb_behind_nose = hull.explorer_cb_from_nose(REMUS_L, REMUS_D)
    for gap in (0.3, 0.01, -0.01):
        cb = point + (gap + cb_behind_nose) * normal
        d = float(events.closest_distance(cb[0], cb[1], psi, REMUS_L, REMUS_D))
        assert d == pytest.approx(gap, abs=1e-4)
        ev = events.classify(cb[0], cb[1], psi, REMUS_L, REMUS_D)
        assert bool(ev.collision) == (gap < 0)
        assert bool(ev.close_call) == (0 < gap <= REMUS_D)


def test_oblique_uuv_side_touching_the_bow_taper():
    """A UUV at 30 deg to the axis near the bow shoulder: find the touching offset by brute force,
    then check both sides of it."""
    x, psi = hull.SUB_BOW_X - 8.0, math.radians(30.0)
    lo, hi = 0.0, 8.0  # y overlapping, y clear
    for _ in range(22):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _brute_clearance(x, mid, psi) < 0 else (lo, mid)
    touch = hi
    for offset in (-0.005, 0.005, 0.05):
        d = float(events.closest_distance(x, touch + offset, psi, REMUS_L, REMUS_D))
        assert (d <= 0) == (offset < 0)
        if offset > 0:
            assert d == pytest.approx(_brute_clearance(x, touch + offset, psi), abs=2e-3)
    ev = events.classify([x, x], [touch - 0.005, touch + 0.05], [psi, psi], REMUS_L, REMUS_D)
    assert ev.collision.tolist() == [True, False]
    assert ev.close_call.tolist() == [False, True]


def test_directly_ahead_or_behind_is_a_close_call():
    xs = [hull.SUB_BOW_X + 30.0, hull.SUB_BOW_X + 30.0, hull.SUB_STERN_X - 10.0, 0.0]
    ys = [0.0, R + REMUS_D + 0.5, -(R + 0.5 * REMUS_D), R + 20.0]
    ev = events.classify(xs, ys, np.zeros(4), REMUS_L, REMUS_D)
    assert ev.close_call.tolist() == [True, False, True, False]
    assert not ev.collision.any()


def test_large_stray_from_the_track_line_segment():
    track = ((0.0, 20.0), (30.0, 20.0))
    x = np.array([10.0, 10.0, 10.0, 33.0, -0.5])
    y = np.array([21.5, 19.2, 20.9, 20.0, 20.0])
    np.testing.assert_allclose(events.track_distance(x, y, *track), [1.5, 0.8, 0.9, 3.0, 0.5])
    ev = events.classify(x, y, np.zeros(5), REMUS_L, REMUS_D, track=track)
    assert ev.large_stray.tolist() == [True, False, False, True, False]
    assert events.track_distance(3.0, 24.0, (0.0, 20.0), (0.0, 20.0)) == pytest.approx(5.0)


def test_batch_equals_single_poses():
    rng = np.random.default_rng(11)
    x = rng.uniform(hull.SUB_STERN_X - 3, hull.SUB_BOW_X + 3, 40)
    y = rng.choice([-1, 1], 40) * (hull.submarine_half_width(x) + rng.uniform(-0.3, 1.5, 40))
    psi = rng.uniform(-math.pi, math.pi, 40)
    batch = events.classify(x, y, psi, REMUS_L, REMUS_D)
    d = events.closest_distance(x, y, psi, REMUS_L, REMUS_D)
    assert batch.collision.any() and batch.close_call.any()
    for i in range(40):
        single = events.classify(x[i], y[i], psi[i], REMUS_L, REMUS_D)
        assert bool(single.collision) == batch.collision[i] == (d[i] <= 0)
        assert bool(single.close_call) == batch.close_call[i]


def _numpy_grid_distance(x, y):
    """The numpy implementation the compiled grid reader replaced (bilinear interpolation of the
    finest grid that trusts its value, closed form beside the middle body, exact elsewhere), kept
    as its reference."""
    x, y = np.asarray(x, dtype=float).ravel(), np.abs(np.asarray(y, dtype=float)).ravel()
    x_bow_joint, x_aft_joint = events._joints_x()
    beside = (x <= x_bow_joint) & (x >= x_aft_joint)
    dist = y - R
    todo = np.flatnonzero(~beside | ((y < R) & (R - y > np.minimum(x_bow_joint - x, x - x_aft_joint))))
    for grid in events._distance_grids():
        fx, fy = (x[todo] - grid.x0) / grid.h, y[todo] / grid.h
        i, j = np.floor(fx), np.floor(fy)
        covered = (i >= 0) & (i < grid.values.size // grid.ny - 1) & (j < grid.ny - 1)
        i, j = np.where(covered, i, 0), np.where(covered, j, 0)
        tx, ty = fx - i, fy - j
        k = (i * grid.ny + j).astype(np.intp)
        v = grid.values
        low = v[k] + tx * (v[k + grid.ny] - v[k])
        high = v[k + 1] + tx * (v[k + grid.ny + 1] - v[k + 1])
        value = np.where(covered, low + ty * (high - low), np.nan)
        found = value >= grid.trusted_from
        dist[todo[found]] = value[found]
        todo = todo[~found]
    dist[todo] = events._exact_signed_distance(x[todo], y[todo])
    return dist


def test_compiled_distances_equal_the_numpy_reference_bit_for_bit():
    """hull_signed_distance and closest_distance against the numpy arrays they replaced, near the
    hull (some points inside, some poses touching), far out and beyond every grid."""
    rng = np.random.default_rng(12)
    x_near = rng.uniform(hull.SUB_STERN_X - 3.0, hull.SUB_BOW_X + 3.0, 4000)
    x = np.concatenate([x_near, rng.uniform(-400, 400, 2000)])
    y = np.concatenate([hull.submarine_half_width(x_near) + rng.uniform(-0.5, 4.0, 4000), rng.uniform(-300, 300, 2000)])
    np.testing.assert_array_equal(events.hull_signed_distance(x, y), _numpy_grid_distance(x, y))
    psi = rng.uniform(-np.pi, np.pi, x.size)
    ox, oy = hull.uuv_outline(x, y, psi, REMUS_L, REMUS_D)
    expected = _numpy_grid_distance(ox, oy).reshape(ox.shape).min(axis=-1)
    got = events.closest_distance(x, y, psi, REMUS_L, REMUS_D)
    assert (got <= 0).any() and (got > 0).any()
    np.testing.assert_array_equal(got, expected)
