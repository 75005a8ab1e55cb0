"""The disk cache of start-up tables: the same bits as computing, and a new key computes afresh; the
shipped field table: read on any CPU, and the ring-panel solution."""

import numpy as np

from nearsub.common.hydro import cache


def test_cached_arrays_come_back_bit_for_bit_and_a_new_key_computes_again(tmp_path, monkeypatch):
    monkeypatch.setenv("NEARSUB_CACHE", str(tmp_path))
    calls = []

    def compute():
        calls.append(1)
        return np.array([0.1, np.pi, -1e-300]), np.arange(4.0)

    key = cache.cache_key([cache.__file__], "grid", np.linspace(0, 1, 3).tobytes())
    first = cache.cached_arrays("table", key, compute)
    again = cache.cached_arrays("table", key, compute)
    assert len(calls) == 1
    assert all(a.tobytes() == b.tobytes() for a, b in zip(first, again, strict=True))
    other = cache.cache_key([cache.__file__], "another grid")
    cache.cached_arrays("table", other, compute)
    assert len(calls) == 2 and key != other


def test_an_unwritable_cache_only_costs_the_computation(tmp_path, monkeypatch):
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    monkeypatch.setenv("NEARSUB_CACHE", str(blocked))
    values = cache.cached_arrays("table", "k", lambda: (np.ones(2),))
    assert values[0].tolist() == [1.0, 1.0]


def count_tabulations(monkeypatch, tmp_path) -> list:
    """A fresh process's view of the field (no table in memory, an empty disk cache) with each
    tabulation counted."""
    from nearsub.common.hydro import low_fidelity as lf

    monkeypatch.setenv("NEARSUB_CACHE", str(tmp_path / "cache"))
    lf._submarine_field.cache_clear()
    monkeypatch.setattr(lf, "_submarine_field", lf._submarine_field.__wrapped__)
    calls = []
    tabulate = lf.tabulate_field
    monkeypatch.setattr(lf, "tabulate_field", lambda n: calls.append(n) or tabulate(n))
    return calls


def test_the_shipped_field_table_is_read_on_any_cpu_and_never_tabulated_again(monkeypatch, tmp_path):
    """The shipped nearsub/data/lf-field.npz is recognised by its identity (format, LF version, panel
    count, the grid's decimal parameters), never by its nodes' bits, which differ between CPUs: a
    process near a submarine reads it and tabulates nothing. A table for another grid is refused."""
    from nearsub.common.hydro import low_fidelity as lf

    calls = count_tabulations(monkeypatch, tmp_path)
    field = lf.submarine_field()
    assert calls == [], "the shipped lf-field.npz was refused: rerun `nearsub lf-field` and ship its file"
    x, r, _, _ = lf.read_field_table(lf.shipped_field_path(), lf.N_FRUSTA)
    assert (field.x_range, field.r_range) == ((x[0], x[-1]), (r[0], r[-1]))  # on its own stored nodes

    other_grid = tmp_path / "other-grid.npz"
    with np.load(lf.shipped_field_path()) as shipped:
        np.savez(other_grid, **{**shipped, "grid": np.array(str(shipped["grid"]).replace("1.12", "1.13"))})
    assert lf.read_field_table(other_grid, lf.N_FRUSTA) is None
    assert lf.read_field_table(lf.shipped_field_path(), lf.N_FRUSTA + 1) is None


def test_a_table_written_by_lf_field_is_read_back_without_tabulating(monkeypatch, tmp_path):
    """What `nearsub lf-field` writes on this machine is accepted as the shipped table would be."""
    from nearsub.common.hydro import low_fidelity as lf

    written = tmp_path / "lf-field.npz"
    np.savez_compressed(written, **lf.tabulate_field())
    calls = count_tabulations(monkeypatch, tmp_path)
    monkeypatch.setattr(lf, "shipped_field_path", lambda: written)
    lf.submarine_field()
    assert calls == []
    monkeypatch.setattr(lf, "shipped_field_path", lambda: tmp_path / "none.npz")
    lf.submarine_field()
    assert calls == [lf.N_FRUSTA]  # no table: tabulated (the count above would have seen it)


# The shipped values against this machine's ring-panel solution [U]: both are the same arithmetic
# (a 240-panel dense solve, elliptic integrals) rounded by different SIMD kernels and BLAS, 1.6e-14 U
# apart between an AVX-512 and an AVX2 machine; a real change is far above 1e-12 U (960 panels
# instead of 240 move the field by 6e-4 U, another grid puts other velocities at the nodes).
FIELD_ROUNDING = 1e-12


def test_the_shipped_field_table_is_the_ring_panel_solution_at_its_nodes():
    """nearsub/data/lf-field.npz holds the ring-panel velocities at its stored nodes: checked at 200
    random nodes against the solution computed here, to FIELD_ROUNDING in units of the stream speed
    (absolute: far out the field is 1e-8 U, where a relative tolerance would measure rounding)."""
    from nearsub.common.hydro import low_fidelity as lf
    from nearsub.common.physics.hull import suboff_profile

    x, r, ux, ur = lf.read_field_table(lf.shipped_field_path(), lf.N_FRUSTA)
    ux, ur = ux.reshape(x.size, r.size), ur.reshape(x.size, r.size)
    rng = np.random.default_rng(7)
    i, j = rng.integers(0, x.size, 200), rng.integers(0, r.size, 200)
    panels = lf.solve_ring_panels(suboff_profile(lf.N_FRUSTA + 1))
    vx, vr = panels.velocity(x[i], r[j])
    np.testing.assert_allclose(ux[i, j], vx, rtol=0, atol=FIELD_ROUNDING)
    np.testing.assert_allclose(ur[i, j], vr, rtol=0, atol=FIELD_ROUNDING)
