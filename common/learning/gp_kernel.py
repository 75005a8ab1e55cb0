"""Compiled kernels of `gp`: the ARD RBF kernel matrix and the sums of its log-likelihood
gradient (`gp._lml`), and the row-wise distances of `gp._Predictor.rows`.

`neg_sq_distances` repeats the numpy loop it replaced (scaled row z = x A + B, then the squared
differences summed over the inputs in their order, from zero), element by element, no fastmath:
the same bits (tests/test_gp.py). exp and the weighted sums stay in numpy, whose exp rounds
differently from the C library's. The likelihood kernels replace numpy expressions over a
(d, n^2) array of squared differences, so they agree with them to rounding only. Imported on
first use (`gp._kernel`); compiled once per install into numba's cache, like `hydro.lf_kernel`.
"""

from __future__ import annotations

import math

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


@njit(cache=True)
def rbf_matrix(U, inv_l2, s2, sn2):
    """K = s2 exp(-0.5 sum_k inv_l2_k (u_ik - u_jk)^2) + sn2 I (n, n), thesis (2.5), from the lower
    triangle mirrored: exactly symmetric, half the exps."""
    n, d = U.shape
    K = np.empty((n, n))
    for i in range(n):
        for j in range(i):
            q = 0.0
            for k in range(d):
                diff = U[i, k] - U[j, k]
                q += inv_l2[k] * diff * diff
            v = s2 * math.exp(-0.5 * q)
            K[i, j] = v
            K[j, i] = v
        K[i, i] = s2 + sn2
    return K


@njit(cache=True)
def lml_gradient_sums(U, K, s2, alpha, Kinv_low):
    """sum_ij W_ij Kf_ij (u_ik - u_jk)^2 per input k, then sum_ij W_ij Kf_ij and tr W (d + 2,),
    with W = alpha alpha^T - K^-1 (R&W 5.9) and Kf = K without the noise diagonal (s2 on it).
    Kinv_low: the lower triangle of K^-1 (LAPACK potri); W is symmetric, so the strict lower
    triangle counts twice."""
    n, d = U.shape
    out = np.zeros(d + 2)
    for i in range(n):
        w = alpha[i] * alpha[i] - Kinv_low[i, i]
        out[d] += w * s2
        out[d + 1] += w
        for j in range(i):
            wk = 2.0 * (alpha[i] * alpha[j] - Kinv_low[i, j]) * K[i, j]
            out[d] += wk
            for k in range(d):
                diff = U[i, k] - U[j, k]
                out[k] += wk * diff * diff
    return out
