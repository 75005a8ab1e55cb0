"""Compiled kernels of `gp`: the ARD RBF kernel matrix and the sums of its log-likelihood
gradient (`gp._lml`), and the row-wise posterior of `gp._Predictor.rows` (`posterior_rows`).

`posterior_rows` is the surrogate's GP mean and std for one query point, compiled, that every
process which predicts runs: the surrogate server, a sim or helm with the model in process, and
the batch engine for its rows (docs/architecture.md, "The interaction kernel"). No fastmath: the
arithmetic is IEEE, in the order written; exp is the C library's, which rounds differently from
numpy's, so it agrees with the numpy formulas to rounding only (tests/test_gp.py). The
likelihood kernels replace numpy expressions over a (d, n^2) array of squared differences, so
they agree with them to rounding only. Imported on first use (`gp._kernel`); compiled once per
install into numba's cache, like `hydro.lf_kernel`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import config, njit, prange

# Whether this process spreads a batch's rows over threads: not in the processes nearsub starts
# (one numba thread each, `runtime.processes.single_blas_thread`), which then never start numba's
# OpenMP pool, so the fork server's children stay safe to fork (GNU OpenMP is not fork-safe).
THREADED = config.NUMBA_NUM_THREADS > 1


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


@njit(cache=True)
def _posterior_row(a, X, A, B, ZT, alpha_s, linv_columns, s2, y_mean, y_std, with_std, mean, std):
    """Row a of `posterior_rows` (the scratch arrays are its own, so rows may run at once)."""
    m, d, n = ZT.shape
    z = np.empty(d)
    e = np.empty(n)
    v = np.empty(n)
    for j in range(m):
        for k in range(d):
            z[k] = X[a, k] * A[j, k] + B[j, k]
        total = 0.0
        for i in range(n):
            sq = 0.0
            for k in range(d):
                diff = ZT[j, k, i] - z[k]
                sq += diff * diff
            e[i] = math.exp(-sq)
            total += e[i] * alpha_s[j, i]
        mean[a, j] = total * y_std[j] + y_mean[j]
        if with_std:
            v[:] = 0.0
            start = 0
            for k in range(n):
                ek = e[k]
                column = linv_columns[j, start : start + n - k]
                below = v[k:]
                for i in range(n - k):
                    below[i] += column[i] * ek
                start += n - k
            sum_sq = 0.0
            for i in range(n):
                sum_sq += v[i] * v[i]
            std[a, j] = math.sqrt(max(s2[j] - sum_sq, 0.0)) * y_std[j]


@njit(cache=True)
def posterior_rows(X, A, B, ZT, alpha_s, linv_columns, s2, y_mean, y_std, with_std, mean, std):
    """Posterior mean (thesis (2.6)) and, with `with_std`, latent std (thesis (2.7)) (rows, m) of
    rows X (rows, d) into mean and std: one row at a time, in a fixed order, so a row's bits do
    not depend on how many rows are asked together (the sim's one vehicle, the surrogate server's
    query, the batch engine's hundreds). Per output j: z = x A[j] + B[j], e_i = exp(-|z - z_i|^2)
    (the squared differences summed over the inputs in their order, from zero), the mean
    sum_i e_i alpha_i y_std + y_mean;
    v = L^-1 e from `linv_columns` (m, n (n + 1) / 2), the columns of the lower-triangular L^-1
    (scaled by s2) packed one after the other from their diagonal down, added to v in column
    order (element-wise, so each v_i is the same sum however the loop is vectorised; a third
    less CPU than BLAS trmv on the full matrix), and the variance s2 - v.v clipped at zero."""
    for a in range(X.shape[0]):
        _posterior_row(a, X, A, B, ZT, alpha_s, linv_columns, s2, y_mean, y_std, with_std, mean, std)


@njit(cache=True, parallel=True)
def posterior_rows_threaded(X, *arrays):
    """`posterior_rows` (the same arguments) with its rows spread over numba's threads (a batch;
    each row the same arithmetic, so the same bits, as one at a time)."""
    for a in prange(X.shape[0]):
        _posterior_row(a, X, *arrays)
