"""The two physics-based fidelities (docs/hydro/README.md) against analytic cases, SUBOFF data and
the thesis's interaction sign pattern. Coarse meshes: the whole file runs in seconds.

Validation sources: classical potential-flow results (Lamb's added-mass coefficients of a spheroid
and its Munk moment; the sphere pair forces of the Lagally theorem), thesis table 3.2 (SUBOFF
drift), thesis section 4.5 (sign pattern), the SUBOFF offsets of Groves, Huang & Chang 1989 (wetted
area).
"""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from nearsub.common.hydro import high_fidelity as hydro_hf
from nearsub.common.hydro import low_fidelity as hydro_lf
from nearsub.common.physics import hull
from nearsub.common.physics.hull import R_SUB, explorer_radius, revolution_properties

RIGHT = np.array([-1.0, 0.0, 0.0])  # the unit stream -x of the body frame


def _sphere(radius=1.0, stations=21, n_azimuths=10):
    profile = hull.profile_from_radius(
        lambda s: np.sqrt(np.maximum(s * (2.0 * radius - s), 0.0)), (0.0, radius, 2.0 * radius), stations
    )
    return hull.revolution_mesh(profile, hull.azimuths(n_azimuths))


def _spheroid_properties(length, diameter):
    """Volume and Lamb's k1, k2 of a prolate spheroid (Lamb, Hydrodynamics)."""
    a, b = 0.5 * length, 0.5 * diameter
    e = math.sqrt(1.0 - b**2 / a**2)
    log = math.log((1.0 + e) / (1.0 - e))
    alpha = 2.0 * (1.0 - e**2) / e**3 * (0.5 * log - e)
    beta = 1.0 / e**2 - (1.0 - e**2) / (2.0 * e**3) * log
    return 4.0 / 3.0 * math.pi * a * b * b, alpha / (2.0 - alpha), beta / (2.0 - beta)


# --- geometry --------------------------------------------------------------------------------------


def test_meshes_are_closed_and_outward():
    mesh = _sphere()
    assert np.all(np.einsum("ij,ij->i", mesh.normals, mesh.centroids) > 0.9)
    image = hull.mirror_z(mesh)
    assert np.all(np.einsum("ij,ij->i", image.normals, image.centroids) > 0.9)
    assert np.all(image.centroids[:, 2] < 0.0)
    # The vertex order of the image still gives its normals.
    assert np.allclose(hull.Mesh.from_vertices(image.vertices).normals, image.normals)
    # A closed surface has zero vector area.
    full = hull.full_surface(mesh)
    assert np.allclose(full.normals.T @ full.areas, 0.0, atol=1e-12)


def test_suboff_wetted_area_from_mesh():
    """5.988 m^2 at model scale (from the Groves et al. 1989 offsets). 80 stations x 32 azimuths:
    the chords of the azimuth polygon lose 1 - sin(pi/32)/(pi/32) = 0.16 %, the meridian chords a little more: 0.5 %."""
    profile = hull.suboff_profile(80, model_scale=True)
    mesh = hull.full_surface(hull.revolution_mesh(profile, hull.azimuths(16)))
    assert mesh.areas.sum() == pytest.approx(5.988, rel=5e-3)
    assert profile.length == pytest.approx(4.3561, abs=1e-4)
    assert profile.cb / profile.length == pytest.approx(0.4611, abs=1e-4)


def test_submarine_window_refinement():
    profile = hull.suboff_profile(60, window=(-5.0, 5.0), window_spacing=0.2)
    inside = (profile.x > -5.0) & (profile.x < 5.0)
    assert np.max(-np.diff(profile.x)[inside[:-1] & inside[1:]]) <= 0.2 + 1e-9
    assert len(profile.s) > 60 + 10.0 / 0.2 - 5


# --- the 3D panel method ---------------------------------------------------------------------------


def test_sphere_surface_pressure():
    """Cp = 1 - 9/4 sin^2 theta; 420 panels on the whole sphere give about 0.006."""
    mesh = _sphere()
    sigma = hydro_hf.solve_sources(mesh, RIGHT)
    velocity = hydro_hf.surface_velocity(mesh, mesh, sigma, RIGHT)
    cp = 1.0 - np.sum(velocity**2, axis=1)
    theta = np.arccos(mesh.centroids[:, 0] / np.linalg.norm(mesh.centroids, axis=1))
    assert np.max(np.abs(cp - (1.0 - 2.25 * np.sin(theta) ** 2))) < 0.012
    assert np.max(np.abs(np.sum(velocity * mesh.normals, axis=1))) < 1e-10


def test_spheroid_munk_moment_panel():
    """N = (k2 - k1) rho Vol U^2 sin psi cos psi for an L/D = 8 spheroid (Munk);
    0.8 % with this mesh."""
    length, diameter, psi = 8.0, 1.0, math.radians(5.0)
    profile = hull.profile_from_radius(
        lambda s: 0.5 * diameter * np.sqrt(np.maximum(1.0 - ((s - 0.5 * length) / (0.5 * length)) ** 2, 0.0)),
        (0.0, 0.5 * length, length),
        41,
    )
    mesh = hull.revolution_mesh(profile, hull.azimuths(8))
    onset = np.array([-math.cos(psi), math.sin(psi), 0.0])
    velocity = hydro_hf.surface_velocity(mesh, mesh, hydro_hf.solve_sources(mesh, onset), onset)
    force, moment = hydro_hf.pressure_force(mesh, velocity, 1.0, np.zeros(3))
    volume, k1, k2 = _spheroid_properties(length, diameter)
    munk = 2.0 * (k2 - k1) * volume * math.sin(psi) * math.cos(psi)  # over rho U^2 / 2
    assert moment == pytest.approx(munk, rel=0.02)
    assert np.abs(force).max() < 1e-3 * munk  # d'Alembert


@pytest.mark.parametrize("arrangement, leading", [("abreast", -3.0), ("in line", 6.0)])
def test_two_spheres(arrangement, leading):
    """Two spheres (a = 1, d = 6a) moving together: abreast they attract with 3 pi rho a^6 U^2/d^4,
    in line they repel with 6 pi rho a^6 U^2/d^4 (leading order in a/d), within 5 %."""
    d = 6.0
    offset = np.array([0.0, 0.5 * d, 0.0]) if arrangement == "abreast" else np.array([0.5 * d, 0.0, 0.0])
    sphere = _sphere()
    first, second = sphere.placed(*offset[:2], 0.0), sphere.placed(*(-offset[:2]), 0.0)
    both = hull.concatenate([first, second])
    sigma = hydro_hf.solve_sources(both, RIGHT)
    force, _ = hydro_hf.pressure_force(first, hydro_hf.surface_velocity(first, both, sigma, RIGHT), 1.0, offset)
    along_centres = force @ (offset[:2] / np.linalg.norm(offset[:2])) * 0.5  # rho = U = 1: F = (1/2) * that
    assert along_centres == pytest.approx(leading * math.pi / d**4, rel=0.05)


def test_panel_kernel_far_field_matches_exact():
    """The point-source far field used beyond FAR_FIELD panel sizes agrees with the exact panel."""
    mesh = _sphere(stations=9, n_azimuths=4)
    j = len(mesh) // 2
    point = mesh.centroids[j] + hydro_hf.FAR_FIELD * mesh.sizes[j] * mesh.normals[j]
    exact = hydro_hf.panel_velocity(point[None], mesh.vertices[j : j + 1], mesh.normals[j : j + 1])[0]
    rel = point - mesh.centroids[j]
    far = mesh.areas[j] * rel / (4.0 * math.pi * np.linalg.norm(rel) ** 3)
    assert np.linalg.norm(far - exact) < 0.01 * np.linalg.norm(exact)


# --- ring sources and the one-way slender model ----------------------------------------------------


@pytest.mark.parametrize("x, r", [(0.5, 0.4), (2.0, 3.0), (0.25, 1.35), (-1.0, 0.01)])
def test_ring_source_against_quadrature(x, r):
    """A ring of unit flux equals point sources of flux d(phi)/2 pi around it."""
    x0, a = 0.2, 1.3

    def point_sources(phi, k):
        d = np.array([x - x0, r - a * np.cos(phi), -a * np.sin(phi)])
        return d[k] / (4.0 * math.pi * np.linalg.norm(d) ** 3) / (2.0 * math.pi)

    ux, ur = hydro_lf.ring_source_velocity(x, r, x0, a)
    assert ux == pytest.approx(quad(point_sources, 0.0, 2.0 * math.pi, args=(0,), limit=200)[0], rel=1e-9)
    assert ur == pytest.approx(quad(point_sources, 0.0, 2.0 * math.pi, args=(1,), limit=200)[0], rel=1e-9)


def test_ring_panels_sphere_surface_speed():
    """The axisymmetric panels reproduce |V| = 3/2 U sin theta on a sphere."""
    profile = hull.profile_from_radius(lambda s: np.sqrt(np.maximum(s * (2.0 - s), 0.0)), (0.0, 1.0, 2.0), 61)
    panels = hydro_lf.solve_ring_panels(profile)
    xm, rm = 0.5 * (panels.xa + panels.xb), 0.5 * (panels.ra + panels.rb)
    ux, ur = panels.velocity(xm, rm)
    tx, tr = (panels.xb - panels.xa) / panels.lengths, (panels.rb - panels.ra) / panels.lengths
    speed = np.abs((ux - 1.0) * tx + ur * tr)
    assert np.max(np.abs(speed - 1.5 * np.sin(np.arctan2(rm, xm)))) < 0.015


def test_submarine_field_table_matches_ring_panels():
    """The spline table reproduces the ring-panel sums it was built from, right next to the hull."""
    field = hydro_lf.submarine_field()
    panels = hydro_lf.solve_ring_panels(hull.suboff_profile(hydro_lf.N_FRUSTA + 1))
    x = np.linspace(-50.0, 45.0, 97)
    for r in (R_SUB + 0.05, R_SUB + 2.0):
        ux, ur = panels.velocity(x, np.full_like(x, r))
        assert np.max(np.abs(field.ux.ev(x, np.full_like(x, r)) - ux)) < 2e-4
        assert np.max(np.abs(field.ur.ev(x, np.full_like(x, r)) - ur)) < 2e-4


def test_submarine_field_table_matches_ring_panels_far_out():
    """Out to the increment's cut-off (interaction.LF_CUT, 260 m) the log-spaced table keeps the
    far field to 1 % of itself, beside the hull and beyond both tips."""
    field = hydro_lf.submarine_field()
    panels = hydro_lf.solve_ring_panels(hull.suboff_profile(hydro_lf.N_FRUSTA + 1))
    for r in (30.0, 100.0, 250.0):
        x = np.linspace(-47.9 - r, 41.0 + r, 41)
        ux, ur = panels.velocity(x, np.full_like(x, r))
        scale = np.hypot(ux, ur).max()
        assert np.max(np.abs(field.ux.ev(x, np.full_like(x, r)) - ux)) < 0.01 * scale
        assert np.max(np.abs(field.ur.ev(x, np.full_like(x, r)) - ur)) < 0.01 * scale


def test_slender_munk_moment():
    """The strip model's free-stream UUV carries the slender Munk moment rho Vol U^2 sin psi cos psi
    (k2 = 1, k1 = 0, slender-body theory) to 1e-3, and no side force."""
    d_ratio, ld, psi = 10.0, 8.0, math.radians(5.0)
    diameter, length = hull.uuv_dimensions(d_ratio, ld)
    volume = revolution_properties(
        lambda s: explorer_radius(s, length, diameter), (0.0, diameter, length - 2.0 * diameter, length), n=4000
    ).volume
    out = hydro_lf.lf_free_stream([0.0, 0.08, 3.5, 5.0, d_ratio, ld])[0]
    assert out[2] == pytest.approx(2.0 * volume * math.sin(psi) * math.cos(psi) / length**3, rel=1e-3)
    assert out[1] == 0.0
    assert out[0] < 0.0


def test_lf_nan_outside_the_table_and_speed_free_potential():
    inside = [0.0, 0.075, 3.5, 0.0, 10.0, 8.0]
    touching = [0.0, 0.059, 3.5, 0.0, 5.0, 5.0]  # centre 5.24 m from the axis, UUV radius 1.04 m
    out = hydro_lf.lf_coefficients([inside, touching])
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1]))
    # Y' and N' are potential flow only: independent of the speed (docs/hydro/README.md).
    slow, fast = hydro_lf.lf_coefficients([[0.4, 0.075, 2.0, 1.0, 10.0, 8.0], [0.4, 0.075, 5.0, 1.0, 10.0, 8.0]])
    assert slow[1:] == pytest.approx(fast[1:], rel=1e-12)
    assert slow[0] < fast[0] < 0.0  # friction coefficient falls with Reynolds number


def test_interaction_vanishes_far_away():
    """70 m beyond either end of the submarine the one-way interaction is down to a few 1e-6. (Beside
    the midbody it is not: the submarine's pressure field reaches R_lat = 0.25 with Y' ~ -4e-5.)"""
    rows = [[1.3, 0.075, 3.5, 1.0, 10.0, 8.0], [-1.3, 0.075, 3.5, 1.0, 10.0, 8.0]]
    assert np.max(np.abs(hydro_lf.lf_coefficients(rows) - hydro_lf.lf_free_stream(rows))) < 1e-5


# --- the high-fidelity model on SUBOFF: thesis table 3.2 --------------------------------------------


def test_suboff_drift_against_table_3_2():
    """The isolated model-scale SUBOFF against the EFD of thesis table 3.2.

    N' is calibrated at 2.08 deg (the Munk efficiency, the one tuned constant), so it must match
    there. The other entries are predictions: X' is ITTC-57 x Hoerner form factor at the panel
    surface speed, 6-8 % light against EFD (the thesis's CFD is 8-9 % light too); Y' is the
    Allen-Perkins cross-flow drag, within 9 %; N' grows too large with angle (+1 % at 4 deg,
    +21 % at 10 deg) because the constant Munk efficiency ignores the stabilising aft-body
    separation that grows like sin^2 psi. Bounds: X' 10 %, Y' 12 %, N' 10 % up to 6 deg and 25 %
    beyond; the surrogate's domain is |psi| <= 2 deg.
    """
    table = hydro_hf.TABLE_3_2_EFD
    out = hydro_hf.suboff_drift(table[:, 0]) * 1e3
    error = out / table[:, 1:] - 1.0
    assert error[0, 2] == pytest.approx(0.0, abs=1e-9)
    assert np.all(np.abs(error[:, 0]) < 0.10)
    assert np.all(np.abs(error[:, 1]) < 0.12)
    assert np.all(np.abs(error[table[:, 0] < 7.0, 2]) < 0.10)
    assert np.all(np.abs(error[:, 2]) < 0.25)
    assert hydro_hf.munk_efficiency() == pytest.approx(hydro_hf.MUNK_EFFICIENCY_MEDIUM, abs=5e-4)
    # The friction model (ITTC-57 x form factor at the panel surface speed) lands on the thesis's
    # own RANS drag: within 3 % of table 3.2's CFD X' at every angle.
    assert np.all(np.abs(out[:, 0] / hydro_hf.TABLE_3_2_CFD[:, 1] - 1.0) < 0.03)


def test_free_stream_symmetry_and_munk_sign():
    plus, minus = hydro_hf.hf_free_stream([[0, 0, 3.5, 2.0, 10, 8], [0, 0, 3.5, -2.0, 10, 8]], hydro_hf.COARSE)
    assert plus[0] == pytest.approx(minus[0], rel=1e-9)
    assert plus[1:] == pytest.approx(-minus[1:], rel=1e-9)
    assert plus[1] > 0.0 and plus[2] > 0.0  # table 3.2 signs: bow away gives Y' > 0 and N' > 0
    lf_plus = hydro_lf.lf_free_stream([0, 0, 3.5, 2.0, 10, 8])[0]
    assert lf_plus[1] == 0.0 and lf_plus[2] > plus[2]  # potential flow: no side force, full Munk moment


def test_hf_nan_when_hulls_touch():
    assert np.all(np.isnan(hydro_hf.hf_coefficients([0.0, 0.059, 3.5, 0.0, 5.0, 5.0], hydro_hf.COARSE)))


# --- the interaction sign pattern of thesis section 4.5 --------------------------------------------

# Mid-domain for D_sub/D_uuv = 10, L/D = 8 (thesis figure 4-4's UUV): (4.4)-(4.5) allow
# R_lat in [0.0656, 0.0816]; 0.075 leaves 0.97 m (0.93 D_uuv) between the hulls.
SWEEP = (-0.5, -0.4, -0.3, 0.3, 0.4, 0.5)


def _sweep_rows():
    return np.array([[r_long, 0.075, 3.5, 0.0, 10.0, 8.0] for r_long in SWEEP])


@pytest.fixture(scope="module")
def fidelities():
    rows = _sweep_rows()
    return {
        "lf": (hydro_lf.lf_coefficients(rows), hydro_lf.lf_free_stream(rows[:1])[0]),
        "hf": (hydro_hf.hf_coefficients(rows, hydro_hf.COARSE), hydro_hf.hf_free_stream(rows[:1], hydro_hf.COARSE)[0]),
    }


@pytest.mark.parametrize("fidelity", ["lf", "hf"])
def test_sign_pattern(fidelities, fidelity):
    """Thesis section 4.5: near the bow the UUV is pushed away with its bow turned away; near the
    stern it is pulled in with its bow turned toward; around R_long = -0.4 the interaction surge is
    positive (and here beats the drag: X' > 0).

    What potential flow gives, and is asserted: N' > 0 over the bow (+0.3..+0.5) and N' < 0 over the
    stern (-0.3..-0.5) everywhere; Y' > 0 only from +0.5 (the submarine's nose is at +0.461): the
    bow shoulder (+0.3, +0.4) sucks the UUV in; Y' < 0 over the afterbody at -0.3, while the stern
    tip (-0.5) pushes it away again. These two departures from the thesis's description are
    reported in docs/hydro/README.md.
    """
    out, free = fidelities[fidelity]
    by = dict(zip(SWEEP, out, strict=True))
    for r_long in (0.3, 0.4, 0.5):
        assert by[r_long][2] > 0.0, r_long
    for r_long in (-0.3, -0.4, -0.5):
        assert by[r_long][2] < 0.0, r_long
    assert by[0.5][1] > 0.0
    assert by[-0.3][1] < 0.0
    assert by[-0.4][0] - free[0] > 0.0
    assert by[-0.4][0] > 0.0
    # The departures, pinned so that a change is noticed.
    assert by[0.3][1] < 0.0 and by[0.4][1] < 0.0 and by[-0.5][1] > 0.0
