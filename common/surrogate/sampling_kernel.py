"""Compiled kernels of `sampling`: a posterior sample's prior (random Fourier features) and data
update at rows that each have their own sample, row by row, without numpy temporaries.

Element by element in the order numpy evaluated them (no fastmath), and sums in numpy's pairwise
order (`_pairwise`, numpy's `pairwise_sum`: blocks of up to 128 in eight accumulators, halves
above), so they give the bits of the numpy expressions they replaced, with `cos` (below) for the
features' cosine. numpy's exp is its own SIMD code, not the C library's, so the exponential stays
in numpy (`sampling._OutputSamples._update`). Imported on first use, compiled once per install
into numba's cache, like `hydro.lf_kernel`.

`cos` is plain float64 arithmetic, not a call into the C library, so LLVM vectorises the features'
loop (packed multiplies and adds, four or eight features at a time). Its bits are those of the
IEEE operations in the order written (no fastmath, so no FMA contraction and no reassociation):
the same on every CPU whatever the vector width, and an element's value depends on its argument
only, not on its place in the loop or how many rows are asked. Within 1 ulp of the C library's
cos on |x| <= COS_LIMIT (tests/test_sampling.py); `prior_rows` takes the C library's cos for an
argument beyond that.
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


# Cody-Waite reduction by pi/2 in three parts and the minimax kernels of sin and cos on
# [-pi/4, pi/4]: the constants of fdlibm (e_rem_pio2.c, k_cos.c, k_sin.c; Sun Microsystems 1993),
# the kernels' final sums as FreeBSD msun has them (k_cos.c, Bruce D. Evans 2004), branch free.
_INVPIO2 = 6.36619772367581382433e-01  # 2 / pi
_PIO2_1 = 1.57079632673412561417e00  # first 33 bits of pi / 2
_PIO2_2 = 6.07710050630396597660e-11  # next 33 bits
_PIO2_3 = 2.02226624871116645580e-21  # next 33 bits
_PIO2_3T = 8.47842766036889956997e-32  # pi / 2 - (_PIO2_1 + _PIO2_2 + _PIO2_3)
_ROUND = 6755399441055744.0  # 1.5 * 2^52: x + _ROUND - _ROUND rounds |x| < 2^51 to an integer
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
# n pi/2 with n < 2^19 keeps n _PIO2_k exact (33 + 19 bits), as in fdlibm's medium range.
COS_LIMIT = 2.0**19 * (math.pi / 2.0)


@njit(cache=True)
def cos(x):
    """cos(x) for |x| <= COS_LIMIT (wrong beyond it: the caller checks), from arithmetic alone."""
    t = abs(x)
    n = (t * _INVPIO2 + _ROUND) - _ROUND  # nearest integer to t / (pi / 2)
    a = t - n * _PIO2_1  # exact, and so are the products n * _PIO2_k below
    b = n * _PIO2_2
    r1 = a - b  # two-sums: r1 + e1 = a - b, r2 + e2 = r1 - c exactly
    v1 = r1 - a
    e1 = (a - (r1 - v1)) + (-b - v1)
    c = n * _PIO2_3
    r2 = r1 - c
    v2 = r2 - r1
    e2 = (r1 - (r2 - v2)) + (-c - v2)
    lo = (e1 + e2) - n * _PIO2_3T
    y = r2 + lo  # t - n pi/2 = y + yy, a double-double
    yy = lo - (y - r2)
    z = y * y
    w = z * z
    rc = z * (_C1 + z * (_C2 + z * _C3)) + w * w * (_C4 + z * (_C5 + z * _C6))
    hz = 0.5 * z
    w1 = 1.0 - hz
    kc = w1 + (((1.0 - w1) - hz) + (z * rc - y * yy))  # cos(y + yy)
    rs = _S2 + z * (_S3 + z * _S4) + z * w * (_S5 + z * _S6)
    v = z * y
    ks = y - ((z * (0.5 * yy - v * rs) - yy) - v * _S1)  # sin(y + yy)
    q = n - 4.0 * ((0.25 * n + _ROUND) - _ROUND)  # n mod 4, as -2, -1, 0, 1 or 2
    k = ks if abs(q) == 1.0 else kc
    return -k if (q > 0.5) | (q < -1.5) else k  # quadrants 1 and 2 negative


@njit(cache=True)
def prior_rows(Z, sample, omega_t, phase, weights, scale, bound, scratch, out):
    """out[r] = scale sum_f w_f cos(b_f + sum_j Z[r, j] omega_jf), the features of sample[r]:
    the projection summed over j in order, then cos, times w, summed pairwise. The loops over
    the features are innermost (contiguous, vectorised; each element's operations keep their order).
    bound[s, j] = max_f |omega_jf| of sample s: a row whose arguments may pass COS_LIMIT
    (2 pi + sum_j |z_j| bound_j above half of it) goes element by element, the C library's cos
    beyond the limit, the same `cos` within it."""
    d = Z.shape[1]
    n_features = phase.shape[1]
    for r in range(Z.shape[0]):
        s = sample[r]
        z = Z[r, 0]
        reach = 2.0 * math.pi
        for j in range(d):
            reach += abs(Z[r, j]) * bound[s, j]
        for f in range(n_features):
            scratch[f] = phase[s, f] + z * omega_t[s, 0, f]
        for j in range(1, d):
            z = Z[r, j]
            for f in range(n_features):
                scratch[f] += z * omega_t[s, j, f]
        if reach <= 0.5 * COS_LIMIT:
            for f in range(n_features):
                scratch[f] = cos(scratch[f]) * weights[s, f]
        else:  # also a NaN input
            for f in range(n_features):
                a = scratch[f]
                scratch[f] = (cos(a) if abs(a) <= COS_LIMIT else math.cos(a)) * weights[s, f]
        out[r] = scale * (0.0 + _pairwise(scratch, 0, n_features))


@njit(cache=True)
def kernel_exponents(Z, U_scaled_t, length, out):
    """out[r, t] = -|Z[r] - U[t]|^2_l / 2 (U_scaled_t[j, t] = U[t, j] / length[j]), the squares
    summed over the inputs in order, the training points innermost (vectorised)."""
    n = U_scaled_t.shape[1]
    for r in range(Z.shape[0]):
        for t in range(n):
            out[r, t] = 0.0
        for j in range(U_scaled_t.shape[0]):
            z = Z[r, j] / length[j]
            for t in range(n):
                diff = z - U_scaled_t[j, t]
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
