"""The disk cache of start-up tables: the same bits as computing, and a new key computes afresh."""

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


def test_the_shipped_field_table_is_the_ring_panel_solution_at_its_nodes():
    """nearsub/data/lf-field.npz must match this LF (version, panels, grid) and hold the ring-panel
    velocities at its nodes: checked at 200 random nodes against the solution itself."""
    from nearsub.common.hydro import low_fidelity as lf
    from nearsub.common.physics.hull import suboff_profile

    x, r = lf._field_grid()
    shipped = lf._shipped_field(lf.N_FRUSTA, x, r)
    assert shipped is not None, "the shipped lf-field.npz was made for another LF: rerun `nearsub lf-field`"
    ux, ur = (a.reshape(x.size, r.size) for a in shipped)
    rng = np.random.default_rng(7)
    i, j = rng.integers(0, x.size, 200), rng.integers(0, r.size, 200)
    panels = lf.solve_ring_panels(suboff_profile(lf.N_FRUSTA + 1))
    vx, vr = panels.velocity(x[i], r[j])
    np.testing.assert_allclose(ux[i, j], vx, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(ur[i, j], vr, rtol=1e-12, atol=1e-15)
