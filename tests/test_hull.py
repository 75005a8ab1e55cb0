"""SUBOFF geometry against the offsets of Groves, Huang & Chang (1989), DTRC/SHD-1298-01, and the
Explorer profile of thesis (3.1)/(3.2) (docs/design.md, "Vehicle data and sources")."""

import math

import numpy as np
import pytest

from nearsub.common.physics import hull

FT = hull.FT


def _model_properties():
    joints = [j * FT for j in (hull.SUBOFF_BOW_END_FT, hull.SUBOFF_PMB_END_FT, hull.SUBOFF_AFT_END_FT)]
    return hull.revolution_properties(
        lambda x: hull.suboff_model_radius_ft(x / FT) * FT,
        (0.0, *joints, hull.SUBOFF_LENGTH_FT * FT),
    )


@pytest.mark.parametrize(
    "joint, expected",
    [
        (hull.SUBOFF_BOW_END_FT, 1.0),
        (hull.SUBOFF_PMB_END_FT, 1.0),
        (hull.SUBOFF_AFT_END_FT, 0.1175),
    ],
)
def test_suboff_continuous_at_joints(joint, expected):
    eps = 1e-7
    left, right = hull.suboff_model_radius_ft([joint - eps, joint + eps])
    assert left == pytest.approx(right, abs=1e-5)
    assert left == pytest.approx(expected * hull.SUBOFF_RMAX_FT, abs=1e-5)


def test_suboff_ends_and_outside():
    r = hull.suboff_model_radius_ft([-1.0, 0.0, hull.SUBOFF_LENGTH_FT, 20.0])
    assert r[0] == 0.0 and r[3] == 0.0
    assert r[1] == pytest.approx(0.0, abs=1e-12)
    assert r[2] == pytest.approx(0.0, abs=2e-3)  # the printed cap constant ends at 1 + 1.4e-6


def test_suboff_model_volume_and_wetted_area():
    props = _model_properties()
    assert props.volume == pytest.approx(0.699, abs=5e-4)  # integrated from the Groves et al. offsets
    assert props.wetted_area == pytest.approx(5.988, abs=5e-4)  # as used for SUBOFF towing-tank C_T


def test_full_scale_dimensions():
    assert hull.L_SUB == pytest.approx(88.86, abs=0.01)  # D = 34 ft, L/D = 8.575 (docs/design.md, "Frames")
    assert hull.D_SUB == pytest.approx(10.363, abs=1e-3)
    assert hull.SUBOFF_JOINTS_M == pytest.approx((20.73, 66.19, 86.92), abs=0.01)  # stations x 20.4
    assert hull.suboff_properties().volume == pytest.approx(5936, rel=1e-3)  # model volume x 20.4^3
    assert float(hull.suboff_radius(40.0)) == pytest.approx(hull.R_SUB)


def test_cb_is_volume_centroid_and_frame():
    model_cb = _model_properties().centroid
    assert hull.SUB_CB_FROM_NOSE == pytest.approx(model_cb * hull.SUBOFF_SCALE, rel=1e-9)
    assert hull.SUB_BOW_X - hull.SUB_STERN_X == pytest.approx(hull.L_SUB)
    w = hull.submarine_half_width([hull.SUB_BOW_X + 1, hull.SUB_BOW_X, 0.0, hull.SUB_STERN_X - 1])
    assert w[0] == 0.0 and w[3] == 0.0 and w[2] == pytest.approx(hull.R_SUB)
    assert w[1] == pytest.approx(0.0, abs=1e-9)
    # The bow (blunt) is at +x: 5 m behind the bow tip is wider than 5 m before the stern tip.
    assert hull.submarine_half_width(hull.SUB_BOW_X - 5) > hull.submarine_half_width(hull.SUB_STERN_X + 5)


def test_submarine_outline_polygon():
    x, y = hull.submarine_outline(200)
    assert len(x) == len(y) == 2 * 200 - 1
    assert (x[0], y[0]) == (x[-1], y[-1])
    assert x.max() == pytest.approx(hull.SUB_BOW_X) and x.min() == pytest.approx(hull.SUB_STERN_X)
    assert np.abs(y).max() == pytest.approx(hull.R_SUB)
    np.testing.assert_allclose(np.abs(y), hull.submarine_half_width(x), atol=1e-9)


@pytest.mark.parametrize("length, diameter", [(1.33, 0.191), (2.2256, 0.419), (5.3, 0.53), (1.0, 1.0 / 3)])
def test_explorer_profile(length, diameter):
    radius = diameter / 2
    joints = [2 * radius, length - 4 * radius]
    eps = 1e-9
    for s in joints:
        left, right = hull.explorer_radius([s - eps, s + eps], length, diameter)
        assert left == pytest.approx(right, abs=1e-6) and left == pytest.approx(radius, abs=1e-6)
    ends = hull.explorer_radius([0.0, length, -0.1, length + 0.1], length, diameter)
    np.testing.assert_allclose(ends, 0.0, atol=1e-12)
    s = np.linspace(0, length, 1001)
    assert hull.explorer_radius(s, length, diameter).max() == pytest.approx(radius)


def test_explorer_cb_matches_closed_form():
    length, diameter = 1.33, 0.191
    r = diameter / 2
    lp = length - 6 * r
    volume = (4 / 3) * math.pi * r**3 + math.pi * r**2 * lp + (32 / 15) * math.pi * r**3
    moment = (
        (5 / 3) * math.pi * r**4
        + math.pi * r**2 * lp * (2 * r + lp / 2)
        + math.pi * r**2 * 4 * r * ((2 * r + lp) * 8 / 15 + 2 * r / 3)
    )
    assert hull.explorer_cb_from_nose(length, diameter) == pytest.approx(moment / volume, rel=1e-5)


def test_explorer_too_short_raises():
    with pytest.raises(ValueError):
        hull.explorer_radius(0.1, 0.5, 0.2)


def test_uuv_outline_pose():
    length, diameter = 1.33, 0.191
    cb = hull.explorer_cb_from_nose(length, diameter)
    x, y = hull.uuv_outline(10.0, 5.0, 0.0, length, diameter, 32)
    assert x.shape == (63,)
    assert x.max() == pytest.approx(10.0 + cb) and x.min() == pytest.approx(10.0 + cb - length)
    assert np.abs(y - 5.0).max() == pytest.approx(diameter / 2, rel=1e-3)
    # Heading +90 deg points the nose to +y; batches broadcast.
    bx, by = hull.uuv_outline([0.0, 1.0], [0.0, 2.0], [math.pi / 2, 0.0], length, diameter, 32)
    assert bx.shape == by.shape == (2, 63)
    assert by[0].max() == pytest.approx(cb) and np.abs(bx[0]).max() == pytest.approx(diameter / 2, rel=1e-3)
    np.testing.assert_allclose(bx[1], x - 9.0)
