"""Hull geometry: the DARPA SUBOFF submarine and the Explorer-shaped UUV.

Both hulls are bodies of revolution, so one radius function r(s) of the distance s from the nose
describes each. In the 3-DOF plane (the plane of both axes; docs/design.md, "Frames, units and
signs") the outline is |y| <= r(s). Frames:
- Submarine frame: origin at the submarine's centre of buoyancy (CB), x forward (bow at +x).
  The SUBOFF offsets (Groves, Huang & Chang 1989) give no CB, so the CB is the volume centroid
  of the bare hull computed here from the offsets: 2.0086 m behind the nose at model scale
  (0.4611 L), 40.976 m behind the nose at full scale. The bow tip sits at x = +40.976 m, the
  stern tip at x = -47.889 m.
- UUV body frame: origin at the UUV's CB (thesis section 5.4), also taken as the volume centroid
  of its Explorer profile, x forward.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

FT = 0.3048  # international foot [m]

# DARPA SUBOFF bare hull, model scale in feet: the DARPA2GEN offset formulas of Groves, Huang &
# Chang (1989), DTRC/SHD-1298-01
SUBOFF_RMAX_FT = 0.8333333  # R_max (D = 0.508 m)
SUBOFF_BOW_END_FT = 3.333333  # bow / parallel middle body joint
SUBOFF_PMB_END_FT = 10.645833  # parallel middle body / afterbody joint
SUBOFF_AFT_END_FT = 13.979167  # afterbody / cap joint
SUBOFF_LENGTH_FT = 14.291667  # overall length L = 4.3561 m
_RH = 0.1175  # r_h, afterbody end radius / R_max (Groves et al. 1989)
_K0 = 10.0  # afterbody slope parameter K0 (Groves et al. 1989)
_K1 = 44.6244  # afterbody curvature parameter K1 (Groves et al. 1989)

# Thesis submarine: SUBOFF scaled to D = 34 ft (thesis section 5.9; docs/design.md, "Frames, units
# and signs")
SUBOFF_SCALE = 34.0 / (2.0 * SUBOFF_RMAX_FT)  # k = 20.4
D_SUB = 2.0 * SUBOFF_RMAX_FT * SUBOFF_SCALE * FT  # 10.363 m
R_SUB = 0.5 * D_SUB
L_SUB = SUBOFF_LENGTH_FT * SUBOFF_SCALE * FT  # 88.86 m


@dataclass(frozen=True)
class RevolutionProperties:
    """Volume, wetted area and volume centroid (distance from the nose) of a body of revolution."""

    volume: float
    wetted_area: float
    centroid: float


def suboff_model_radius_ft(x_ft):
    """SUBOFF bare-hull radius in feet at x feet from the nose, exactly the DARPA2GEN formulas
    of Groves, Huang & Chang (1989)."""
    x = np.asarray(x_ft, dtype=float)
    rm = SUBOFF_RMAX_FT
    a = 0.3 * x - 1.0
    bow = 1.126395101 * x * a**4 + 0.442874707 * x**2 * a**3 + 1.0 - a**4 * (1.2 * x + 1.0)
    xi = (SUBOFF_AFT_END_FT - x) / 3.333333
    aft = (
        _RH**2
        + _RH * _K0 * xi**2
        + (20 - 20 * _RH**2 - 4 * _RH * _K0 - _K1 / 3) * xi**3
        + (-45 + 45 * _RH**2 + 6 * _RH * _K0 + _K1) * xi**4
        + (36 - 36 * _RH**2 - 4 * _RH * _K0 - _K1) * xi**5
        + (-10 + 10 * _RH**2 + _RH * _K0 + _K1 / 3) * xi**6
    )
    cap = 1.0 - (3.2 * x - 44.733333) ** 2
    # The printed constants leave round-off of order 1e-6 at the ends; clip it before the roots.
    r = np.select(
        [
            x < 0.0,
            x <= SUBOFF_BOW_END_FT,
            x <= SUBOFF_PMB_END_FT,
            x <= SUBOFF_AFT_END_FT,
            x <= SUBOFF_LENGTH_FT,
        ],
        [
            0.0,
            rm * np.maximum(bow, 0.0) ** (1.0 / 2.1),
            rm,
            rm * np.sqrt(np.maximum(aft, 0.0)),
            _RH * rm * np.sqrt(np.maximum(cap, 0.0)),
        ],
        default=0.0,
    )
    return r


def suboff_radius(x_from_nose_m):
    """Full-scale submarine radius [m] at a distance [m] from the nose (0 outside the hull)."""
    scale = SUBOFF_SCALE * FT
    return suboff_model_radius_ft(np.asarray(x_from_nose_m, dtype=float) / scale) * scale


SUBOFF_JOINTS_M = tuple(
    s * SUBOFF_SCALE * FT for s in (SUBOFF_BOW_END_FT, SUBOFF_PMB_END_FT, SUBOFF_AFT_END_FT)
)  # 20.73, 66.19, 86.92 m


def revolution_properties(radius, breakpoints, n: int = 4000) -> RevolutionProperties:
    """Integrate a piecewise body of revolution numerically.

    Each piece between breakpoints gets n cosine-clustered stations, so the blunt nose (where
    dr/ds is infinite) and the joints are resolved. Volume and centroid use the trapezoid rule on
    pi r^2; the wetted area sums conical frustums, which stays finite at a blunt nose.
    """
    theta = np.linspace(0.0, np.pi, n)
    pieces = [a + 0.5 * (b - a) * (1.0 - np.cos(theta)) for a, b in zip(breakpoints[:-1], breakpoints[1:], strict=True)]
    s = np.unique(np.concatenate(pieces))
    r = radius(s)
    area = np.pi * r**2
    volume = np.trapezoid(area, s)
    moment = np.trapezoid(area * s, s)
    wetted = np.sum(np.pi * (r[1:] + r[:-1]) * np.hypot(np.diff(s), np.diff(r)))
    return RevolutionProperties(float(volume), float(wetted), float(moment / volume))


@lru_cache(maxsize=1)
def suboff_properties() -> RevolutionProperties:
    """Full-scale SUBOFF volume, wetted area and CB (volume centroid, from the nose)."""
    return revolution_properties(suboff_radius, (0.0, *SUBOFF_JOINTS_M, L_SUB))


SUB_CB_FROM_NOSE = suboff_properties().centroid  # 40.976 m: volume centroid (see module doc)
SUB_BOW_X = SUB_CB_FROM_NOSE  # bow tip in the submarine frame
SUB_STERN_X = SUB_CB_FROM_NOSE - L_SUB  # stern tip in the submarine frame


def submarine_half_width(x_frame):
    """Half-width |y| of the submarine outline at frame x (CB origin, bow +x); 0 off the hull."""
    return suboff_radius(SUB_CB_FROM_NOSE - np.asarray(x_frame, dtype=float))


def _cosine_stations(length: float, n: int) -> np.ndarray:
    """n stations from 0 to length, clustered at both ends where the profiles curve most."""
    return 0.5 * length * (1.0 - np.cos(np.linspace(0.0, np.pi, n)))


def _closed_outline(x_nose_to_tail: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Upper side nose to tail, lower side back, tips not repeated, first point appended."""
    x = np.concatenate([x_nose_to_tail, x_nose_to_tail[-2:0:-1], x_nose_to_tail[:1]])
    y = np.concatenate([r, -r[-2:0:-1], r[:1]])
    return x, y


def submarine_outline(n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Closed polygon (x, y) of the submarine in its frame, n stations per side, for plots."""
    s = _cosine_stations(L_SUB, n)
    return _closed_outline(SUB_CB_FROM_NOSE - s, suboff_radius(s))


# Explorer-shaped UUV, thesis (3.1) bow ellipse and (3.2) stern paraboloid (thesis section 3.2)
def explorer_radius(s, length: float, diameter: float):
    """Explorer hull radius at s from the nose: ellipse (3.1) over 2R, cylinder, paraboloid (3.2)
    over 4R with a pointed tail. Requires length >= 3 diameter (L = 6R + L_p, L_p >= 0); length
    may be an array that broadcasts with s (one hull per row)."""
    radius = 0.5 * diameter
    parallel = length - 6.0 * radius  # L_p (L = 6R + L_p)
    if np.any(parallel < 0.0):
        raise ValueError(f"Explorer hull needs length >= 3 diameters, got L={length}, D={diameter}")
    s = np.asarray(s, dtype=float)
    bow = radius * np.sqrt(np.maximum(1.0 - ((s - 2.0 * radius) / (2.0 * radius)) ** 2, 0.0))  # (3.1)
    stern = radius * (1.0 - ((s - 2.0 * radius - parallel) / (4.0 * radius)) ** 2)  # (3.2)
    return np.select(
        [s < 0.0, s <= 2.0 * radius, s <= 2.0 * radius + parallel, s <= length],
        [0.0, bow, radius, np.maximum(stern, 0.0)],
        default=0.0,
    )


@lru_cache(maxsize=64)
def explorer_cb_from_nose(length: float, diameter: float) -> float:
    """UUV CB: volume centroid of the Explorer profile, measured from the nose (cached: every
    outline needs it)."""
    radius = 0.5 * diameter
    props = revolution_properties(
        lambda s: explorer_radius(s, length, diameter),
        (0.0, 2.0 * radius, length - 4.0 * radius, length),
        n=400,
    )
    return props.centroid


def uuv_body_outline(length: float, diameter: float, n: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Closed Explorer outline in the UUV body frame (origin at its CB, bow +x)."""
    s = _cosine_stations(length, n)
    return _closed_outline(explorer_cb_from_nose(length, diameter) - s, explorer_radius(s, length, diameter))


def uuv_outline(x, y, psi, length: float, diameter: float, n: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Closed UUV outline placed at CB position (x, y) and heading psi (from +x towards +y).

    x, y, psi broadcast together; the result has shape broadcast_shape + (2n - 1,).
    """
    bx, by = uuv_body_outline(length, diameter, n)
    x, y, psi = (np.asarray(a, dtype=float)[..., None] for a in (x, y, psi))
    cos_psi, sin_psi = np.cos(psi), np.sin(psi)
    return x + bx * cos_psi - by * sin_psi, y + bx * sin_psi + by * cos_psi


# -- Profiles and panel meshes --------------------------------------------------------------
# The radius functions come from hull.py (SUBOFF, Explorer); this module only places stations and
# panels on them.
#
# Frames (docs/design.md, "Frames, units and signs"): a body frame has its origin at the body's
# centre of buoyancy (CB) with x forward, so a station at distance s from the nose sits at
# x = cb - s. Meshes cover the half z >= 0 of the surface: both hulls' axes lie in the plane z = 0,
# which is therefore a plane of symmetry of the flow (thesis section 3.3.3.1 uses the same symmetry
# plane in its CFD). `mirror_z` gives the image half.
#
# Half-mesh azimuth theta runs from 0 (facing +y) to pi (facing -y) through +z: y = r cos(theta),
# z = r sin(theta). Panels are flat quads (planar: isosceles trapezoids between two stations and two
# azimuths), degenerate to triangles at the pointed tips, ordered counter-clockwise about the
# outward normal (the edge and solid-angle formulas of high_fidelity.panel_velocity expect it).

_DENSE = 400  # dense meridian samples per smooth piece, for arc lengths and station placement


@dataclass(frozen=True)
class Profile:
    """Stations of a body of revolution: s from the nose (increasing), radius r, length, CB from nose."""

    s: np.ndarray
    r: np.ndarray
    length: float
    cb: float

    @property
    def x(self) -> np.ndarray:
        """Body-frame x of the stations (CB origin, bow +x): decreasing from the nose."""
        return self.cb - self.s


@dataclass(frozen=True)
class Mesh:
    """Flat panels: vertices (N, 4, 3) counter-clockwise about the outward normal, and what the
    panel method needs of them (centroid control points, unit normals, areas, max diagonal)."""

    vertices: np.ndarray
    centroids: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    sizes: np.ndarray

    @classmethod
    def from_vertices(cls, vertices: np.ndarray) -> Mesh:
        """Derive normals and areas from the diagonals (exact for planar quads and for triangles
        with a repeated vertex) and centroids from the two triangles (0,1,2) and (0,2,3)."""
        v = np.asarray(vertices, dtype=float)
        d1, d2 = v[:, 2] - v[:, 0], v[:, 3] - v[:, 1]
        cross = np.cross(d1, d2)
        twice_area = np.linalg.norm(cross, axis=1)
        normals = cross / np.maximum(twice_area, 1e-300)[:, None]
        a1 = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
        a2 = 0.5 * np.linalg.norm(np.cross(v[:, 2] - v[:, 0], v[:, 3] - v[:, 0]), axis=1)
        c1, c2 = (v[:, 0] + v[:, 1] + v[:, 2]) / 3.0, (v[:, 0] + v[:, 2] + v[:, 3]) / 3.0
        centroids = (a1[:, None] * c1 + a2[:, None] * c2) / np.maximum(a1 + a2, 1e-300)[:, None]
        sizes = np.maximum(np.linalg.norm(d1, axis=1), np.linalg.norm(d2, axis=1))
        return cls(v, centroids, normals, 0.5 * twice_area, sizes)

    def __len__(self) -> int:
        return len(self.areas)

    def placed(self, x: float, y: float, psi: float) -> Mesh:
        """This body-frame mesh turned by psi about z (from +x towards +y) and moved to (x, y, 0)."""
        c, s = np.cos(psi), np.sin(psi)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        shift = np.array([x, y, 0.0])
        return Mesh(
            self.vertices @ rot.T + shift,
            self.centroids @ rot.T + shift,
            self.normals @ rot.T,
            self.areas,
            self.sizes,
        )

    def scaled(self, factor: float) -> Mesh:
        """The mesh scaled about the origin (the panel method's coefficients are scale-free)."""
        return Mesh(
            self.vertices * factor, self.centroids * factor, self.normals, self.areas * factor**2, self.sizes * factor
        )


def concatenate(meshes: Sequence[Mesh]) -> Mesh:
    """One mesh holding the panels of several bodies, in order."""
    return Mesh(
        *(
            np.concatenate([getattr(m, f) for m in meshes])
            for f in ("vertices", "centroids", "normals", "areas", "sizes")
        )
    )


def mirror_z(mesh: Mesh) -> Mesh:
    """Image of a half mesh in the plane z = 0, with the vertex order reversed so that the normals
    still point out of the body. With the same source strength on each panel and its image, the
    normal velocity through z = 0 vanishes (method of images)."""
    flip = np.array([1.0, 1.0, -1.0])
    return Mesh(
        mesh.vertices[:, ::-1] * flip,
        mesh.centroids * flip,
        mesh.normals * flip,
        mesh.areas,
        mesh.sizes,
    )


def _dense_meridian(radius: Callable, breakpoints: Sequence[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dense (s, r, arc length) along the meridian, cosine-clustered on each smooth piece so the
    blunt nose (infinite dr/ds) and the joints are resolved (as hull.revolution_properties does)."""
    theta = np.linspace(0.0, np.pi, _DENSE)
    pieces = [a + 0.5 * (b - a) * (1.0 - np.cos(theta)) for a, b in zip(breakpoints[:-1], breakpoints[1:], strict=True)]
    s = np.unique(np.concatenate(pieces))
    r = np.asarray(radius(s), dtype=float)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(s), np.diff(r)))])
    return s, r, arc


def place_stations(
    radius: Callable,
    breakpoints: Sequence[float],
    n: int,
    *,
    end_clustering: float = 0.5,
    window: tuple[float, float] | None = None,
    window_spacing: float | None = None,
    growth: float = 0.2,
) -> tuple[np.ndarray, np.ndarray]:
    """Stations (s, r) spaced along the meridian's arc length.

    The base distribution has n stations, a blend of uniform and cosine spacing (weight
    `end_clustering`) so the curved ends get small panels. `window` = (s_lo, s_hi) adds a region
    where the arc-length spacing is at most `window_spacing`, graded geometrically outside it (the
    spacing grows by `growth` times the distance from the window): the submarine panels next to
    the UUV must be comparable to the UUV's size and clearance (docs/hydro/README.md).
    """
    s_dense, _, arc = _dense_meridian(radius, breakpoints)
    total = arc[-1]
    t = np.linspace(0.0, 1.0, 20001)
    base_arc = total * ((1.0 - end_clustering) * t + end_clustering * 0.5 * (1.0 - np.cos(np.pi * t)))
    # Station density per unit arc length: the base one, raised to 1/spacing near the window.
    ell = np.linspace(0.0, total, 20001)
    density = (n - 1) * np.gradient(np.interp(ell, base_arc, t), ell)
    if window is not None:
        lo, hi = np.interp(np.clip(np.sort(window), 0.0, s_dense[-1]), s_dense, arc)
        distance = np.maximum(np.maximum(lo - ell, ell - hi), 0.0)
        density = np.maximum(density, 1.0 / (window_spacing + growth * distance))
    cumulative = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(ell))])
    count = max(int(np.ceil(cumulative[-1])), n - 1) + 1
    station_arc = np.interp(np.linspace(0.0, cumulative[-1], count), cumulative, ell)
    s = np.interp(station_arc, arc, s_dense)
    s[0], s[-1] = s_dense[0], s_dense[-1]
    return s, np.asarray(radius(s), dtype=float)


def profile_from_radius(
    radius: Callable, breakpoints: Sequence[float], n: int, cb: float | None = None, **station_options
) -> Profile:
    """Profile of any body of revolution given r(s) and the s of its nose, joints and tail.

    The CB defaults to the volume centroid (hull.py's convention for both hulls)."""
    s, r = place_stations(radius, breakpoints, n, **station_options)
    if cb is None:
        s_dense, r_dense, _ = _dense_meridian(radius, breakpoints)
        area = np.pi * r_dense**2
        cb = float(np.trapezoid(area * s_dense, s_dense) / np.trapezoid(area, s_dense))
    return Profile(s, r, float(breakpoints[-1] - breakpoints[0]), float(cb))


def suboff_profile(
    n: int, *, model_scale: bool = False, window: tuple[float, float] | None = None, window_spacing: float | None = None
) -> Profile:
    """SUBOFF bare hull (hull.py), full scale D = 10.363 m by default or model scale D = 0.508 m.

    `window` is a range of submarine-frame x to refine (see `place_stations`); CB at 0.4611 L from
    the nose at both scales (hull.py)."""
    factor = 1.0 if not model_scale else 1.0 / SUBOFF_SCALE
    length = L_SUB * factor
    joints = [j * factor for j in SUBOFF_JOINTS_M]
    cb = SUB_CB_FROM_NOSE * factor

    def radius(s):
        if model_scale:
            return suboff_model_radius_ft(np.asarray(s) / FT) * FT
        return suboff_radius(s)

    s_window = None if window is None else (cb - window[1], cb - window[0])
    return profile_from_radius(radius, (0.0, *joints, length), n, cb=cb, window=s_window, window_spacing=window_spacing)


def uuv_dimensions(d_ratio, ld_ratio) -> tuple[np.ndarray, np.ndarray]:
    """UUV diameter and length [m] from D_sub/D_uuv and L/D_uuv (thesis table 4.2)."""
    diameter = D_SUB / np.asarray(d_ratio, dtype=float)
    return diameter, np.asarray(ld_ratio, dtype=float) * diameter


def explorer_profile(n: int, length: float, diameter: float) -> Profile:
    """Explorer UUV, thesis (3.1)/(3.2) through hull.explorer_radius; CB from hull.py."""
    radius = 0.5 * diameter
    return profile_from_radius(
        lambda s: explorer_radius(s, length, diameter),
        (0.0, 2.0 * radius, length - 4.0 * radius, length),
        n,
        cb=explorer_cb_from_nose(length, diameter),
    )


def azimuths(n: int, *, power: float = 1.0, both_ends: bool = False) -> np.ndarray:
    """n + 1 half-mesh azimuth nodes from 0 to pi.

    power > 1 clusters them towards theta = 0 (the +y side: the submarine's side facing the UUV,
    docs/hydro/README.md, high fidelity); both_ends uses cosine spacing, clustering both
    in-plane sides (the UUV's side facing the submarine and its far side)."""
    t = np.linspace(0.0, 1.0, n + 1)
    if both_ends:
        return 0.5 * np.pi * (1.0 - np.cos(np.pi * t))
    return np.pi * t**power


def revolution_mesh(profile: Profile, theta: np.ndarray) -> Mesh:
    """Half-surface (z >= 0) quad mesh of a body of revolution in its body frame."""
    x = profile.x[:, None]
    r = profile.r[:, None]
    grid = np.stack(np.broadcast_arrays(x, r * np.cos(theta), r * np.sin(theta)), axis=-1)  # (stations, azimuths, 3)
    a, b = grid[:-1, :-1], grid[1:, :-1]
    c, d = grid[1:, 1:], grid[:-1, 1:]
    # Stations run nose to tail (x decreasing) and theta from +y to +z: the order (a, b, c, d) is
    # counter-clockwise seen from outside.
    vertices = np.stack([a, b, c, d], axis=2).reshape(-1, 4, 3)
    mesh = Mesh.from_vertices(vertices)
    keep = mesh.areas > 1e-14 * profile.length**2  # drop the zero-area "panels" on the axis at the tips
    return Mesh(*(getattr(mesh, f)[keep] for f in ("vertices", "centroids", "normals", "areas", "sizes")))


def full_surface(mesh: Mesh) -> Mesh:
    """The half mesh and its image: the whole closed surface."""
    return concatenate([mesh, mirror_z(mesh)])
