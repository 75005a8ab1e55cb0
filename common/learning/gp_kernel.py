"""Compiled kernel of `gp._Predictor.rows`: the negated squared distances of a block of rows to
the training inputs, for all outputs, in one pass without numpy temporaries.

The arithmetic is the numpy loop's it replaced (scaled row z = x A + B, then the squared
differences summed over the inputs in their order, from zero), element by element, no fastmath:
the same bits (tests/test_gp.py). exp and the weighted sums stay in numpy, whose exp rounds
differently from the C library's. Imported on first use only (`gp._kernel`); compiled once per
install into numba's cache, like `hydro.lf_kernel`.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def neg_sq_distances(X, A, B, ZT):
    """-|z_a - z_i|^2 (m, rows, n) of rows X (rows, d) scaled per output j as X A[j] + B[j], to the
    scaled training inputs ZT (m, d, n)."""
    m, d, n = ZT.shape
    rows = X.shape[0]
    out = np.empty((m, rows, n))
    z = np.empty(d)
    for j in range(m):
        for a in range(rows):
            for k in range(d):
                z[k] = X[a, k] * A[j, k] + B[j, k]
            for i in range(n):
                sq = 0.0
                for k in range(d):
                    diff = ZT[j, k, i] - z[k]
                    sq += diff * diff
                out[j, a, i] = -sq
    return out
