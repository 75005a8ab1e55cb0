"""High fidelity "two-way panel" model of the UUV-submarine interaction (docs/hydro/README.md).

The thesis's high fidelity source was steady RANS CFD (STAR-CCM+, k-omega; thesis section 3.3).
The thesis's CFD data are not public, so nearsub makes its own (docs/design.md, "Hydrodynamic
fidelities"). This replacement keeps the two-way coupling the thesis found essential (section 3.5)
and adds empirical viscous corrections:

1. Potential flow of both hulls together: 3D constant-strength source panels (Hess & Smith 1967,
   Prog. Aero. Sci. 8) on the half meshes of physics/hull.py with their z = 0 images, in the
   steady stream -U x of the submarine frame (both vehicles move at U = u through the water,
   thesis section 4.2.2). One dense solve per evaluation (scipy.linalg.solve).
2. Forces by integrating the Bernoulli pressure over the UUV panels, minus the isolated UUV's
   numerical drag (the same UUV mesh alone at the same heading: low-order pressure integration
   leaves a small spurious drag, which d'Alembert says must be zero).
3. Viscous corrections:
   - friction: ITTC-57 C_F(Re_L) times Hoerner's (1965) form factor, applied panel by panel at the
     local surface speed of the two-body solution;
   - cross-flow drag: Allen & Perkins (1951) strips on the local cross-flow of the submarine's
     field;
   - the potential yaw moment due to the UUV's own heading (its isolated Munk moment) scaled by
     a Munk efficiency calibrated on one SUBOFF drift angle of thesis table 3.2.

Inputs are rows [R_long, R_lat, u_kn, psi_deg, d_ratio, ld_ratio]; outputs the UUV body-axis
[X', Y', N'] with the signs of low_fidelity (docs/design.md, "Frames, units and signs").
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.linalg import solve

from nearsub.common.hydro.low_fidelity import NU, input_columns, ittc57
from nearsub.common.physics.hull import (
    Mesh,
    Profile,
    azimuths,
    concatenate,
    explorer_profile,
    mirror_z,
    revolution_mesh,
    suboff_profile,
)
from nearsub.common.physics.proximity import closest_distance

FOURPI = 4.0 * np.pi
FAR_FIELD = 4.0  # point-source far field beyond 4 panel sizes (about 1 % of the pairs are nearer)
_CHUNK = 512  # target points per block of the influence assembly (bounds the temporaries' memory)
_NUDGE = 1e-9  # control points sit this many panel sizes outside their panel


# --- the Hess-Smith kernel -------------------------------------------------------------------------


def _dot(a, b):
    return np.einsum("...i,...i", a, b)


def _cross(a, b):
    """Cross product over the last axis (spelled out: np.cross is slow on many short vectors)."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def _solid_angle(r1, r2, r3, n1, n2, n3):
    """Signed solid angle of triangles seen from P, given R_k = vertex_k - P and n_k = |R_k|;
    positive on the side of the normal of the counter-clockwise order (Van Oosterom & Strackee 1983,
    IEEE Trans. BME-30:125)."""
    numerator = _dot(r1, _cross(r2, r3))
    denominator = n1 * n2 * n3 + _dot(r1, r2) * n3 + _dot(r1, r3) * n2 + _dot(r2, r3) * n1
    return -2.0 * np.arctan2(numerator, denominator)


def panel_velocity(points: np.ndarray, vertices: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Velocity at points (K, 3) of unit-density flat source panels (K, 4, 3) paired row by row:
    (1/4 pi) [sum over edges of the outward edge normal times ln((ra + rb + d)/(ra + rb - d)) plus
    n times the solid angle] (Hess & Smith 1967; Katz & Plotkin 2001, Low-Speed Aerodynamics,
    ch. 10). Degenerate
    (zero-length) edges of the triangles at the tips contribute nothing."""
    rel = vertices - points[:, None, :]
    dist = np.sqrt(_dot(rel, rel))
    velocity = np.zeros_like(points)
    scale = np.max(dist, axis=1)
    for a in range(4):
        b = (a + 1) % 4
        edge = vertices[:, b] - vertices[:, a]
        length = np.sqrt(_dot(edge, edge))
        ok = length > 1e-12 * scale
        total = dist[:, a] + dist[:, b]
        log = np.where(ok, np.log(np.maximum(total + length, 1e-300) / np.maximum(total - length, 1e-300)), 0.0)
        velocity += _cross(edge, normals) * (log / np.where(ok, length, 1.0))[:, None]
    omega = _solid_angle(rel[:, 0], rel[:, 1], rel[:, 2], dist[:, 0], dist[:, 1], dist[:, 2]) + _solid_angle(
        rel[:, 0], rel[:, 2], rel[:, 3], dist[:, 0], dist[:, 2], dist[:, 3]
    )
    return (velocity + normals * omega[:, None]) / FOURPI


def _point_sources(points: np.ndarray, mesh: Mesh):
    """Far-field weights area_j / (4 pi r_ij^3) of the panels of one mesh (no image) seen as point
    sources (M, N), computed with matrix products, and the pairs closer than FAR_FIELD panel sizes
    (rows, columns) with their exact velocities."""
    centroids = mesh.centroids
    r2 = points @ centroids.T
    r2 *= -2.0
    r2 += _dot(points, points)[:, None]
    r2 += _dot(centroids, centroids)[None, :]
    near_i, near_j = np.nonzero(r2 < (FAR_FIELD * mesh.sizes) ** 2)
    np.maximum(r2, (1e-3 * mesh.sizes) ** 2, out=r2)  # only near pairs get this close: replaced
    weight = np.sqrt(r2)
    weight *= r2
    np.divide(mesh.areas / FOURPI, weight, out=weight)
    exact = panel_velocity(points[near_i], mesh.vertices[near_j], mesh.normals[near_j])
    return weight, near_i, near_j, exact


def _normal_block(points: np.ndarray, normals: np.ndarray, mesh: Mesh) -> np.ndarray:
    weight, near_i, near_j, exact = _point_sources(points, mesh)
    out = normals @ mesh.centroids.T
    np.subtract(_dot(normals, points)[:, None], out, out=out)
    out *= weight
    out[near_i, near_j] = _dot(normals[near_i], exact)
    return out


def _velocity_block(points: np.ndarray, mesh: Mesh, sigma: np.ndarray) -> np.ndarray:
    weight, near_i, near_j, exact = _point_sources(points, mesh)
    weight[near_i, near_j] = 0.0
    weight *= sigma
    velocity = points * np.sum(weight, axis=1)[:, None] - weight @ mesh.centroids
    np.add.at(velocity, near_i, exact * sigma[near_j, None])
    return velocity


def normal_influence(points: np.ndarray, normals: np.ndarray, mesh: Mesh) -> np.ndarray:
    """(M, N): normal velocity n_i . V_ij at points (M, 3) along `normals` (M, 3) due to unit source
    density on panel j of a half mesh and on its z = 0 image."""
    image = mirror_z(mesh)
    out = np.empty((len(points), len(mesh)))
    for start in range(0, len(points), _CHUNK):
        rows = slice(start, start + _CHUNK)
        out[rows] = _normal_block(points[rows], normals[rows], mesh)
        out[rows] += _normal_block(points[rows], normals[rows], image)
    return out


def induced_velocity(points: np.ndarray, mesh: Mesh, sigma: np.ndarray) -> np.ndarray:
    """(M, 3): velocity at points due to source densities sigma on a half mesh and its image."""
    image = mirror_z(mesh)
    out = np.empty((len(points), 3))
    for start in range(0, len(points), _CHUNK):
        rows = slice(start, start + _CHUNK)
        out[rows] = _velocity_block(points[rows], mesh, sigma) + _velocity_block(points[rows], image, sigma)
    return out


def solve_sources(mesh: Mesh, onset: np.ndarray) -> np.ndarray:
    """Source densities making the normal velocity vanish at every control point of the (half,
    mirrored) mesh in the uniform stream `onset`: sum_j sigma_j n_i.V_ij = -onset.n_i."""
    matrix = normal_influence(_control_points(mesh), mesh.normals, mesh)
    return solve(matrix, -mesh.normals @ onset, check_finite=False)


def _control_points(mesh: Mesh) -> np.ndarray:
    """Panel centroids nudged outward so each panel's own solid angle is +2 pi (self term sigma/2)."""
    return mesh.centroids + _NUDGE * mesh.sizes[:, None] * mesh.normals


def surface_velocity(mesh: Mesh, sources: Mesh, sigma: np.ndarray, onset: np.ndarray) -> np.ndarray:
    """Total velocity (M, 3) at the control points of `mesh` due to the stream and the sources."""
    return onset + induced_velocity(_control_points(mesh), sources, sigma)


def pressure_force(mesh: Mesh, velocity: np.ndarray, speed: float, about: np.ndarray) -> tuple[np.ndarray, float]:
    """Force (x, y) and yaw moment about `about` on the whole body from the Bernoulli pressure on a
    half mesh, over (1/2) rho U^2: F = -sum Cp n A with Cp = 1 - |V|^2/U^2, doubled for the image
    half (its z-force cancels). Pressure integration converges far better than Lagally for
    moments (the spheroid Munk moment, tests/test_hydro.py)."""
    cp = 1.0 - np.sum(velocity**2, axis=1) / speed**2
    df = -(cp * mesh.areas)[:, None] * mesh.normals
    return _totals(mesh, df, about)


def _totals(mesh: Mesh, df: np.ndarray, about: np.ndarray) -> tuple[np.ndarray, float]:
    """Whole-body force (x, y) and yaw moment from half-mesh panel forces."""
    arm = mesh.centroids - about
    moment = np.sum(arm[:, 0] * df[:, 1] - arm[:, 1] * df[:, 0])
    return 2.0 * np.sum(df[:, :2], axis=0), 2.0 * moment


# --- viscous corrections (docs/hydro/README.md, high fidelity) -----------------------------------

C_DC = 1.2  # cross-flow drag coefficient of a circular cylinder, subcritical Re_c
# Munk efficiency: the share of the isolated potential (Munk) yaw moment that a real hull feels
# calibrated on the EFD N' of thesis table 3.2 at psi = 2.08 deg,
# the table's angle nearest the surrogate's |psi| <= 2 deg. `munk_efficiency(panels)` recomputes it
# for each mesh spec so that it also absorbs the mesh's Munk-moment error; for MEDIUM it is:
MUNK_EFFICIENCY_MEDIUM = 0.943
CALIBRATION_ANGLE = 2.08  # [deg]
# SUBOFF tow-tank conditions for table 3.2: U = 3.05 m/s (thesis table 3.1) in fresh water with
# the thesis's mu = 8.899e-4 Pa s and rho = 997 kg/m^3 (thesis section 3.2).
SUBOFF_TEST_SPEED = 3.05
SUBOFF_TEST_NU = 8.899e-4 / 997.0
# Thesis table 3.2 (EFD, Roddy 1990 via the thesis's [51]): psi [deg] and X', Y', N' (x 1e-3).
TABLE_3_2_EFD = np.array(
    [
        [2.08, -1.045, 0.134, 0.517],
        [4.07, -1.061, 0.449, 0.996],
        [6.03, -1.059, 0.886, 1.385],
        [8.00, -1.069, 1.536, 1.708],
        [10.05, -1.049, 2.450, 2.008],
    ]
)
TABLE_3_2_CFD = np.array(  # the thesis's own STAR-CCM+ values, same table
    [
        [2.08, -0.962, 0.213, 0.473],
        [4.07, -0.964, 0.452, 0.916],
        [6.03, -0.966, 0.760, 1.329],
        [8.00, -0.968, 1.189, 1.709],
        [10.05, -0.966, 1.796, 2.062],
    ]
)


def hoerner_form_factor(d_over_l):
    """1 + k = 1 + 1.5 (D/L)^1.5 + 7 (D/L)^3 for bodies of revolution (Hoerner 1965, Fluid-Dynamic
    Drag)."""
    return 1.0 + 1.5 * d_over_l**1.5 + 7.0 * d_over_l**3


def crossflow_efficiency(l_over_d):
    """Allen & Perkins' (1951, NACA TR-1048) finite-length factor eta: about 0.6 at L/D = 4 to 0.7
    at L/D = 12-13, interpolated linearly between those ends."""
    return np.interp(l_over_d, [4.0, 12.5], [0.6, 0.7])


def _friction(mesh: Mesh, velocity: np.ndarray, about: np.ndarray, cf_total: float) -> tuple[np.ndarray, float]:
    """Skin friction over (1/2) rho U^2: tau = C_F (1 + k) |V_t| V_t on every panel, along the
    local tangential velocity, so friction grows with the local speed near the submarine."""
    tangential = velocity - np.sum(velocity * mesh.normals, axis=1)[:, None] * mesh.normals
    speed = np.linalg.norm(tangential, axis=1)
    return _totals(mesh, cf_total * (speed * mesh.areas)[:, None] * tangential, about)


def _crossflow(xi: np.ndarray, r: np.ndarray, v_cross: np.ndarray, l_over_d: float) -> tuple[float, float]:
    """Cross-flow drag strips over (1/2) rho U^2: f = eta C_dc 2r V_c |V_c| (Allen & Perkins 1951,
    NACA TR-1048), pushing the section along the cross-flow V_c; returns (Y, N about xi = 0)."""
    f = crossflow_efficiency(l_over_d) * C_DC * 2.0 * r * v_cross * np.abs(v_cross)
    return float(np.trapezoid(f, xi)), float(np.trapezoid(xi * f, xi))


# --- meshes and the isolated body ------------------------------------------------------------------


@dataclass(frozen=True)
class Panels:
    """Panel counts. Half meshes (z >= 0): azimuth counts are per half. The submarine gets
    `sub_stations` stations cosine/arc-length spaced plus a refined window beside the UUV with an
    axial spacing of `window_spacing` UUV diameters. The defaults put
    the panels where docs/hydro/panel-convergence.md found the error: on the UUV, not the submarine."""

    sub_stations: int = 80
    sub_azimuths: int = 16
    sub_azimuth_power: float = 2.0
    window_spacing: float = 0.5
    uuv_stations: int = 60
    uuv_azimuths: int = 12


COARSE = Panels(sub_stations=50, sub_azimuths=10, window_spacing=1.0, uuv_stations=30, uuv_azimuths=8)
MEDIUM = Panels()
FINE = Panels(sub_stations=100, sub_azimuths=24, window_spacing=0.35, uuv_stations=120, uuv_azimuths=24)


@dataclass(frozen=True)
class IsolatedBody:
    """A body alone (body frame, CB origin) and its surface velocities for unit onsets +x and +y;
    the flow at any heading is their combination."""

    mesh: Mesh
    profile: Profile
    wx: np.ndarray
    wy: np.ndarray

    def potential(self, psi: float) -> tuple[np.ndarray, float, np.ndarray]:
        """Pressure force (x, y), yaw moment and surface velocity in the stream at heading psi,
        unit speed, body axes (the stream is -(cos psi, -sin psi) in body axes)."""
        velocity = -np.cos(psi) * self.wx + np.sin(psi) * self.wy
        force, moment = pressure_force(self.mesh, velocity, 1.0, np.zeros(3))
        return force, moment, velocity


@lru_cache(maxsize=64)
def isolated_body(hull: str, ld_ratio: float, stations: int, n_azimuths: int) -> IsolatedBody:
    """Isolated UUV of unit diameter (hull "explorer", L/D = ld_ratio) or the model-scale SUBOFF
    (hull "suboff"), meshed with `stations` x `n_azimuths` (cosine in azimuth: both in-plane sides
    resolved). Cached: coefficients are scale-free, so one solution serves every UUV size."""
    if hull == "explorer":
        profile = explorer_profile(stations, ld_ratio, 1.0)
    elif hull == "suboff":
        profile = suboff_profile(stations, model_scale=True)
    else:
        raise ValueError(f"unknown hull {hull!r}")
    mesh = revolution_mesh(profile, azimuths(n_azimuths, both_ends=True))
    points = _control_points(mesh)
    sigma = solve(normal_influence(points, mesh.normals, mesh), -mesh.normals @ np.eye(3)[:, :2], check_finite=False)
    wx, wy = (surface_velocity(mesh, mesh, sigma[:, k], np.eye(3)[k]) for k in range(2))
    return IsolatedBody(mesh, profile, wx, wy)


def _free_body(body: IsolatedBody, psi: float, reynolds: float, efficiency: float) -> tuple[np.ndarray, np.ndarray]:
    """Isolated-body [X', Y', N'] with the viscous corrections and the Munk moment scaled by
    `efficiency`, and the potential part alone."""
    length = body.profile.length
    diameter = 2.0 * np.max(body.profile.r)
    force, moment, velocity = body.potential(psi)
    potential = np.array([force[0] / length**2, force[1] / length**2, moment / length**3])
    cf_total = float(ittc57(reynolds)) * hoerner_form_factor(diameter / length)
    f_force, f_moment = _friction(body.mesh, velocity, np.zeros(3), cf_total)
    xi, r = body.profile.x[::-1], body.profile.r[::-1]
    y_cross, n_cross = _crossflow(xi, r, np.full_like(xi, np.sin(psi)), length / diameter)
    viscous = np.array([f_force[0] / length**2, (f_force[1] + y_cross) / length**2, (f_moment + n_cross) / length**3])
    # The potential X and Y of a closed body are zero (d'Alembert): what the panels give is
    # numerical drag, dropped here as in the two-body case.
    return viscous + np.array([0.0, 0.0, efficiency * potential[2]]), potential


def suboff_drift(psi_deg, panels: Panels = MEDIUM) -> np.ndarray:
    """[X', Y', N'] of the model-scale SUBOFF alone at drift angles psi_deg (thesis table 3.2
    conditions), meshed like a UUV of the `panels` spec: the calibration and validation case."""
    body, reynolds = _suboff_model(panels)
    efficiency = munk_efficiency(panels)
    return np.array([_free_body(body, np.radians(p), reynolds, efficiency)[0] for p in np.atleast_1d(psi_deg)])


def _suboff_model(panels: Panels) -> tuple[IsolatedBody, float]:
    """The model-scale SUBOFF meshed like a UUV of this spec, and its tow-tank Reynolds number."""
    body = isolated_body("suboff", 0.0, panels.uuv_stations, panels.uuv_azimuths)
    return body, SUBOFF_TEST_SPEED * body.profile.length / SUBOFF_TEST_NU


def munk_efficiency(panels: Panels = MEDIUM) -> float:
    """The Munk efficiency that makes the SUBOFF N' at CALIBRATION_ANGLE equal thesis table 3.2's
    EFD value, given the friction and cross-flow moments."""
    return _munk_efficiency(panels)


@lru_cache(maxsize=16)
def _munk_efficiency(panels: Panels) -> float:
    body, reynolds = _suboff_model(panels)
    target = TABLE_3_2_EFD[TABLE_3_2_EFD[:, 0] == CALIBRATION_ANGLE, 3][0] * 1e-3
    viscous, potential = _free_body(body, np.radians(CALIBRATION_ANGLE), reynolds, 0.0)
    return float((target - viscous[2]) / potential[2])


# --- the two-body evaluation -----------------------------------------------------------------------


def submarine_mesh(x_lo: float, x_hi: float, spacing: float, panels: Panels) -> Mesh:
    """Full-scale SUBOFF half mesh in the submarine frame, refined to `spacing` between frame x_lo
    and x_hi and clustered in azimuth towards +y, the UUV's side."""
    profile = suboff_profile(panels.sub_stations, window=(x_lo, x_hi), window_spacing=spacing)
    return revolution_mesh(profile, azimuths(panels.sub_azimuths, power=panels.sub_azimuth_power))


def two_body_meshes(x_c, y_c, psi, diameter, length, panels: Panels):
    """The UUV's isolated body, its placed half mesh and the submarine's half mesh refined beside
    it (window: the UUV's extent plus two diameters and the clearance each way), for one pose;
    None if the hulls touch."""
    clearance = float(closest_distance(x_c, y_c, psi, length, diameter))
    if not clearance > 0.0:
        return None
    ld = length / diameter
    body = isolated_body("explorer", ld, panels.uuv_stations, panels.uuv_azimuths)
    uuv = body.mesh.scaled(diameter).placed(x_c, y_c, psi)
    nose = x_c + body.profile.cb * diameter * np.cos(psi)
    tail = x_c - (ld - body.profile.cb) * diameter * np.cos(psi)
    margin = 2.0 * diameter + clearance
    sub = submarine_mesh(tail - margin, nose + margin, panels.window_spacing * diameter, panels)
    return body, uuv, sub


def _two_body(x_c, y_c, speed, psi, diameter, length, panels: Panels) -> np.ndarray:
    """[X', Y', N'] of one UUV pose (module doc, steps 1-3); NaN if the hulls touch."""
    meshes = two_body_meshes(x_c, y_c, psi, diameter, length, panels)
    if meshes is None:
        return np.full(3, np.nan)
    body, uuv, sub = meshes
    ld = length / diameter
    cos_psi, sin_psi = np.cos(psi), np.sin(psi)
    both = concatenate([sub, uuv])
    onset = np.array([-1.0, 0.0, 0.0])  # unit stream; the potential coefficients do not depend on U
    sigma = solve_sources(both, onset)
    velocity = surface_velocity(uuv, both, sigma, onset)
    about = np.array([x_c, y_c, 0.0])
    e_xi, e_eta = np.array([cos_psi, sin_psi]), np.array([-sin_psi, cos_psi])
    scale = np.array([length**2, length**2, length**3])
    force, moment = pressure_force(uuv, velocity, 1.0, about)
    # Isolated UUV at the same heading: its X, Y are numerical drag (d'Alembert), its N the Munk
    # moment, of which the real hull feels the share munk_efficiency.
    iso_force, iso_moment, _ = body.potential(psi)
    iso = np.array([iso_force[0] / ld**2, iso_force[1] / ld**2, (1.0 - munk_efficiency(panels)) * iso_moment / ld**3])
    potential = np.array([force @ e_xi, force @ e_eta, moment]) / scale - iso
    cf_total = float(ittc57(speed * length / NU)) * hoerner_form_factor(1.0 / ld)
    f_force, f_moment = _friction(uuv, velocity, about, cf_total)
    # Cross-flow of the stream plus the submarine's sources at the UUV's axis stations.
    xi = body.profile.x[::-1] * diameter
    axis = np.column_stack([x_c + xi * cos_psi, y_c + xi * sin_psi, np.zeros_like(xi)])
    external = onset + induced_velocity(axis, sub, sigma[: len(sub)])
    y_cross, n_cross = _crossflow(xi, body.profile.r[::-1] * diameter, external[:, :2] @ e_eta, ld)
    viscous = np.array([f_force @ e_xi, f_force @ e_eta + y_cross, f_moment + n_cross]) / scale
    return potential + viscous


def hf_coefficients(inputs, panels: Panels = MEDIUM) -> np.ndarray:
    """High-fidelity [X', Y', N'] (n, 3) for input rows [R_long, R_lat, u_kn, psi_deg, d_ratio,
    ld_ratio] (thesis table 4.2), one panel solve per row: about 1 s at MEDIUM, 0.2 s at COARSE,
    12 s at FINE (docs/hydro/README.md). Rows whose hulls touch are NaN."""
    x_c, y_c, speed, psi, diameter, length = input_columns(inputs)
    return np.array(
        [_two_body(*row, panels) for row in zip(x_c, y_c, speed, psi, diameter, length, strict=True)]
    ).reshape(-1, 3)


def hf_free_stream(inputs, panels: Panels = MEDIUM) -> np.ndarray:
    """The same model's [X', Y', N'] for the UUV alone at that speed and heading (R_long, R_lat
    ignored). The interaction increment (docs/design.md, "Physics decisions") is
    hf_coefficients - hf_free_stream."""
    _, _, speed, psi, diameter, length = input_columns(inputs)
    out = []
    for u, heading, d, big_l in zip(speed, psi, diameter, length, strict=True):
        body = isolated_body("explorer", big_l / d, panels.uuv_stations, panels.uuv_azimuths)
        out.append(_free_body(body, heading, u * big_l / NU, munk_efficiency(panels))[0])
    return np.array(out).reshape(-1, 3)
