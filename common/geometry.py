"""Axial profiles and surface panel meshes of bodies of revolution (issue 6: the hydrodynamic fidelities).

The radius functions come from hull.py (SUBOFF, Explorer); this module only places stations and
panels on them.

Frames (SPEC section 2, hull.py): a body frame has its origin at the body's centre of buoyancy (CB)
with x forward, so a station at distance s from the nose sits at x = cb - s. Meshes cover the half
z >= 0 of the surface: both hulls' axes lie in the plane z = 0, which is therefore a plane of
symmetry of the flow (thesis section 3.3.3.1 uses the same symmetry plane in its CFD;
hydro-notes section 2.4 "Mirror symmetry"). `mirror_z` gives the image half.

Half-mesh azimuth theta runs from 0 (facing +y) to pi (facing -y) through +z: y = r cos(theta),
z = r sin(theta). Panels are flat quads (planar: isosceles trapezoids between two stations and two
azimuths), degenerate to triangles at the pointed tips, ordered counter-clockwise about the
outward normal (hydro-notes Appendix A).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .hull import (
    D_SUB,
    FT,
    L_SUB,
    SUB_CB_FROM_NOSE,
    SUBOFF_JOINTS_M,
    SUBOFF_SCALE,
    explorer_cb_from_nose,
    explorer_radius,
    suboff_model_radius_ft,
    suboff_radius,
)

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
    normal velocity through z = 0 vanishes (hydro-notes section 2.4 "Mirror symmetry")."""
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
    the UUV must be comparable to the UUV's size and clearance (hydro-notes section 6(b)1).
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
    """UUV diameter and length [m] from D_sub/D_uuv and L/D_uuv (SPEC section 5, table 4.2)."""
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
    hydro-notes section 6(b)1, theta = pi s^1.6); both_ends uses cosine spacing, clustering both
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
