"""Compiled row kernels of the surrogate's domain arithmetic: a state's inputs (thesis section 5.2,
mirrored as in section 4.2.1), the constraints (4.4)-(4.7), the blend and discrepancy weights,
x_c, the outside flags and the coefficient-to-force conversion, row by row in scalars.

The sim asks `interaction.interaction_at` about one vehicle every step and the batch engine about
hundreds: in numpy the glue around the compiled LF and GP cost about 200 us a call for one
vehicle, more than the physics it wraps. These are the one implementation of that arithmetic:
`domain` and `interaction` call them for one row or many, so the sim, the surrogate server's
askers and the batch engine agree bit for bit. The constants (bounds, constraint
coefficients, ramp widths) are passed in from `domain` and `interaction`, which own them. No
fastmath, and numpy's error model (a division by zero gives inf or NaN, as in numpy): each
operation is the IEEE one of the numpy expression it replaced, in the same order, so the bits are
numpy's, except the constraint sums, which run left to right where numpy's matrix product may
have fused or reordered them.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

N_INPUTS = 6
GEOMETRY = (4, 5)  # D_sub/D_uuv and L/D_uuv
HEADING = 3
LATERAL = 1  # constraint (4.5)


@njit(cache=True, error_model="numpy")
def state_inputs(x, y, u, psi, length, diameter, d_sub, l_sub, knot, inputs, mirror):
    """Rows of `domain.to_inputs`: x, y, u, psi, length, diameter (n,) into inputs (n, 6) and mirror (n,)."""
    two_pi = 2.0 * math.pi
    to_degrees = 180.0 / math.pi  # numpy's degrees: x * (180 / pi)
    for i in range(x.shape[0]):
        side = -1.0 if y[i] < 0.0 else 1.0
        wrapped = (psi[i] + math.pi) % two_pi - math.pi  # Python's and numpy's float remainder alike
        mirror[i] = side
        inputs[i, 0] = x[i] / l_sub
        inputs[i, 1] = abs(y[i]) / l_sub
        inputs[i, 2] = u[i] / knot
        inputs[i, 3] = side * (wrapped * to_degrees)
        inputs[i, 4] = d_sub / diameter[i]
        inputs[i, 5] = length[i] / diameter[i]


@njit(cache=True, error_model="numpy")
def _constraints(row, c, out):
    """(4.4)-(4.7) of one input row into out (4,): c (4, 5) over [R_lat, 1/d, ld/d, ld, 1], summed left to right."""
    inv_d = 1.0 / row[4]
    ld = row[5]
    features = (row[1], inv_d, inv_d * ld, ld)
    for j in range(4):
        total = c[j, 0] * features[0]
        for k in range(1, 4):
            total += c[j, k] * features[k]
        out[j] = total + c[j, 4]


@njit(cache=True, error_model="numpy")
def constraint_rows(X, c, out):
    """`domain.constraint_values` of rows X (n, 6) into out (n, 4)."""
    for i in range(X.shape[0]):
        _constraints(X[i], c, out[i])


@njit(cache=True, error_model="numpy")
def _smoothstep(x):
    """0 below 0, 1 above 1, x^2 (3 - 2x) between; NaN stays NaN (as numpy's minimum and maximum)."""
    if x != x:
        return x
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


@njit(cache=True, error_model="numpy")
def _least(a, b):
    """np.minimum of two values: NaN if either is."""
    if a != a or b != b:
        return math.nan
    return a if a < b else b


@njit(cache=True, error_model="numpy")
def _margin(row, values, lower, upper, ramp, band, heading, lateral_taper):
    """The ramp coordinate nearest to off of one row: the state inputs' distances inside their bounds
    over the ramps (the heading's only with `heading`), the hull ratios' +inf inside and -inf outside,
    and the constraints over their bands, (4.5) tapered outward over `lateral_taper` D_uuv when that is
    above zero. NaN if any is NaN."""
    least = math.inf
    for k in range(N_INPUTS):
        inside = _least(row[k] - lower[k], upper[k] - row[k]) / ramp[k]
        if k == GEOMETRY[0] or k == GEOMETRY[1]:
            inside = math.inf if inside >= 0.0 else -math.inf
        elif k == HEADING and not heading:
            inside = math.inf
        least = _least(least, inside)
    for j in range(4):
        feasible = values[j] / band[j]
        if j == LATERAL and lateral_taper > 0.0:
            taper = lateral_taper / row[4]  # one D_uuv in units of D_sub: 1 / (D_sub/D_uuv)
            feasible = 1.0 + feasible * band[j] / taper
        least = _least(least, feasible)
    return least


@njit(cache=True, error_model="numpy")
def _weight(margin):
    """smoothstep of a margin, 0 where it is not finite."""
    if not math.isfinite(margin):
        return 0.0
    return _smoothstep(margin)


@njit(cache=True, error_model="numpy")
def weight_rows(X, c, lower, upper, ramp, band, heading, lateral_taper, out):
    """`interaction.blend_weight` (lateral_taper 0) or `discrepancy_weight` of rows X (n, 6) into out (n,)."""
    values = np.empty(4)
    for i in range(X.shape[0]):
        _constraints(X[i], c, values)
        out[i] = _weight(_margin(X[i], values, lower, upper, ramp, band, heading, lateral_taper))


@njit(cache=True, error_model="numpy")
def _clamped(row, c, lower, upper, lateral_slope, out):
    """x_c of one row into out (6,): clamped into the bounds, then beyond (4.5) R_lat onto its edge."""
    for k in range(N_INPUTS):
        value = row[k]
        if value == value:  # NaN stays NaN, as numpy's maximum and minimum keep it
            value = min(max(value, lower[k]), upper[k])
        out[k] = value
    values = np.empty(4)
    _constraints(out, c, values)
    beyond = values[LATERAL]
    if beyond == beyond:
        beyond = min(beyond, 0.0)
    out[1] += beyond / lateral_slope


@njit(cache=True, error_model="numpy")
def clamped_rows(X, c, lower, upper, lateral_slope, out):
    """`interaction.discrepancy_inputs` of rows X (n, 6) into out (n, 6)."""
    for i in range(X.shape[0]):
        _clamped(X[i], c, lower, upper, lateral_slope, out[i])


@njit(cache=True, error_model="numpy")
def _flags(row, values, lower, upper, out):
    """Which inputs lie outside their bounds (NaN included) and which constraints fail, into out (10,)."""
    for k in range(N_INPUTS):
        out[k] = not (row[k] >= lower[k] and row[k] <= upper[k])
    for j in range(4):
        out[N_INPUTS + j] = not (values[j] >= 0.0)


@njit(cache=True, error_model="numpy")
def flag_rows(X, c, lower, upper, out):
    """`interaction.outside_mask` of rows X (n, 6) into out (n, 10)."""
    values = np.empty(4)
    for i in range(X.shape[0]):
        _constraints(X[i], c, values)
        _flags(X[i], values, lower, upper, out[i])


@njit(cache=True, error_model="numpy")
def interaction_rows(
    raw, c, lower, upper, ramp, band, geometry_lower, geometry_upper, lateral_slope, delta_taper, lf_in_loop,
    inputs, weight, delta_weight, clamped, flags,
):  # fmt: skip
    """Everything `interaction.interaction_at` needs of rows of raw inputs (n, 6) before it asks a
    model: the inputs with the hull ratios clipped to their trained range, and for those the weight
    (with `lf_in_loop` the discrepancy weight w and x_c, weight NaN; else the blend weight, heading
    included, delta_weight and x_c NaN); the flags (n, 10) of the raw rows."""
    values = np.empty(4)
    for i in range(raw.shape[0]):
        row = inputs[i]
        for k in range(N_INPUTS):
            row[k] = raw[i, k]
        for k in GEOMETRY:
            if row[k] == row[k]:
                row[k] = min(max(row[k], geometry_lower[k - GEOMETRY[0]]), geometry_upper[k - GEOMETRY[0]])
        _constraints(row, c, values)
        if lf_in_loop:
            weight[i] = math.nan
            delta_weight[i] = _weight(_margin(row, values, lower, upper, ramp, band, False, delta_taper))
            _clamped(row, c, lower, upper, lateral_slope, clamped[i])
        else:
            weight[i] = _weight(_margin(row, values, lower, upper, ramp, band, True, 0.0))
            delta_weight[i] = math.nan
            clamped[i, :] = math.nan
        _constraints(raw[i], c, values)
        _flags(raw[i], values, lower, upper, flags[i])


@njit(cache=True, error_model="numpy")
def reach_rows(clearance, full, cut, out):
    """`interaction.lf_reach_weight` of clearances (n,) into out (n,)."""
    for i in range(clearance.shape[0]):
        weight = 1.0 - _smoothstep((clearance[i] - full) / (cut - full))
        out[i] = weight if math.isfinite(weight) else 0.0


@njit(cache=True, error_model="numpy")
def force_rows(coefficients, mirror, u, length, rho, out):
    """`domain.to_forces` of coefficients (m, n, 3) sharing one mirror (n,), speed (n,) and length
    (n,): coefficient x [q L^2, q L^2, q L^3] x [1, mirror, mirror], q = 0.5 rho u^2 (thesis section 5.2)."""
    for i in range(mirror.shape[0]):
        ql2 = 0.5 * rho * (u[i] * u[i]) * (length[i] * length[i])
        scales = (ql2, ql2, ql2 * length[i])
        signs = (1.0, mirror[i], mirror[i])
        for m in range(coefficients.shape[0]):
            for k in range(3):
                out[m, i, k] = coefficients[m, i, k] * scales[k] * signs[k]
