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
