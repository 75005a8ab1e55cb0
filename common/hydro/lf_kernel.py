"""Compiled kernels of the low fidelity (`low_fidelity`): the submarine's field table and the UUV's
strip forces, fused point by point, without numpy temporaries.

One function of one row at a time, in a fixed order, so a vehicle's numbers do not depend on how
many rows are evaluated together (the sim's single vehicle and the batch engine's hundreds call the
same code). No fastmath: the arithmetic is IEEE, in the order written.

numba compiles these on first use and caches the machine code (`cache=True`): in `__pycache__`
beside this file, or, when that is not writable (a read-only install), numba's per-user cache
directory (~/.cache/numba on Linux); NUMBA_CACHE_DIR overrides both. Only the first run after an
install or an edit of this file pays the compilation. This module is imported only by the code that
evaluates the LF (`low_fidelity._kernel`), so processes that never do skip numba's import.
"""

from __future__ import annotations

import math

import numpy as np
from numba import config, njit, prange

# Whether this process spreads a batch's rows over threads: not in the processes nearsub starts
# (one numba thread each, `runtime.processes.single_blas_thread`), which then never start numba's
# OpenMP pool, so the fork server's children stay safe to fork (GNU OpenMP is not fork-safe).
THREADED = config.NUMBA_NUM_THREADS > 1

RING_WEIGHTS = (0.25, 0.25, 0.5)  # ring-mean weights of the +eta, -eta, +z points (-z mirrors +z)


@njit(cache=True)
def _interval(inner, value, guess):
    """Number of interior breakpoints at or below `value` (searchsorted side="right"): walked from
    `guess`, the index of a nearby point (neighbouring strips are a few cells apart at most), or
    by bisection when there is none (guess < 0). Either ends at the same index."""
    n = inner.shape[0]
    if guess < 0:
        lo, hi = 0, n
        while lo < hi:
            mid = (lo + hi) // 2
            if inner[mid] <= value:
                lo = mid + 1
            else:
                hi = mid
        return lo
    i = guess
    while i < n and inner[i] <= value:
        i += 1
    while i > 0 and inner[i - 1] > value:
        i -= 1
    return i


@njit(cache=True)
def _horner(c, dx, dr):
    """One field's bicubic cell polynomial sum_kl c[k, l] dx^k dr^l, by Horner's rule in R then x."""
    q3 = ((c[3, 3] * dr + c[3, 2]) * dr + c[3, 1]) * dr + c[3, 0]
    q2 = ((c[2, 3] * dr + c[2, 2]) * dr + c[2, 1]) * dr + c[2, 0]
    q1 = ((c[1, 3] * dr + c[1, 2]) * dr + c[1, 1]) * dr + c[1, 0]
    q0 = ((c[0, 3] * dr + c[0, 2]) * dr + c[0, 1]) * dr + c[0, 0]
    return ((q3 * dx + q2) * dx + q1) * dx + q0


@njit(cache=True)
def field_values(cells, x_inner, r_inner, x_left, r_left, x, r, ux, ur):
    """(u_x, u_R) of the table `cells` (x cell, R cell, field, x power, R power) at points x, R into
    ux, ur; points outside continue the edge cells' polynomials."""
    a = 0
    b = 0
    for i in range(x.shape[0]):
        a = _interval(x_inner, x[i], a)
        b = _interval(r_inner, r[i], b)
        dx = x[i] - x_left[a]
        dr = r[i] - r_left[b]
        ux[i] = _horner(cells[a, b, 0], dx, dr)
        ur[i] = _horner(cells[a, b, 1], dx, dr)


@njit(cache=True)
def _strip_row(
    n,
    x_c,
    y_c,
    cos_psi,
    sin_psi,
    diameter,
    length,
    friction_coefficient,
    strip_row,
    unit_xi,
    unit_r,
    unit_arc,
    cells,
    x_inner,
    r_inner,
    x_left,
    r_left,
    bounds,
    hold,
    with_submarine,
    lf,
    free,
    held,
):
    """One row n of `strip_forces` (the scratch arrays are its own, so rows may run at once)."""
    x_lo, x_hi, r_lo, r_hi = bounds[0], bounds[1], bounds[2], bounds[3]
    w0, w1, w2 = RING_WEIGHTS
    n_strips = unit_xi.shape[1]
    guess_a = np.empty(3, dtype=np.int64)
    guess_b = np.empty(3, dtype=np.int64)
    cp = np.empty(3)
    v_xi = np.empty(3)
    v_eta = np.empty(3)
    # Each ring point's cell is searched for at the row's first station, then walked from the
    # previous station's: rows in any order cost the same.
    guess_a[:] = -1
    guess_b[:] = -1
    c, s, d = cos_psi[n], sin_psi[n], diameter[n]
    row = strip_row[n]
    valid = True
    near = False
    y_force = 0.0
    moment = 0.0
    x_pressure = 0.0
    friction = 0.0
    free_moment = 0.0
    free_friction = 0.0
    xi_prev = arc_prev = area_prev = 0.0  # the previous station's values (set at j = 0)
    y_prev = moment_prev = cp_prev = friction_prev = free_moment_prev = free_friction_prev = 0.0
    for j in range(n_strips):
        xi = unit_xi[row, j] * d
        r = unit_r[row, j] * d
        arc = unit_arc[row, j] * d
        area = math.pi * (r * r)
        if with_submarine:
            axis_x = x_c[n] + xi * c
            axis_y = y_c[n] + xi * s
            for k in range(3):
                # In the plane z = 0 the distance from the axis is |y| (hypot's value there).
                if k == 0:
                    px, py, pz = axis_x - r * s, axis_y + r * c, 0.0
                    radial = abs(py)
                elif k == 1:
                    px, py, pz = axis_x + r * s, axis_y - r * c, 0.0
                    radial = abs(py)
                else:
                    px, py, pz = axis_x, axis_y, r
                    radial = math.hypot(py, pz)
                if radial < r_lo:
                    near = True
                lookup = max(radial, r_lo) if hold else radial
                ux = 0.0
                ur = 0.0
                if px >= x_lo and px <= x_hi and lookup >= r_lo and lookup <= r_hi:
                    a = _interval(x_inner, px, guess_a[k])
                    b = _interval(r_inner, lookup, guess_b[k])
                    guess_a[k] = a
                    guess_b[k] = b
                    dx = px - x_left[a]
                    dr = lookup - r_left[b]
                    ux = _horner(cells[a, b, 0], dx, dr)
                    ur = _horner(cells[a, b, 1], dx, dr)
                else:
                    valid = False
                # Velocity per unit U in UUV body axes: stream -U x plus the perturbation.
                safe_radial = radial if radial > 0.0 else 1.0
                vx = -1.0 + ux
                vy = ur * py / safe_radial
                v_xi[k] = vx * c + vy * s
                v_eta[k] = -vx * s + vy * c
                speed2 = vx * vx + vy * vy
                if k == 2:  # v_z = 0 at the +/-eta points
                    vz = ur * pz / safe_radial
                    speed2 += vz * vz
                cp[k] = -speed2
            cp_mean = w0 * cp[0] + w1 * cp[1] + w2 * cp[2]
            v_eta_mean = w0 * v_eta[0] + w1 * v_eta[1] + w2 * v_eta[2]
            u_axial = w0 * -v_xi[0] + w1 * -v_xi[1] + w2 * -v_xi[2]
            dcp_deta = (cp[0] - cp[1]) / (2.0 * r) if r > 0.0 else 0.0
            y_term = area * dcp_deta
            moment_term = 2.0 * area * u_axial * v_eta_mean - xi * area * dcp_deta
            friction_term = 2.0 * math.pi * r * (u_axial * u_axial)
            if j > 0:
                step = xi - xi_prev
                y_force += step * (y_term + y_prev) / 2.0
                moment += step * (moment_term + moment_prev) / 2.0
                x_pressure += 0.5 * (area + area_prev) * (cp_mean - cp_prev)
                friction += (arc - arc_prev) * (friction_term + friction_prev) / 2.0
            y_prev, moment_prev, cp_prev, friction_prev = y_term, moment_term, cp_mean, friction_term
        # The UUV alone: a uniform ring (no lateral gradient, no X pressure, no Y), axial speed
        # cos psi and lateral sin psi at every point.
        free_moment_term = 2.0 * area * c * s
        free_friction_term = 2.0 * math.pi * r * (c * c)
        if j > 0:
            free_moment += (xi - xi_prev) * (free_moment_term + free_moment_prev) / 2.0
            free_friction += (arc - arc_prev) * (free_friction_term + free_friction_prev) / 2.0
        free_moment_prev, free_friction_prev = free_moment_term, free_friction_term
        xi_prev, arc_prev, area_prev = xi, arc, area
    length2 = length[n] * length[n]
    length3 = length2 * length[n]
    cf = friction_coefficient[n]
    free[n, 0] = -cf * free_friction / length2
    free[n, 1] = 0.0
    free[n, 2] = free_moment / length3
    held[n] = near
    if with_submarine:
        if valid:
            lf[n, 0] = (-x_pressure - cf * friction) / length2
            lf[n, 1] = -y_force / length2
            lf[n, 2] = moment / length3
        else:
            lf[n, 0] = lf[n, 1] = lf[n, 2] = np.nan


@njit(cache=True)
def strip_forces(*arrays):
    """[X', Y', N'] of the strip model, row by row, into lf (with the submarine; NaN where a ring
    point lies outside the table's `bounds` (x_min, x_max, R_min, R_max)) and free (the UUV alone),
    and into held whether a point was closer to the axis than R_min (`hold`: then it sees the field
    at R_min instead of making the row NaN). Without `with_submarine` only `free` is filled.

    The UUV (`low_fidelity._strips`, stations `unit_xi` tail to nose, radius `unit_r`, meridian arc
    `unit_arc` of a unit-diameter hull, row `strip_row`) at CB (x_c, y_c) and heading psi: ring
    points at azimuth 0 (+eta, away from the submarine), pi (-eta) and pi/2 (+z). In the stream
    -U x plus the submarine's perturbation (u_x, u_R) per unit U: the pressure p / (rho U^2 / 2) =
    -|v|^2 up to a constant, its lateral gradient from the +/-eta points, the ring means of p, of
    the lateral velocity and of the axial speed. Strip forces over (1/2) rho U^2 (slender-body
    theory, Newman 1977): f_y = -d/dxi[rho A U_x V_y] - A dp/dy; Y integrates the first term to zero
    (A = 0 at both tips), N takes it by parts (the Munk moment, Munk 1924), X is the pressure on the
    changing section; ITTC-57 friction (thesis section 4.4) at the perimeter-weighted local axial
    speed. Integrals by the trapezoidal rule over the stations.

    Arguments, in order: x_c, y_c, cos_psi, sin_psi, diameter, length, friction_coefficient,
    strip_row, unit_xi, unit_r, unit_arc, cells, x_inner, r_inner, x_left, r_left, bounds, hold,
    with_submarine, lf, free, held (`_strip_row`)."""
    for n in range(arrays[0].shape[0]):
        _strip_row(n, *arrays)


@njit(cache=True, parallel=True)
def strip_forces_threaded(*arrays):
    """`strip_forces` with its rows spread over numba's threads (a batch of vehicles; each row the
    same arithmetic, so the same bits, as one at a time)."""
    for n in prange(arrays[0].shape[0]):
        _strip_row(n, *arrays)
