"""Waves of thesis section 5.8: table 5.1, deep-water dispersion, (5.22)/(5.23) in the plane."""

import math

import numpy as np
import pytest

from nearsub.common.physics import waves


@pytest.mark.parametrize(
    "number, depth, expected",
    [(6, 50.0, 0.411), (6, 90.0, 0.144), (5, 50.0, 0.153)],
)
def test_orbital_amplitude_reproduces_the_thesis_numbers(number, depth, expected):
    state = waves.sea_state(number)
    assert state.orbital_amplitude(depth) == pytest.approx(expected, rel=0.02)


def test_table_values_and_dispersion():
    ss6 = waves.sea_state(6)
    assert ss6.amplitude == 3.0  # half of the 6.0 m upper significant height
    assert ss6.omega == pytest.approx(2 * math.pi / 12.4)
    assert ss6.wavenumber == pytest.approx(ss6.omega**2 / waves.G)
    assert ss6.wavelength == pytest.approx(2 * math.pi * waves.G / ss6.omega**2)  # docs/design.md, errata 1
    amplitudes = [waves.sea_state(n).orbital_amplitude(0.0) for n in range(7)]
    assert amplitudes[0] == amplitudes[1] == 0.0  # no period in table 5.1: calm
    assert all(a < b for a, b in zip(amplitudes[2:], amplitudes[3:], strict=False))
    with pytest.raises(KeyError):
        waves.sea_state(7)


def test_velocity_is_a_rotating_vector_of_the_depth_amplitude():
    state = waves.sea_state(5)
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-60, 60, (4, 5)), rng.uniform(-15, 15, (4, 5))
    for heading in (0.0, 0.7, math.pi / 2):
        u, v = waves.orbital_velocity(x, y, 12.3, state, 50.0, heading=heading)
        assert u.shape == v.shape == (4, 5)
        np.testing.assert_allclose(np.hypot(u, v), state.orbital_amplitude(50.0))


def test_down_component_points_towards_the_submarine():
    state = waves.sea_state(6)
    amp = state.orbital_amplitude(50.0)
    quarter = state.wavelength / 4  # phase pi/2: all of the amplitude is in (5.23), "down"
    u, v = waves.orbital_velocity([quarter, quarter], [8.0, -8.0], 0.0, state, 50.0)
    np.testing.assert_allclose(u, 0.0, atol=1e-12)
    np.testing.assert_allclose(v, [-amp, amp])  # towards y = 0 on both sides (mirrored)
    u, v = waves.orbital_velocity(0.0, 8.0, 0.0, state, 50.0)  # phase 0: along the heading
    assert (float(u), float(v)) == pytest.approx((amp, 0.0))


def test_lateral_component_has_full_amplitude_for_any_heading():
    state = waves.sea_state(5)
    t = np.linspace(0.0, 9.7, 2001)  # one period
    for heading in (0.0, 0.4, math.pi / 2, 2.5):
        _, v = waves.orbital_velocity(3.0, 7.0, t, state, 50.0, heading=heading)
        assert np.abs(v).max() == pytest.approx(state.orbital_amplitude(50.0), rel=1e-4)


def test_submarine_frame_sees_the_water_fixed_wave():
    state = waves.sea_state(4)
    x, t, u_sub = np.linspace(-40, 40, 9), 7.0, 1.5
    moving = waves.orbital_velocity(x, 6.0, t, state, 30.0, heading=0.3, u_sub=u_sub)
    fixed = waves.orbital_velocity(x + u_sub * t, 6.0, t, state, 30.0, heading=0.3)
    np.testing.assert_allclose(moving, fixed, atol=1e-12)
