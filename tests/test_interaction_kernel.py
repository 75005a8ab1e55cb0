"""The compiled domain arithmetic (`surrogate.interaction_kernel`) against the numpy formulas it
replaced: the state's inputs and the force conversion to the bit (divisions, products and the
float remainder are exactly rounded on every CPU), the constraint sums to rounding (numpy's matrix
product may fuse or reorder them), the weights, x_c and the flags to rounding, with NaN, inf and
out-of-range rows included; and each row's numbers do not depend on the batch it came in."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nearsub.common.physics.hull import D_SUB, L_SUB
from nearsub.common.surrogate import domain
from nearsub.common.surrogate import interaction as ia

RNG = np.random.default_rng(7)


def _states(n: int) -> tuple[np.ndarray, ...]:
    x = RNG.uniform(-80.0, 80.0, n)
    y = RNG.uniform(-12.0, 12.0, n)
    u = RNG.uniform(0.5, 3.0, n)
    psi = RNG.uniform(-9.0, 9.0, n)  # beyond +/- pi: the wrap is exercised
    return x, y, u, psi


def _rows(n: int) -> np.ndarray:
    """Input rows around and beyond table 4.2's box, with non-finite values sprinkled in."""
    lower, upper = domain.BOUNDS[:, 0], domain.BOUNDS[:, 1]
    width = upper - lower
    rows = RNG.uniform(lower - 0.2 * width, upper + 0.2 * width, size=(n, 6))
    rows[:, 1] = RNG.uniform(0.055, 0.12, n)  # R_lat across (4.4) and (4.5)
    rows[5, 2], rows[6, 4], rows[7, 1], rows[8, 3] = np.nan, np.inf, -np.inf, np.nan
    rows[9, 4] = 0.0  # D_sub/D_uuv = 0: 1/0 in the constraints
    return rows


def _constraints(X: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_d = 1.0 / X[:, 4]
        features = np.column_stack([X[:, 1], inv_d, inv_d * X[:, 5], X[:, 5]])
        return features @ domain.CONSTRAINT_COEFFICIENTS[:, :4].T + domain.CONSTRAINT_COEFFICIENTS[:, 4]


def _smoothstep(x):
    x = np.minimum(np.maximum(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def _weight(X: np.ndarray, heading: bool, taper: bool) -> np.ndarray:
    lower, upper = domain.BOUNDS[:, 0], domain.BOUNDS[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        inside = np.minimum(X - lower, upper - X) / (ia.BLEND_FRACTION * (upper - lower))
        inside[:, 4:6] = np.where(inside[:, 4:6] >= 0, np.inf, -np.inf)
        if not heading:
            inside[:, 3] = np.inf
        feasible = _constraints(X) / ia.CONSTRAINT_BAND
        if taper:
            feasible[:, 1] = 1.0 + feasible[:, 1] * ia.CONSTRAINT_BAND[1] / (ia.DELTA_TAPER / X[:, 4])
        margin = np.minimum(inside.min(axis=1), feasible.min(axis=1))
    return _smoothstep(np.where(np.isfinite(margin), margin, 0.0))


def test_a_states_inputs_are_the_formulas_to_the_bit():
    x, y, u, psi = _states(500)
    inputs, mirror = domain.to_inputs(x, y, u, psi, 1.6, 0.19)
    side = np.where(y < 0.0, -1.0, 1.0)
    wrapped = np.remainder(psi + math.pi, 2.0 * math.pi) - math.pi
    expected = np.column_stack(
        [
            x / L_SUB,
            np.abs(y) / L_SUB,
            u / domain.KNOT,
            side * np.degrees(wrapped),
            np.full(500, D_SUB / 0.19),
            np.full(500, 1.6 / 0.19),
        ]
    )
    np.testing.assert_array_equal(mirror, side)
    np.testing.assert_array_equal(inputs, expected)


def test_the_force_conversion_is_the_formula_to_the_bit():
    coefficients = RNG.normal(size=(300, 3)) * 1e-3
    mirror = np.where(RNG.uniform(size=300) < 0.5, -1.0, 1.0)
    u = RNG.uniform(0.5, 3.0, 300)
    q = 0.5 * 1025.0 * u**2 * 1.6**2
    expected = coefficients * np.column_stack([q, q, q * 1.6]) * np.column_stack([np.ones(300), mirror, mirror])
    np.testing.assert_array_equal(domain.to_forces(coefficients, mirror, u, 1.6, 1025.0), expected)


def test_the_constraints_are_the_matrix_product_to_rounding():
    X = _rows(400)
    got, expected = domain.constraint_values(X), _constraints(X)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(expected))
    finite = np.isfinite(expected)
    np.testing.assert_array_equal(got[~finite], expected[~finite])
    np.testing.assert_allclose(got[finite], expected[finite], rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("heading", [True, False])
def test_the_blend_weight_is_the_formula_to_rounding(heading):
    X = _rows(2000)
    got = ia.blend_weight(X, heading=heading)
    np.testing.assert_allclose(got, _weight(X, heading, taper=False), rtol=0, atol=1e-12)
    assert got[5:10].tolist() == [0.0] * 5  # NaN, inf, D_sub/D_uuv = 0: no surrogate there
    assert 0.0 < got.mean() < 1.0  # rows inside, outside and on the ramps


def test_the_discrepancy_weight_x_c_and_the_flags_are_the_formulas_to_rounding():
    X = _rows(2000)
    np.testing.assert_allclose(ia.discrepancy_weight(X), _weight(X, False, taper=True), rtol=0, atol=1e-12)
    lower, upper = domain.BOUNDS[:, 0], domain.BOUNDS[:, 1]
    clamped = np.minimum(np.maximum(X, lower), upper)
    clamped[:, 1] += np.minimum(_constraints(clamped)[:, 1], 0.0) / 8.575
    np.testing.assert_allclose(ia.discrepancy_inputs(X), clamped, rtol=1e-14, atol=1e-15)
    with np.errstate(invalid="ignore"):
        beyond = ~((X >= lower) & (X <= upper))
        failed = ~(_constraints(X) >= 0.0)
    flags = ia.outside_mask(X)
    np.testing.assert_array_equal(flags[:, :6], beyond)
    settled = np.abs(np.nan_to_num(_constraints(X), nan=1.0)) > 1e-12  # not on a constraint's edge
    np.testing.assert_array_equal(flags[:, 6:][settled], failed[settled])


@pytest.mark.parametrize("lf_in_loop", [True, False])
def test_a_rows_terms_do_not_depend_on_its_batch(lf_in_loop):
    X = _rows(64)
    together = ia.DomainRows.of(X, lf_in_loop)
    for i in (0, 5, 9, 40):
        alone = ia.DomainRows.of(X[i], lf_in_loop)
        for name in ("inputs", "weight", "delta_weight", "clamped", "flags"):
            np.testing.assert_array_equal(getattr(alone, name)[0], getattr(together, name)[i])
    unused = ("weight",) if lf_in_loop else ("delta_weight", "clamped")
    assert all(np.isnan(getattr(together, name)).all() for name in unused)
