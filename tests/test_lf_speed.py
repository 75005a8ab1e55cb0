"""The LF's compiled kernels (`lf_kernel`) compute the same function as the numpy strip model they
replace, evaluated on the field's two `RectBivariateSpline`s, and the batch envelope does not
notice the change."""

from __future__ import annotations

import numpy as np
import pytest

from nearsub.common.analysis import envelope as env
from nearsub.common.hydro import low_fidelity as lf

SMALL = env.EnvelopeConfig(vehicle="remus100", grid=(6, 4), r_long=(-0.5, 0.5), r_lat=(0.05, 0.075), duration=6.0)


def splines(x, r):
    field = lf.submarine_field()
    return field.ux.ev(x, r), field.ur.ev(x, r)


def reference_terms(inputs, n_strips=lf.N_STRIPS):
    """The strip model as numpy arrays over (ring point, row, strip), on the splines: the
    implementation the kernel replaced, kept as its reference."""
    x_c, y_c, speed, psi, diameter, length = lf.input_columns(inputs)
    unit_xi, unit_r, unit_arc, row = lf._strips(length / diameter, n_strips)
    xi, r, arc = (part[row] * diameter[:, None] for part in (unit_xi, unit_r, unit_arc))
    c, s = np.cos(psi)[:, None], np.sin(psi)[:, None]
    axis_x, axis_y = x_c[:, None] + xi * c, y_c[:, None] + xi * s
    px = np.stack([axis_x - r * s, axis_x + r * s, axis_x])
    py = np.stack([axis_y + r * c, axis_y - r * c, axis_y])
    pz = np.stack([np.zeros_like(r), np.zeros_like(r), r])
    radial = np.hypot(py, pz)
    field = lf.submarine_field()
    held = (radial < field.r_range[0]).any(axis=(0, 2))
    lookup = np.maximum(radial, field.r_range[0])
    inside = (px >= field.x_range[0]) & (px <= field.x_range[1]) & (lookup <= field.r_range[1])
    ux, ur = (np.where(inside, v.reshape(px.shape), 0.0) for v in splines(px.ravel(), lookup.ravel()))
    vx = -1.0 + ux
    safe = np.where(radial > 0.0, radial, 1.0)
    vy, vz = ur * py / safe, ur * pz / safe
    v_xi, v_eta = vx * c + vy * s, -vx * s + vy * c
    cp = -(vx**2 + vy**2 + vz**2)
    ring = np.array([0.25, 0.25, 0.5])[:, None, None]
    cp_mean, v_eta_mean, u_axial = (np.sum(ring * q, axis=0) for q in (cp, v_eta, -v_xi))
    area = np.pi * r**2
    dcp = np.where(r > 0.0, (cp[0] - cp[1]) / np.where(r > 0.0, 2.0 * r, 1.0), 0.0)
    y_force = -np.trapezoid(area * dcp, xi, axis=1)
    n_moment = np.trapezoid(2.0 * area * u_axial * v_eta_mean - xi * area * dcp, xi, axis=1)
    x_pressure = -np.sum(0.5 * (area[:, 1:] + area[:, :-1]) * np.diff(cp_mean, axis=1), axis=1)
    cf = lf.ittc57(speed * length / lf.NU)
    friction = -cf * np.trapezoid(2.0 * np.pi * r * u_axial**2, arc, axis=1)
    with_sub = np.column_stack([(x_pressure + friction) / length**2, y_force / length**2, n_moment / length**3])
    with_sub[~inside.all(axis=(0, 2))] = np.nan
    free_moment = np.trapezoid(2.0 * area * c * s, xi, axis=1)
    free_friction = -cf * np.trapezoid(2.0 * np.pi * r * c**2, arc, axis=1)
    alone = np.column_stack([free_friction / length**2, np.zeros(len(length)), free_moment / length**3])
    return with_sub, alone, held


def rows_near_the_hull(n, seed):
    rng = np.random.default_rng(seed)
    return np.column_stack(
        [
            rng.uniform(-0.7, 0.7, n),
            rng.uniform(0.045, 0.12, n),
            rng.uniform(2.0, 6.0, n),
            rng.uniform(-10.0, 10.0, n),
            rng.uniform(8.0, 60.0, n),
            rng.uniform(5.0, 10.0, n),
        ]
    )


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


def test_table_does_not_depend_on_the_order_or_the_call_size():
    """A point's cell is found from its neighbour's: far jumps, any order and any subset give the
    same bits."""
    field = lf.submarine_field()
    rng = np.random.default_rng(3)
    x = rng.uniform(*field.x_range, 5000)
    r = rng.uniform(field.r_range[0], 10.0, x.size)
    together = field.table.values(x, r)
    order = rng.permutation(x.size)
    shuffled = field.table.values(x[order], r[order])
    np.testing.assert_array_equal(shuffled[0], together[0][order])
    np.testing.assert_array_equal(shuffled[1], together[1][order])
    for part in (slice(0, 1), slice(2400, 2580), slice(x.size - 180, x.size)):
        alone = field.table.values(x[part], r[part])
        np.testing.assert_array_equal(alone[0], together[0][part])
        np.testing.assert_array_equal(alone[1], together[1][part])


def test_lf_values_unchanged():
    """lf_increment_terms against the numpy reference on the splines, rows near the hull (some
    held at the table's inner edge); lf_coefficients and lf_free_stream are its parts."""
    rows = rows_near_the_hull(300, 11)
    fast = lf.lf_increment_terms(rows)
    slow = reference_terms(rows)
    assert slow[2].any() and not slow[2].all()
    for a, b in zip(fast, slow, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-15)
    plain = np.where(slow[2][:, None], np.nan, slow[0])  # without holding, a held row is outside the table
    np.testing.assert_allclose(lf.lf_coefficients(rows), plain, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(lf.lf_free_stream(rows), fast[1])


def test_lf_rows_do_not_depend_on_the_batch():
    """A row gets the same bits alone as among many, whatever its neighbours."""
    rows = rows_near_the_hull(200, 5)
    together = lf.lf_increment_terms(rows)
    for k in (0, 77, 199):
        alone = lf.lf_increment_terms(rows[k : k + 1])
        for a, b in zip(alone, together, strict=True):
            np.testing.assert_array_equal(a[0], b[k])


def test_batch_envelope_unchanged():
    """A small envelope in the batch engine with the kernel against the same with the reference."""
    surrogate = env.cached_surrogate(SMALL.model)
    fast = env.compute_envelope(SMALL, surrogate).result
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(lf, "lf_increment_terms", lambda inputs: reference_terms(inputs))
        slow = env.compute_envelope(SMALL, surrogate).result
    np.testing.assert_array_equal(fast.outcome, slow.outcome)
    np.testing.assert_allclose(fast.final, slow.final, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.closest, slow.closest, rtol=0, atol=1e-9)


def test_a_batch_spread_over_threads_gives_each_row_the_bits_it_gets_alone():
    """The batch engine's rows run on numba's threads (`lf_kernel.strip_forces_threaded`), the sim's
    one row on one: the same arithmetic per row, so the same bits, the held flags included."""
    rng = np.random.default_rng(5)
    n = 4 * lf.THREADED_ROWS
    rows = np.column_stack(
        [rng.uniform(-0.6, 0.6, n), rng.uniform(0.03, 0.2, n), rng.uniform(1.0, 5.0, n), rng.uniform(-10, 10, n)]
        + [np.full(n, 19.55), np.full(n, 10.0)]
    )
    together = lf.lf_increment_terms(rows)
    assert together[2].any() and not together[2].all()  # some rows hold the field at the hull
    for k in range(n):
        alone = lf.lf_increment_terms(rows[k : k + 1])
        for name, part, batch in zip(("with the submarine", "alone", "held"), alone, together, strict=True):
            np.testing.assert_array_equal(part[0], batch[k], name)
