"""Event geometry of thesis section 5.11.2 (docs/design.md, "Physics decisions"): collision, close
call, large stray.

Everything works in the plane of both axes (the submarine frame of docs/design.md, "Frames, units
and signs") and is vectorised over arrays of UUV poses.

- Collision: the UUV outline (Explorer profile of the vehicle's length and diameter, hull.py)
  touches or overlaps the SUBOFF outline, i.e. `closest_distance <= 0`.
- Close call: no collision, and either the outline comes within one UUV diameter of the hull
  (`closest_distance <= D_uuv`), or the UUV is directly ahead of or behind the submarine. "Directly
  ahead/behind" means the UUV's CB lies beyond the bow tip (x > SUB_BOW_X) or beyond the stern tip
  (x < SUB_STERN_X) and inside the submarine's swept corridor widened by one UUV diameter,
  |y| < R_sub + D_uuv: the submarine would run into it, or pass within one diameter of it.
- Large stray: the UUV's CB is more than 1 m (thesis section 5.11.2) from the current track-line,
  the segment from the previous to the next waypoint.

Distances come from the UUV polygon of `hull.uuv_outline` and the hull's signed distance: exact in
closed form beside the parallel middle body, interpolated elsewhere from graded grids built once
from a polyline of the hull resampled every 1 cm of arc (under 1 mm of error within 1 m of the
hull), and exact from that polyline where a point touches or enters the hull. One `classify` serves
the sim and the batch engine; the grids make it cheap enough for sweeps of thousands of UUVs.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from nearsub.common.physics.hull import (
    L_SUB,
    R_SUB,
    SUB_BOW_X,
    SUB_CB_FROM_NOSE,
    SUB_STERN_X,
    SUBOFF_JOINTS_M,
    submarine_half_width,
    suboff_radius,
    uuv_body_outline,
    uuv_outline,
)

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

STRAY_LIMIT = 1.0  # large stray: more than 1 m from the track-line (thesis section 5.11.2) [m]
_HULL_SPACING = 0.01  # arc-length spacing of the hull polyline [m]

# Graded signed-distance grids, finest first: (node spacing h [m], smallest distance it answers
# for [m], largest distance from the hull it holds [m]). Bilinear interpolation of a distance field
# errs by at most about h^2 / (8 (rho + d)), rho the hull's radius of curvature (>= 0.19 m at the
# tip of the stern cap, >= 2.65 m on the bow) and d the distance: < 1 mm within 1 m of the hull,
# where collisions and close calls are decided; < 5 mm within 5 m, where the near pre-check reads
# it; a few cm beyond (tests/test_events.py measures it). Fine spacing is only paid for near the
# hull, which keeps the build to about 0.1 s (every sim process builds it once).
_GRID_LEVELS = ((0.04, 0.01, 1.0), (0.2, 0.9, 5.0), (1.0, 4.5, 40.0))
# Below the finest grid's smallest distance (0.01 m, far above its error) the exact polyline
# distance is used, so contact (collision) decisions and every point inside the hull are exact.
_GRID_TOLERANCE = 0.01  # bound on the grids' error where the near pre-check reads them [m]


def _resample(s_start: float, s_end: float) -> np.ndarray:
    """Upper outline between two stations, frame (x, y) points every _HULL_SPACING of arc."""
    s = s_start + 0.5 * (s_end - s_start) * (1.0 - np.cos(np.linspace(0.0, np.pi, 20000)))
    r = suboff_radius(s)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(s), np.diff(r)))])
    uniform = np.linspace(0.0, arc[-1], int(np.ceil(arc[-1] / _HULL_SPACING)) + 1)
    return np.column_stack([SUB_CB_FROM_NOSE - np.interp(uniform, arc, s), np.interp(uniform, arc, r)])


@lru_cache(maxsize=1)
def _hull_curves() -> tuple[tuple[cKDTree, np.ndarray], tuple[cKDTree, np.ndarray]]:
    """Dense polylines of the curved bow and stern (upper half), each with a KD-tree.

    The outline is symmetric in y, so the distance from (x, y) is the distance from (x, |y|) to
    the upper half. The parallel middle body is a straight line, handled exactly in closed form.
    """
    from scipy.spatial import cKDTree  # here: the processes that never ask (the clock) skip scipy

    joint_bow, joint_aft, _ = SUBOFF_JOINTS_M
    bow, stern = _resample(0.0, joint_bow), _resample(joint_aft, L_SUB)
    return (cKDTree(bow), bow), (cKDTree(stern), stern)


def _joints_x() -> tuple[float, float]:
    """Frame x of the bow / middle body joint and of the middle body / afterbody joint."""
    joint_bow, joint_aft, _ = SUBOFF_JOINTS_M
    return SUB_CB_FROM_NOSE - joint_bow, SUB_CB_FROM_NOSE - joint_aft


def _curve_nearest(curve: tuple[cKDTree, np.ndarray], query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance from points (M, 2) to a polyline, and the nearest polyline points (M, 2); the
    nearest vertex's two segments hold the closest point."""
    tree, pts = curve
    _, nearest = tree.query(query)
    best = np.full(len(query), np.inf)
    where = np.empty_like(query)
    for lo in (nearest - 1, nearest):
        a = pts[np.clip(lo, 0, len(pts) - 1)]
        ab = pts[np.clip(lo + 1, 0, len(pts) - 1)] - a
        t = np.clip(
            np.einsum("ij,ij->i", query - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300),
            0,
            1,
        )
        foot = a + t[:, None] * ab
        gap = np.linalg.norm(query - foot, axis=1)
        closer = gap < best
        best, where[closer] = np.where(closer, gap, best), foot[closer]
    return best, where


def _exact_nearest(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance from points (flat arrays, y >= 0) to the outline, from the 1 cm polylines
    (exact to about 0.1 mm), and the x of the nearest outline point."""
    bow, stern = _hull_curves()
    x_bow_joint, x_aft_joint = _joints_x()
    beside = (x <= x_bow_joint) & (x >= x_aft_joint)
    inside = y < submarine_half_width(x)
    dist = np.where(beside, np.abs(y - R_SUB), np.inf)
    hull_x = x.copy()  # beside the middle body the nearest point is straight across
    for curve, side in ((bow, x > x_aft_joint), (stern, x < x_bow_joint)):
        todo = np.flatnonzero(side & (~beside | inside))  # inside points near a joint may be closer to a curve
        if todo.size:
            gap, foot = _curve_nearest(curve, np.column_stack([x[todo], y[todo]]))
            closer = gap < dist[todo]
            dist[todo[closer]], hull_x[todo[closer]] = gap[closer], foot[closer, 0]
    return np.where(inside, -dist, dist), hull_x


def _exact_signed_distance(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Signed distance from points (flat arrays, y >= 0) to the outline (`_exact_nearest`): the
    reference the grids are built from, and their fallback."""
    return _exact_nearest(x, y)[0]


def nearest_hull_point(px, py) -> tuple[np.ndarray, np.ndarray]:
    """Exact signed distance [m] from points to the submarine outline (negative inside), and the
    frame x [m] of the nearest outline point: where on the hull a UUV came closest."""
    px, py = np.broadcast_arrays(np.asarray(px, dtype=float), np.asarray(py, dtype=float))
    dist, hull_x = _exact_nearest(px.ravel(), np.abs(py.ravel()))
    return dist.reshape(px.shape), hull_x.reshape(px.shape)


@dataclass(frozen=True)
class _DistanceGrid:
    """Signed distances on the nodes x0 + i h, j h (y >= 0); NaN at nodes outside its band. Read
    by bilinear interpolation (`proximity_kernel`), it answers only for distances of at least
    `trusted_from`, where its error is small."""

    x0: float
    h: float
    ny: int
    values: np.ndarray  # flat, index i * ny + j
    trusted_from: float


def _running(reduce, values: np.ndarray, reach: float, h: float) -> np.ndarray:
    """max or min of `values` (spaced h) within `reach` either side; zero beyond the ends."""
    cells = int(np.ceil(reach / h))
    padded = np.pad(values, cells)
    return reduce(np.lib.stride_tricks.sliding_window_view(padded, 2 * cells + 1), axis=1)


def _build_grid(h: float, trusted_from: float, band: float) -> _DistanceGrid:
    """Exact signed distances at the nodes within about `band` outside and 2 h inside the bow and
    stern curves. Nodes are chosen from the half-width alone: a point within `band` of the hull lies
    below the highest half-width within `band` along x, plus `band`."""
    x_bow_joint, x_aft_joint = _joints_x()
    reach = band + 2.0 * h
    x0 = SUB_STERN_X - reach
    nx, ny = int(np.ceil((SUB_BOW_X + reach - x0) / h)) + 1, int(np.ceil((R_SUB + reach) / h)) + 1
    xs, ys = x0 + h * np.arange(nx), h * np.arange(ny)
    width = submarine_half_width(xs)
    highest, lowest = _running(np.max, width, band, h), _running(np.min, width, 2.0 * h, h)
    curved = (xs > x_bow_joint - 2.0 * h) | (xs < x_aft_joint + 2.0 * h)  # beside the middle body: closed form
    wanted = curved[:, None] & (ys <= highest[:, None] + reach) & (ys >= lowest[:, None] - 2.0 * h)
    values = np.full((nx, ny), np.nan)
    gx, gy = np.broadcast_to(xs[:, None], wanted.shape)[wanted], np.broadcast_to(ys, wanted.shape)[wanted]
    values[wanted] = _exact_signed_distance(gx, gy)
    return _DistanceGrid(float(x0), h, ny, values.ravel(), trusted_from)


@lru_cache(maxsize=1)
def _distance_grids() -> tuple[_DistanceGrid, ...]:
    """The graded grids, finest first, built on first use (about 0.1 s)."""
    return tuple(_build_grid(*level) for level in _GRID_LEVELS)


def _kernel():
    """The compiled kernels (`proximity_kernel`), imported on first use: processes that never
    classify a pose do not pay numba's import."""
    from nearsub.common.physics import proximity_kernel

    return proximity_kernel


@lru_cache(maxsize=1)
def _kernel_grids() -> tuple:
    """The joints, R_sub and the grids as the kernels read them: per grid x0, h, ny, nx, its first
    value's index in one flat array and its trusted distance, then that array."""
    grids = _distance_grids()
    sizes = [g.values.size for g in grids]
    return (
        np.array(_joints_x()),
        R_SUB,
        np.array([g.x0 for g in grids]),
        np.array([g.h for g in grids]),
        np.array([g.ny for g in grids], dtype=np.int64),
        np.array([size // g.ny for size, g in zip(sizes, grids, strict=True)], dtype=np.int64),
        np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64),
        np.array([g.trusted_from for g in grids]),
        np.concatenate([g.values for g in grids]),
    )


def hull_signed_distance(px, py):
    """Signed distance [m] from points to the submarine outline: negative inside the hull.

    Beside the parallel middle body the hull's widest line is the closest part, so outside it the
    distance is |y| - R_sub exactly. Elsewhere the finest grid that covers the point answers,
    if the distance is in its trusted range; points inside or within 1 cm of the hull, and the
    rare ones beyond every grid, get the exact polyline distance.
    """
    px, py = np.asarray(px, dtype=float), np.asarray(py, dtype=float)
    if px.shape != py.shape:
        px, py = np.broadcast_arrays(px, py)
    x, y = np.ascontiguousarray(px).ravel(), np.ascontiguousarray(py).ravel()
    dist = np.empty(x.size)
    _kernel().signed_distances(x, y, *_kernel_grids(), dist)
    todo = np.flatnonzero(np.isnan(dist))
    if todo.size:
        dist[todo] = _exact_signed_distance(x[todo], np.abs(y[todo]))
    return dist.reshape(px.shape)


def closest_distance(x, y, psi, length: float, diameter: float, n: int = 64):
    """Clearance [m] between the UUV outline at CB (x, y), heading psi and the hull outline.

    Positive when apart; zero or negative when touching or overlapping (a collision). Shape is the
    broadcast shape of x, y, psi.
    """
    x, y, psi = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (x, y, psi)))
    flat = [np.ascontiguousarray(a).ravel() for a in (x, y, psi)]
    bx, by = _body_outline(length, diameter, n)
    clearance = np.empty(flat[0].size)
    _kernel().outline_clearances(
        flat[0], flat[1], np.cos(flat[2]), np.sin(flat[2]), bx, by, *_kernel_grids(), clearance
    )
    # A pose with a point no grid answers for (touching, inside, or beyond every grid): its whole
    # outline through hull_signed_distance, which takes the exact distance there.
    exact = np.flatnonzero(np.isnan(clearance))
    if exact.size:
        ox, oy = uuv_outline(flat[0][exact], flat[1][exact], flat[2][exact], length, diameter, n)
        clearance[exact] = hull_signed_distance(ox, oy).min(axis=-1)
    return clearance.reshape(x.shape)


@lru_cache(maxsize=64)
def _body_outline(length: float, diameter: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """`hull.uuv_body_outline`, kept per hull (the sim classifies every step with one; nothing here
    writes to it, and the kernels keep their writable-array signatures)."""
    return uuv_body_outline(length, diameter, n)


@lru_cache(maxsize=64)
def _uuv_reach(length: float, diameter: float, n: int) -> float:
    """Largest distance from the UUV's CB to its outline (a bound for the cheap pre-check)."""
    bx, by = _body_outline(length, diameter, n)
    return float(np.max(np.hypot(bx, by)))


def ahead_or_astern(x, y, diameter: float):
    """True where the UUV's CB is directly ahead of the bow or behind the stern (module doc)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return ((x > SUB_BOW_X) | (x < SUB_STERN_X)) & (np.abs(y) < R_SUB + diameter)


def track_distance(x, y, start, end):
    """Distance [m] from (x, y) to the track-line segment from `start` to `end`: points (2,), or
    (N, 2) for one segment per position."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    ax, ay = start[..., 0], start[..., 1]
    dx, dy = end[..., 0] - ax, end[..., 1] - ay
    seg2 = dx * dx + dy * dy
    safe = np.where(seg2 > 0, seg2, 1.0)
    t = np.where(seg2 > 0, np.clip(((x - ax) * dx + (y - ay) * dy) / safe, 0.0, 1.0), 0.0)
    return np.hypot(x - (ax + t * dx), y - (ay + t * dy))


@dataclass(frozen=True)
class Events:
    """Event flags, one entry per UUV pose; large_stray is None when no track-line was given.
    centre_clearance is the signed distance [m] from the UUV's CB to the hull."""

    collision: np.ndarray
    close_call: np.ndarray
    large_stray: np.ndarray | None
    centre_clearance: np.ndarray


def classify(x, y, psi, length: float, diameter: float, track=None, n: int = 64) -> Events:
    """Classify UUV poses. `track` is the current track-line ((x0, y0), (x1, y1)) or None.

    Poses whose CB is farther from the hull than the UUV's reach plus one diameter (plus the
    grids' error) can be neither a collision nor a near pass, so the outline is only built for
    the others.
    """
    x, y, psi = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (x, y, psi)))
    centre = hull_signed_distance(x, y)
    near = centre - _uuv_reach(length, diameter, n) <= diameter + _GRID_TOLERANCE
    clearance = centre.copy()
    if near.any():
        clearance[near] = closest_distance(x[near], y[near], psi[near], length, diameter, n)
    collision = near & (clearance <= 0.0)
    close_call = ~collision & ((near & (clearance <= diameter)) | ahead_or_astern(x, y, diameter))
    stray = None if track is None else track_distance(x, y, *track) > STRAY_LIMIT
    return Events(collision, close_call, stray, centre)
