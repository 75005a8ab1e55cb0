"""Compiled kernels of `proximity`: the hull's signed distance from its graded grids, point by
point, and the closest UUV outline point of each pose, without numpy temporaries.

Bilinear interpolation of `proximity._DistanceGrid` and the outline placed as `hull.uuv_outline`
places it, element by element in the order written (no fastmath): the numpy arrays they replaced
give the same bits (tests/test_events.py keeps them as the reference). NaN marks a point no grid
answers for: the caller takes the exact polyline distance there. Imported on first use only
(`proximity._kernel`), so processes that never classify a pose skip numba's import; compiled once
per install into numba's cache, like `hydro.lf_kernel`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _from_grids(x, y, joints, r_sub, x0, h, ny, nx, start, trusted, values):
    """Signed distance at (x, y >= 0): closed form beside the middle body, else the finest grid
    that covers the point and trusts its value; NaN when none does."""
    x_bow_joint, x_aft_joint = joints[0], joints[1]
    if x <= x_bow_joint and x >= x_aft_joint:
        # Inside beside the middle body, the flat is nearest while the joints are farther than it.
        if not (y < r_sub and r_sub - y > min(x_bow_joint - x, x - x_aft_joint)):
            return y - r_sub
    for g in range(h.shape[0]):
        fx = (x - x0[g]) / h[g]
        fy = y / h[g]
        i = np.floor(fx)
        j = np.floor(fy)
        if not (i >= 0 and i < nx[g] - 1 and j < ny[g] - 1):
            continue
        tx = fx - i
        ty = fy - j
        k = start[g] + int(i * ny[g] + j)
        row = ny[g]
        low = values[k] + tx * (values[k + row] - values[k])
        high = values[k + 1] + tx * (values[k + row + 1] - values[k + 1])
        value = low + ty * (high - low)
        if value >= trusted[g]:
            return value
    return math.nan


@njit(cache=True)
def signed_distances(x, y, joints, r_sub, x0, h, ny, nx, start, trusted, values, out):
    """`_from_grids` at points x, |y| (flat arrays) into out."""
    for p in range(x.shape[0]):
        out[p] = _from_grids(x[p], abs(y[p]), joints, r_sub, x0, h, ny, nx, start, trusted, values)


@njit(cache=True)
def outline_clearances(x, y, cos_psi, sin_psi, bx, by, joints, r_sub, x0, h, ny, nx, start, trusted, values, out):
    """Smallest signed distance over the outline (bx, by) (body frame) of each pose at CB (x, y),
    heading psi, placed as `hull.uuv_outline` places it; NaN when a point needs the exact distance."""
    for m in range(x.shape[0]):
        c, s = cos_psi[m], sin_psi[m]
        best = math.inf
        for p in range(bx.shape[0]):
            ox = x[m] + bx[p] * c - by[p] * s
            oy = y[m] + bx[p] * s + by[p] * c
            d = _from_grids(ox, abs(oy), joints, r_sub, x0, h, ny, nx, start, trusted, values)
            if math.isnan(d):
                best = math.nan
                break
            best = min(best, d)
        out[m] = best
