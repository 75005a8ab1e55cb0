"""Compiled kernels of `sampling`: a posterior sample's prior (random Fourier features) and data
update at rows that each have their own sample, row by row, without numpy temporaries.

Element by element in the order numpy evaluated them (no fastmath), and sums in numpy's pairwise
order (`_pairwise`, numpy's `pairwise_sum`: blocks of up to 128 in eight accumulators, halves
above), so they give the bits of the numpy expressions they replaced. `math.cos` is the C
library's cos, which numpy's float64 cos also calls; numpy's exp is its own SIMD code, not the C
library's, so the exponential stays in numpy (`sampling._OutputSamples.__call__`). Imported on first
use, compiled once per install into numba's cache, like `hydro.lf_kernel`.
"""

from __future__ import annotations

import math

from numba import njit

PAIRWISE_MAX = 4096  # longest sum `_pairwise` takes: six levels of halving above blocks of 128


@njit(cache=True)
def _block(a, lo, n):
    """sum of a[lo : lo + n], n <= 128, as numpy's pairwise_sum adds a block: eight accumulators."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - (n % 8):
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def _half(n):
    """Where numpy's pairwise_sum splits a sum of n > 128: half, down to a multiple of 8."""
    return n // 2 - (n // 2) % 8


# numpy's pairwise_sum recurses; numba cannot cache a recursive function, so each level of halving
# is a function of its own (six levels: sums of up to PAIRWISE_MAX).
@njit(cache=True)
def _level1(a, lo, n):
    if n <= 128:
        return _block(a, lo, n)
    h = _half(n)
    return _block(a, lo, h) + _block(a, lo + h, n - h)


@njit(cache=True)
def _level2(a, lo, n):
    if n <= 128:
        return _block(a, lo, n)
    h = _half(n)
    return _level1(a, lo, h) + _level1(a, lo + h, n - h)


@njit(cache=True)
def _level3(a, lo, n):
    if n <= 128:
        return _block(a, lo, n)
    h = _half(n)
    return _level2(a, lo, h) + _level2(a, lo + h, n - h)


@njit(cache=True)
def _level4(a, lo, n):
    if n <= 128:
        return _block(a, lo, n)
    h = _half(n)
    return _level3(a, lo, h) + _level3(a, lo + h, n - h)


@njit(cache=True)
def _level5(a, lo, n):
    if n <= 128:
        return _block(a, lo, n)
    h = _half(n)
    return _level4(a, lo, h) + _level4(a, lo + h, n - h)


@njit(cache=True)
def _pairwise(a, lo, n):
    """sum of a[lo : lo + n], n <= PAIRWISE_MAX, in the order of numpy's pairwise summation (np.sum
    over a contiguous row)."""
    if n <= 128:
        return _block(a, lo, n)
    h = _half(n)
    return _level5(a, lo, h) + _level5(a, lo + h, n - h)


@njit(cache=True)
def prior_rows(Z, sample, omega_t, phase, weights, scale, scratch, out):
    """out[r] = scale sum_f w_f cos(b_f + sum_j Z[r, j] omega_jf), the features of sample[r]:
    the projection summed over j in order, then cos, times w, summed pairwise. The loops over
    the features are innermost (contiguous, vectorised; each element's operations keep their order)."""
    d = Z.shape[1]
    n_features = phase.shape[1]
    for r in range(Z.shape[0]):
        s = sample[r]
        z = Z[r, 0]
        for f in range(n_features):
            scratch[f] = phase[s, f] + z * omega_t[s, 0, f]
        for j in range(1, d):
            z = Z[r, j]
            for f in range(n_features):
                scratch[f] += z * omega_t[s, j, f]
        for f in range(n_features):
            scratch[f] = math.cos(scratch[f]) * weights[s, f]
        out[r] = scale * (0.0 + _pairwise(scratch, 0, n_features))


@njit(cache=True)
def kernel_exponents(Z, U_t, length, out):
    """out[r, t] = -|Z[r] - U[t]|^2_l / 2 (U_t = U transposed, (d, n_train)), the squares summed
    over the inputs in order, the training points innermost (vectorised)."""
    n = U_t.shape[1]
    for r in range(Z.shape[0]):
        for t in range(n):
            out[r, t] = 0.0
        for j in range(U_t.shape[0]):
            z, scale = Z[r, j], length[j]
            for t in range(n):
                diff = (z - U_t[j, t]) / scale
                out[r, t] += diff * diff
        for t in range(n):
            out[r, t] = -0.5 * out[r, t]


@njit(cache=True)
def update_rows(E, s2, sample, v, scratch, out):
    """out[r] = sum_t (s2 E[r, t]) v[sample[r], t] (E the exponentials of `kernel_exponents`),
    summed pairwise: the data update k(z, U) K^-1 (y - f(U) - eps) of each row's own sample."""
    n = E.shape[1]
    for r in range(E.shape[0]):
        s = sample[r]
        for t in range(n):
            scratch[t] = (s2 * E[r, t]) * v[s, t]
        out[r] = 0.0 + _pairwise(scratch, 0, n)
