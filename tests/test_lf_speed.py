"""The LF's fast field evaluation (`low_fidelity.FieldTable`) is the same function as the two
`RectBivariateSpline.ev` calls it replaces, and the batch envelope does not notice the change."""

from __future__ import annotations

import numpy as np
import pytest

from nearsub.common.analysis import envelope as env
from nearsub.common.hydro import low_fidelity as lf

SMALL = env.EnvelopeConfig(vehicle="remus100", grid=(6, 4), r_long=(-0.5, 0.5), r_lat=(0.05, 0.075), duration=6.0)


def splines(x, r):
    field = lf.submarine_field()
    return field.ux.ev(x, r), field.ur.ev(x, r)


def assert_same_as_splines(x, r):
    ux, ur = lf.submarine_field().table.values(x, r)
    ex, er = splines(x, r)
    assert np.max(np.abs(ux - ex)) < 1e-14
    assert np.max(np.abs(ur - er)) < 1e-14


def test_table_equals_the_splines_at_random_points():
    field = lf.submarine_field()
    rng = np.random.default_rng(7)
    x = rng.uniform(*field.x_range, 40000)
    r = np.concatenate([rng.uniform(*field.r_range, 20000), field.r_range[0] + rng.exponential(0.3, 20000)])
    assert_same_as_splines(x, np.minimum(r, field.r_range[1]))


def test_table_equals_the_splines_at_knots_and_edges():
    field = lf.submarine_field()
    table = field.table
    xs = np.concatenate([table.x_breaks, 0.5 * (table.x_breaks[1:] + table.x_breaks[:-1]), field.x_range])
    rs = np.concatenate([table.r_breaks, 0.5 * (table.r_breaks[1:] + table.r_breaks[:-1]), field.r_range])
    x, r = (grid.ravel() for grid in np.meshgrid(xs, rs, indexing="ij"))
    assert_same_as_splines(x, r)
    # Just inside the edges and either side of each knot.
    eps = 1e-12
    assert_same_as_splines(np.clip(x + eps, *field.x_range), np.clip(r - eps, *field.r_range))


def test_table_does_not_depend_on_the_call_size():
    """One vehicle's points get the same bits alone as among many (the chunking is invisible)."""
    field = lf.submarine_field()
    rng = np.random.default_rng(3)
    x = rng.uniform(*field.x_range, 3 * lf._CHUNK + 17)
    r = rng.uniform(field.r_range[0], 10.0, x.size)
    together = field.table.values(x, r)
    for part in (slice(0, 180), slice(lf._CHUNK - 90, lf._CHUNK + 90), slice(x.size - 180, x.size)):
        alone = field.table.values(x[part], r[part])
        np.testing.assert_array_equal(alone[0], together[0][part])
        np.testing.assert_array_equal(alone[1], together[1][part])


def test_lf_values_unchanged():
    """lf_increment_terms with the table against the same with the splines, on rows near the hull."""
    rng = np.random.default_rng(11)
    n = 300
    rows = np.column_stack(
        [
            rng.uniform(-0.7, 0.7, n),
            rng.uniform(0.045, 0.12, n),
            rng.uniform(2.0, 6.0, n),
            rng.uniform(-10.0, 10.0, n),
            rng.uniform(0.04, 0.12, n),
            rng.uniform(5.0, 10.0, n),
        ]
    )
    fast = lf.lf_increment_terms(rows)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(lf.FieldTable, "values", lambda self, x, r: splines(x, r))
        slow = lf.lf_increment_terms(rows)
    for a, b in zip(fast, slow, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-15)


def test_batch_envelope_unchanged():
    """A small envelope in the batch engine with the table against the same with the splines."""
    surrogate = env.cached_surrogate(SMALL.model)
    fast = env.compute_envelope(SMALL, surrogate).result
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(lf.FieldTable, "values", lambda self, x, r: splines(x, r))
        slow = env.compute_envelope(SMALL, surrogate).result
    np.testing.assert_array_equal(fast.outcome, slow.outcome)
    np.testing.assert_allclose(fast.final, slow.final, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.closest, slow.closest, rtol=0, atol=1e-9)
