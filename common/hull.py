"""Hull geometry: the DARPA SUBOFF submarine and the Explorer-shaped UUV.

Both hulls are bodies of revolution, so one radius function r(s) of the distance s from the nose
describes each. In the 3-DOF plane (the plane of both axes, SPEC section 2) the outline is
|y| <= r(s). Frames:
- Submarine frame: origin at the submarine's centre of buoyancy (CB), x forward (bow at +x).
  ../shared/data/hulls.md gives no CB for SUBOFF, so the CB is the volume centroid of the bare
  hull computed here from the offsets: 2.0086 m behind the nose at model scale (0.4611 L),
  40.976 m behind the nose at full scale. The bow tip sits at x = +40.976 m, the stern tip at
  x = -47.889 m.
- UUV body frame: origin at the UUV's CB (thesis section 5.4), also taken as the volume centroid
  of its Explorer profile, x forward.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

FT = 0.3048  # international foot [m]

# DARPA SUBOFF bare hull, model scale in feet (../shared/data/hulls.md section 5, [SUBOFF] hull.f90)
SUBOFF_RMAX_FT = 0.8333333  # R_max (D = 0.508 m)
SUBOFF_BOW_END_FT = 3.333333  # bow / parallel middle body joint
SUBOFF_PMB_END_FT = 10.645833  # parallel middle body / afterbody joint
SUBOFF_AFT_END_FT = 13.979167  # afterbody / cap joint
SUBOFF_LENGTH_FT = 14.291667  # overall length L = 4.3561 m
_RH = 0.1175  # r_h, afterbody end radius / R_max (hulls.md)
_K0 = 10.0  # afterbody slope parameter K0 (hulls.md)
_K1 = 44.6244  # afterbody curvature parameter K1 (hulls.md)

# Thesis submarine: SUBOFF scaled to D = 34 ft (thesis section 5.9; SPEC section 2)
SUBOFF_SCALE = 34.0 / (2.0 * SUBOFF_RMAX_FT)  # k = 20.4 (hulls.md "Scaling")
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
    """SUBOFF bare-hull radius in feet at x feet from the nose, exactly the hulls.md formulas."""
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
)  # 20.73, 66.19, 86.92 m (hulls.md "Scaling")


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


# Explorer-shaped UUV, thesis (3.1) bow ellipse and (3.2) stern paraboloid (hulls.md section 5)
def explorer_radius(s, length: float, diameter: float):
    """Explorer hull radius at s from the nose: ellipse (3.1) over 2R, cylinder, paraboloid (3.2)
    over 4R with a pointed tail. Requires length >= 3 diameter (L = 6R + L_p, L_p >= 0)."""
    radius = 0.5 * diameter
    parallel = length - 6.0 * radius  # L_p (hulls.md: L = 6R + L_p)
    if parallel < 0.0:
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
