"""Gaussian-process regression core: ARD RBF kernel, type-II maximum likelihood, fast prediction.

Numpy/scipy (no GPy, no scikit-learn at run time), and one numba kernel for row-wise prediction
(`gp_kernel`). The thesis builds its surrogates from one independent GP per output (thesis
section 2.5, used again in section 4.4); this module provides the single-output `GaussianProcess`
and the `MultiOutputGP` container.

Conventions (see docs in the classes):

* Inputs are mapped to the unit cube with known bounds, so hyperparameters are comparable from
  one active-learning iteration to the next. Outputs are standardised (mean 0, std 1) per GP.
* Hyperparameters live in log space, ``theta = [log l_1 .. log l_d, log s2, log sn2]``, where
  ``l`` are length scales on the unit cube, ``s2`` the signal variance and ``sn2`` the noise
  variance, both in standardised output units.
* Predicted std is the std of the latent function f (thesis (2.7)), not of a noisy observation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.linalg.blas import dtrmm
from scipy.linalg.lapack import dpotrf, dpotri, dpotrs, dtrtri
from scipy.optimize import minimize

__all__ = ["FINAL_FIT_RESTARTS", "DegenerateFitError", "GaussianProcess", "MultiOutputGP"]

# Optimiser starts of every final surrogate fit: with 2 starts the shipped N' fit sat 2-3x worse
# than a 10-start refit (docs/hydro/validation.md, "Fitting").
FINAL_FIT_RESTARTS = 10
# An optimum with every length scale within this (log units) of a bound is degenerate: all at the
# floor is white noise that interpolates, all at the ceiling a constant. It is rejected, and a
# fresh round of random starts tried, up to _REJECT_ROUNDS rounds in all.
_AT_BOUND_TOL = 1e-3
_REJECT_ROUNDS = 3

# Jitter ladder, as multiples of mean(diag K): try the exact matrix first, then add more and
# more until Cholesky succeeds (GPy's jitchol; GPy #642, BoTorch #862 show why it is needed).
_JITTER_LADDER = (0.0, 1e-10, 1e-8, 1e-6, 1e-4)
# Default start: l = 0.5 (half the domain width: a smooth response), s2 = 1 (y is
# standardised), sn2 = 1e-6 (near-deterministic simulators). Clipped into the bounds.
_DEFAULT_LENGTH_SCALE = 0.5
_DEFAULT_SIGNAL_VARIANCE = 1.0
_DEFAULT_NOISE_VARIANCE = 1e-6
# Random starts are log-uniform in this "plausible" box intersected with the bounds. Starts at
# l = 1e-2 (allowed as an optimum) leave K ~ s2*I with vanishing gradients, a wasted restart.
_RANDOM_LENGTH_SCALE = (0.05, 5.0)
_RANDOM_SIGNAL_VARIANCE = (0.1, 10.0)
# Noise starts stay above 1e-6: from near the floor, d LML / d log sn2 = sn2 tr(W) / 2 is tiny
# and L-BFGS-B stays in the interpolating optimum even when the data are noisy (GPy #848).
# The default start already covers the low-noise basin.
_RANDOM_NOISE_VARIANCE = (1e-6, 1.0)
# Rows per block in batch prediction: bounds the (rows, n) temporaries.
_BATCH_ROWS = 4096
# Rows from which `rows` spreads them over numba's threads (`gp_kernel.posterior_rows_threaded`, the
# same bits per row). The shipped model's delta with its std on 2 cores: 1 row 57 -> 61 us, 4 rows
# 163 -> 128, 750 rows 27.4 -> 19.7 ms (memory-bound: each row reads every L^-1). Processes a
# launcher or a Dask cluster starts have one thread each, so only a batch in one process (a sweep)
# uses the cores this way.
THREADED_ROWS = 4
_LOG_2PI = math.log(2.0 * math.pi)


class DegenerateFitError(RuntimeError):
    """No optimiser start reached an acceptable optimum (see `all_length_scales_at_bound`)."""


def all_length_scales_at_bound(log_l: np.ndarray, log_bounds: np.ndarray) -> bool:
    """True if every log length scale lies within _AT_BOUND_TOL of its lower or upper bound."""
    near = np.minimum(np.abs(log_l - log_bounds[:, 0]), np.abs(log_l - log_bounds[:, 1]))
    return bool(np.all(near < _AT_BOUND_TOL))


def _cholesky(K: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Lower Cholesky factor of K with the jitter ladder; None if even the largest jitter fails."""
    scale = float(np.mean(np.diag(K)))
    for rel in _JITTER_LADDER:
        jitter = rel * scale
        Kj = K + jitter * np.eye(K.shape[0]) if jitter else K
        L, info = dpotrf(Kj, lower=1, clean=1)
        if info == 0:
            return L, jitter
    return None


def _rbf(theta: np.ndarray, U: np.ndarray) -> np.ndarray:
    """K (n, n) of the ARD RBF kernel, thesis (2.5) with lambda = diag(l^2), plus the noise."""
    d = U.shape[1]
    return _kernel().rbf_matrix(U, np.exp(-2.0 * theta[:d]), math.exp(theta[d]), math.exp(theta[d + 1]))


def _lml_of_factor(L: np.ndarray, alpha: np.ndarray, y: np.ndarray) -> float:
    """log p(y) = -y^T alpha / 2 - sum log L_ii - n log(2 pi) / 2 (R&W Alg. 2.1)."""
    return -0.5 * float(y @ alpha) - float(np.sum(np.log(np.diag(L)))) - 0.5 * len(y) * _LOG_2PI


def _lml(theta: np.ndarray, U: np.ndarray, y: np.ndarray, eval_gradient: bool) -> tuple[float, np.ndarray | None]:
    """Log marginal likelihood of standardised data (R&W Alg. 2.1) and its gradient (R&W 5.9)
    at unit-cube inputs U (n, d).

    Returns (-inf, None) when the Cholesky factorisation fails even with jitter, so the
    optimiser backtracks instead of crashing (scikit-learn's trick).
    """
    n, d = U.shape
    inv_l2 = np.exp(-2.0 * theta[:d])
    s2 = math.exp(theta[d])
    sn2 = math.exp(theta[d + 1])
    K = _rbf(theta, U)
    fact = _cholesky(K)
    if fact is None:
        return -math.inf, None
    L, _ = fact
    alpha, _ = dpotrs(L, y, lower=1)
    lml = _lml_of_factor(L, alpha, y)
    if not math.isfinite(lml):
        return -math.inf, None
    if not eval_gradient:
        return lml, None
    # K^-1 from the factor (LAPACK potri: a third of the flops of solving K X = I), as its lower
    # triangle; dLML/dtheta_j = 0.5 tr(W dK/dtheta_j), W = alpha alpha^T - K^-1, summed over
    # that triangle in one compiled pass (no (d, n^2) array of squared differences).
    Kinv_low, _ = dpotri(L, lower=1)
    sums = _kernel().lml_gradient_sums(U, K, s2, alpha, Kinv_low)
    grad = np.empty(d + 2)
    grad[:d] = 0.5 * sums[:d] * inv_l2  # dK/dlog l_k = Kf * (dx_k / l_k)^2
    grad[d] = 0.5 * sums[d]  # dK/dlog s2 = Kf
    grad[d + 1] = 0.5 * sn2 * sums[d + 1]  # dK/dlog sn2 = sn2 * I
    return lml, grad


def _neg_lml(theta: np.ndarray, U: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray]:
    """L-BFGS-B objective: +inf with a zero gradient where the factorisation fails."""
    lml, grad = _lml(theta, U, y, True)
    if grad is None:
        return math.inf, np.zeros_like(theta)
    return -lml, -grad


def _kernel():
    """The compiled kernels (`gp_kernel`), imported on first use: a process that only predicts
    from a plain-numpy path does not pay numba's import."""
    from nearsub.common.learning import gp_kernel

    return gp_kernel


class _Predictor:
    """Posterior mean/std of m GPs sharing training inputs, precomputed for speed.

    Each output j uses scaled coordinates z = x * A[j] + B[j] = (unit-cube x) / (sqrt(2) l_j),
    so the kernel is s2_j * exp(-|z - z_i|^2). The factor s2_j is folded into alpha and L^-1.
    Arrays are stacked over outputs so one numpy expression serves all outputs of one point.
    """

    def __init__(self, gps: Sequence[GaussianProcess]):
        # C order everywhere: numpy/BLAS pick kernels (and rounding) by memory layout, and a
        # model rebuilt from a state must round exactly like the original.
        def stack(arrays):
            return np.ascontiguousarray(np.stack(arrays))

        self.A = stack([gp._A for gp in gps])  # (m, d)
        self.B = stack([gp._B for gp in gps])  # (m, d)
        self.Z = stack([gp._Z for gp in gps])  # (m, n, d) scaled training inputs
        self.ZZ = np.einsum("mnd,mnd->mn", self.Z, self.Z)  # (m, n)
        self.Zt2 = np.ascontiguousarray(-2.0 * self.Z.transpose(0, 2, 1))  # (m, d, n)
        self.ZT = np.ascontiguousarray(self.Z.transpose(0, 2, 1))  # (m, d, n)
        self.s2 = np.array([gp.signal_variance for gp in gps])  # (m,)
        self.alpha_s = stack([gp._alpha * gp.signal_variance for gp in gps])  # (m, n)
        self.Linv_s = stack([gp._L_inv * gp.signal_variance for gp in gps])  # (m, n, n)
        self.LinvT_s = np.ascontiguousarray(self.Linv_s.transpose(0, 2, 1))
        # The columns of each L^-1 packed from the diagonal down (`gp_kernel.posterior_rows`).
        self.linv_columns = stack([self.LinvT_s[j][np.triu_indices(self.Z.shape[1])] for j in range(len(gps))])
        self.y_mean = np.array([gp.y_mean_ for gp in gps])
        self.y_std = np.array([gp.y_std_ for gp in gps])
        # Load (the first time after an install, compile) the kernel of `rows` with the model, so
        # that a server's or a sim's first prediction costs no more than the next.
        self.rows(np.zeros((0, self.A.shape[1])), True)

    def point(self, x: np.ndarray, return_std: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Mean and std (m,) at one point x (d,): the hot path, ~a dozen small numpy calls."""
        diff = self.Z - (x * self.A + self.B)[:, None, :]
        e = np.exp(-np.einsum("mnd,mnd->mn", diff, diff))
        mean = self.y_mean + self.y_std * np.einsum("mn,mn->m", e, self.alpha_s)  # thesis (2.6)
        if not return_std:
            return mean, None
        return mean, self._point_std(e)

    def _point_std(self, e: np.ndarray) -> np.ndarray:
        v = np.matmul(self.Linv_s, e[:, :, None])
        var = self.s2 - np.einsum("mni,mni->m", v, v)  # thesis (2.7), diagonal
        return self.y_std * np.sqrt(np.maximum(var, 0.0))

    def rows(self, X: np.ndarray, return_std: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Mean and std (N, m) with per-row arithmetic that does not depend on how many rows are
        asked together: one vehicle and a batch of vehicles get the same bits for the same point,
        mean and std (`gp_kernel.posterior_rows`, compiled: the shipped model's delta at one row,
        with its std, 78-87 -> 42 us of CPU, against exp in numpy and a BLAS triangular product per
        output). Squared distances are formed from differences, without the cancelling
        |z|^2 + |z_i|^2 - 2 z.z_i expansion of `batch`."""
        X = np.ascontiguousarray(X, dtype=float)
        mean = np.empty((X.shape[0], self.s2.shape[0]))
        std = np.empty_like(mean) if return_std else np.empty((0, 0))
        threaded = _kernel().THREADED and X.shape[0] >= THREADED_ROWS
        kernel = _kernel().posterior_rows_threaded if threaded else _kernel().posterior_rows
        kernel(
            X, self.A, self.B, self.ZT, self.alpha_s, self.linv_columns, self.s2, self.y_mean, self.y_std, return_std,
            mean, std,
        )  # fmt: skip
        return mean, (std if return_std else None)

    def batch(self, X: np.ndarray, return_std: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Mean and std (N, m) at many points; BLAS matrix products on row blocks."""
        N = X.shape[0]
        m = self.s2.shape[0]
        mean = np.empty((N, m))
        std = np.empty((N, m)) if return_std else None
        for start in range(0, N, _BATCH_ROWS):
            Xb = X[start : start + _BATCH_ROWS]
            for j in range(m):
                Zb = Xb * self.A[j] + self.B[j]
                # |z - z_i|^2 = |z|^2 + |z_i|^2 - 2 z.z_i, clipped at 0 against rounding
                sq = Zb @ self.Zt2[j]
                sq += self.ZZ[j]
                sq += np.einsum("nd,nd->n", Zb, Zb)[:, None]
                np.maximum(sq, 0.0, out=sq)
                np.negative(sq, out=sq)
                E = np.exp(sq, out=sq)
                mean[start : start + _BATCH_ROWS, j] = E @ self.alpha_s[j]  # thesis (2.6)
                if std is not None:
                    std[start : start + _BATCH_ROWS, j] = self._batch_std(E, j)
        mean *= self.y_std
        mean += self.y_mean
        if std is not None:
            std *= self.y_std
        return mean, std

    def _batch_std(self, E: np.ndarray, j: int) -> np.ndarray:
        """Overwrites E (rows, n) with V^T = L^-1 E^T: a triangular product (BLAS trmm, in place on
        the Fortran-ordered view E^T), half the flops of a general one."""
        Vt = dtrmm(1.0, self.LinvT_s[j].T, E.T, side=0, lower=1, overwrite_b=1)
        var = self.s2[j] - np.einsum("in,in->n", Vt, Vt)  # thesis (2.7), diagonal
        return np.sqrt(np.maximum(var, 0.0))


def _as_2d(X: Any, d: int | None = None) -> np.ndarray:
    X = np.asarray(X, dtype=float)
    if X.ndim != 2:
        raise ValueError(f"X must be a 2-D array (n, d), got shape {X.shape}")
    if d is not None and X.shape[1] != d:
        raise ValueError(f"X has {X.shape[1]} columns, the model has {d} inputs")
    return X


class GaussianProcess:
    """Single-output GP regression with an ARD RBF kernel (thesis (2.5)) fitted by max. likelihood.

    Parameters
    ----------
    bounds : array (d, 2) or None
        Input domain used to map inputs to the unit cube. Prefer the known design domain, so the
        scaling (and thus the hyperparameters) stays fixed as points are added. None: use the
        training data's min/max per column (a constant column gets width 1).
    n_restarts : int
        Total number of L-BFGS-B starts (not "additional" starts as in scikit-learn). The first
        is the default start l = 0.5 (unit cube), s2 = 1, sn2 = 1e-6 (clipped to the bounds);
        the others are log-uniform random draws (l in [0.05, 5], s2 in [0.1, 10], sn2 in
        [1e-6, 1], intersected with the bounds). With ``fit(..., warm_start=True)`` the previous
        optimum replaces the last random start; it is tried first.
    seed : int
        Seeds a fresh numpy Generator at every fit, so a fit depends only on its inputs.
    noise_bounds, length_scale_bounds, signal_variance_bounds : (low, high)
        Box bounds for sn2 (standardised output units), l (unit-cube units) and s2
        (standardised output units). The low noise floor suits deterministic simulators.
    normalize : bool
        Standardise y (mean, population std) before fitting; False fits y as given.
    """

    def __init__(
        self,
        bounds: Any = None,
        n_restarts: int = 5,
        seed: int = 0,
        noise_bounds: tuple[float, float] = (1e-10, 1e-1),
        length_scale_bounds: tuple[float, float] = (1e-2, 1e2),
        signal_variance_bounds: tuple[float, float] = (1e-2, 1e2),
        normalize: bool = True,
    ):
        if bounds is not None:
            bounds = np.array(bounds, dtype=float)
            if bounds.ndim != 2 or bounds.shape[1] != 2 or np.any(bounds[:, 1] <= bounds[:, 0]):
                raise ValueError("bounds must have shape (d, 2) with upper > lower")
        if n_restarts < 1:
            raise ValueError("n_restarts must be >= 1")
        for name, (low, high) in (
            ("noise_bounds", noise_bounds),
            ("length_scale_bounds", length_scale_bounds),
            ("signal_variance_bounds", signal_variance_bounds),
        ):
            if not 0.0 < low <= high < math.inf:
                raise ValueError(f"{name} must satisfy 0 < low <= high < inf (log parameters)")
        self.bounds = bounds
        self.n_restarts = int(n_restarts)
        self.seed = int(seed)
        self.noise_bounds = (float(noise_bounds[0]), float(noise_bounds[1]))
        self.length_scale_bounds = (float(length_scale_bounds[0]), float(length_scale_bounds[1]))
        self.signal_variance_bounds = (
            float(signal_variance_bounds[0]),
            float(signal_variance_bounds[1]),
        )
        self.normalize = bool(normalize)
        self.theta_: np.ndarray | None = None

    # ----------------------------------------------------------------- fitting
    def fit(self, X: Any, y: Any, *, warm_start: bool = False, theta: Any = None) -> GaussianProcess:
        """Fit hyperparameters by maximising the log marginal likelihood, then condition on data.

        warm_start: also start from the previous optimum (cheap refit after adding a point;
        hyperparameters drift slowly in active learning). Ignored before the first fit.
        theta: log hyperparameters to use as they are, without optimisation (conditioning only,
        e.g. for NMMF's temporary points or to reproduce a given model).
        """
        X = _as_2d(X)
        y = np.asarray(y, dtype=float)
        if y.shape != (X.shape[0],):
            raise ValueError(f"y must have shape ({X.shape[0]},), got {y.shape}")
        if X.shape[0] < 1 or not (np.all(np.isfinite(X)) and np.all(np.isfinite(y))):
            raise ValueError("X and y must be non-empty and finite")
        d = X.shape[1]
        if self.bounds is not None and self.bounds.shape[0] != d:
            raise ValueError(f"bounds has {self.bounds.shape[0]} rows, X has {d} columns")
        previous = self.theta_ if warm_start else None

        if self.bounds is not None:
            lower, width = self.bounds[:, 0].copy(), self.bounds[:, 1] - self.bounds[:, 0]
        else:
            lower, width = X.min(axis=0), X.max(axis=0) - X.min(axis=0)
            width[width == 0.0] = 1.0
        if self.normalize:
            y_mean, y_std = float(np.mean(y)), float(np.std(y))
            y_std = y_std if y_std > 0.0 else 1.0
        else:
            y_mean, y_std = 0.0, 1.0
        self.X_train_, self.y_train_ = X.copy(), y.copy()
        self.lower_, self.width_ = lower, width
        self.y_mean_, self.y_std_ = y_mean, y_std
        self._U = (X - lower) / width
        self._ys = (y - y_mean) / y_std

        if theta is None:
            theta = self._optimise(previous)
        else:
            theta = np.array(theta, dtype=float)
            if theta.shape != (d + 2,):
                raise ValueError(f"theta must have shape ({d + 2},), got {theta.shape}")
        self._condition(theta)
        return self

    def _theta_bounds(self, d: int) -> np.ndarray:
        return np.log([self.length_scale_bounds] * d + [self.signal_variance_bounds, self.noise_bounds])

    def _optimise(self, previous: np.ndarray | None) -> np.ndarray:
        d = self._U.shape[1]
        tb = self._theta_bounds(d)
        rng = np.random.default_rng(self.seed)

        def box(low: float, high: float, row: int) -> tuple[float, float]:
            lo, hi = max(math.log(low), tb[row, 0]), min(math.log(high), tb[row, 1])
            return (lo, hi) if lo <= hi else (tb[row, 0], tb[row, 1])

        rand_box = np.array(
            [box(*_RANDOM_LENGTH_SCALE, k) for k in range(d)]
            + [box(*_RANDOM_SIGNAL_VARIANCE, d), box(*_RANDOM_NOISE_VARIANCE, d + 1)]
        )
        default = np.log([_DEFAULT_LENGTH_SCALE] * d + [_DEFAULT_SIGNAL_VARIANCE])
        default = np.append(default, math.log(_DEFAULT_NOISE_VARIANCE))
        starts = [np.clip(default, tb[:, 0], tb[:, 1])]
        starts += list(rng.uniform(rand_box[:, 0], rand_box[:, 1], (self.n_restarts - 1, d + 2)))
        if previous is not None and previous.shape == (d + 2,):
            starts = [np.clip(previous, tb[:, 0], tb[:, 1])] + starts[: self.n_restarts - 1]

        self.n_rejected_ = 0
        for _ in range(_REJECT_ROUNDS):
            best_theta, best_f = None, math.inf
            for x0 in starts:
                res = minimize(_neg_lml, x0, args=(self._U, self._ys), jac=True, method="L-BFGS-B", bounds=tb)
                if not math.isfinite(res.fun):
                    continue
                if all_length_scales_at_bound(res.x[:d], tb[:d]):
                    self.n_rejected_ += 1
                elif res.fun < best_f:
                    best_theta, best_f = res.x, float(res.fun)
            if best_theta is not None:
                return best_theta
            starts = list(rng.uniform(rand_box[:, 0], rand_box[:, 1], (self.n_restarts, d + 2)))
        raise DegenerateFitError(
            f"GP fit failed: after {_REJECT_ROUNDS} rounds of {self.n_restarts} starts every optimum had all "
            "length scales at a bound (or the kernel matrix was not factorisable)"
        )

    def _condition(self, theta: np.ndarray) -> None:
        """Factorise K at theta and precompute alpha = K^-1 y and L^-1 for prediction."""
        fact = _cholesky(_rbf(theta, self._U))
        if fact is None:
            raise RuntimeError("GP conditioning failed: K is not factorisable even with jitter")
        L, jitter = fact
        self.theta_ = theta
        self.jitter_ = jitter
        self._alpha = dpotrs(L, self._ys, lower=1)[0]
        self._L_inv = dtrtri(L, lower=1)[0]  # LAPACK triangular inverse: a third of solving L X = I
        self.log_marginal_likelihood_value_ = _lml_of_factor(L, self._alpha, self._ys)  # = _lml's
        self._finish()

    def _finish(self) -> None:
        """Derive the prediction arrays (elementwise only, so bit-reproducible from a state)."""
        d = self.lower_.shape[0]
        scale = 1.0 / (math.sqrt(2.0) * np.exp(self.theta_[:d]))
        self._A = scale / self.width_
        self._B = -self.lower_ * self._A
        self._Z = self._U * scale
        self._predictor = _Predictor([self])

    # ------------------------------------------------------------- prediction
    def predict(self, X: Any, return_std: bool = False):
        """Posterior mean (n,) at X (n, d), and the latent std (n,) if return_std.

        The variance is computed only when asked. Single rows take a low-overhead path.
        """
        if self.theta_ is None:
            raise RuntimeError("GaussianProcess is not fitted")
        X = _as_2d(X, self.lower_.shape[0])
        if X.shape[0] == 1:
            mean, std = self._predictor.point(X[0], return_std)
        else:
            mean, std = self._predictor.batch(X, return_std)
            mean = mean[:, 0]
            std = std[:, 0] if std is not None else None
        return (mean, std) if return_std else mean

    def scale_std(self, factor: float) -> None:
        """Multiply the posterior std by `factor`, the mean unchanged (to rounding): the signal and
        noise variances both times factor^2 (common/surrogate/calibration.py)."""
        theta = self.theta_.copy()
        theta[-2:] += 2.0 * math.log(factor)
        self._condition(theta)

    # ---------------------------------------------------------- likelihood
    def log_marginal_likelihood(self, theta: Any = None, eval_gradient: bool = True):
        """LML of the standardised training data at log hyperparameters theta (default: fitted).

        Returns (lml, gradient w.r.t. theta) if eval_gradient, else lml; -inf (gradient None)
        where K cannot be factorised.
        """
        if self.theta_ is None:
            raise RuntimeError("GaussianProcess is not fitted")
        theta = self.theta_ if theta is None else np.asarray(theta, dtype=float)
        lml, grad = _lml(theta, self._U, self._ys, eval_gradient)
        return (lml, grad) if eval_gradient else lml

    # ----------------------------------------------------- hyperparameters
    @property
    def length_scales_unit(self) -> np.ndarray:
        """ARD length scales on the unit cube."""
        return np.exp(self.theta_[: self.lower_.shape[0]])

    @property
    def length_scales(self) -> np.ndarray:
        """ARD length scales in the original input units."""
        return self.length_scales_unit * self.width_

    @property
    def signal_variance(self) -> float:
        """Signal variance s2 in standardised output units (times y_std_**2 for output units)."""
        return math.exp(self.theta_[-2])

    @property
    def noise_variance(self) -> float:
        """Noise variance sn2 in standardised output units (times y_std_**2 for output units)."""
        return math.exp(self.theta_[-1])

    # --------------------------------------------------------------- state
    def get_state(self) -> dict[str, Any]:
        """Everything needed to rebuild the fitted model without refitting (plain arrays/scalars).

        Holds the training data, scaling, hyperparameters and the precomputed alpha and L^-1,
        so predictions after `from_state` are bit-identical on any machine.
        """
        if self.theta_ is None:
            raise RuntimeError("GaussianProcess is not fitted")
        state = {
            "n_restarts": self.n_restarts,
            "seed": self.seed,
            "normalize": self.normalize,
            "noise_bounds": np.array(self.noise_bounds),
            "length_scale_bounds": np.array(self.length_scale_bounds),
            "signal_variance_bounds": np.array(self.signal_variance_bounds),
            "X": self.X_train_.copy(),
            "y": self.y_train_.copy(),
            "lower": self.lower_.copy(),
            "width": self.width_.copy(),
            "y_mean": self.y_mean_,
            "y_std": self.y_std_,
            "theta": self.theta_.copy(),
            "jitter": self.jitter_,
            "alpha": self._alpha.copy(),
            "L_inv": self._L_inv.copy(),
            "log_marginal_likelihood": self.log_marginal_likelihood_value_,
        }
        if self.bounds is not None:
            state["bounds"] = self.bounds.copy()
        return state

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> GaussianProcess:
        """Rebuild a fitted model from `get_state` output (numpy scalars accepted)."""
        gp = cls(
            bounds=state.get("bounds"),
            n_restarts=int(state["n_restarts"]),
            seed=int(state["seed"]),
            noise_bounds=tuple(np.asarray(state["noise_bounds"], dtype=float)),
            length_scale_bounds=tuple(np.asarray(state["length_scale_bounds"], dtype=float)),
            signal_variance_bounds=tuple(np.asarray(state["signal_variance_bounds"], dtype=float)),
            normalize=bool(state["normalize"]),
        )

        def arr(key: str) -> np.ndarray:
            return np.array(state[key], dtype=float)

        gp.X_train_, gp.y_train_ = arr("X"), arr("y")
        gp.lower_, gp.width_ = arr("lower"), arr("width")
        gp.y_mean_, gp.y_std_ = float(state["y_mean"]), float(state["y_std"])
        gp.theta_, gp.jitter_ = arr("theta"), float(state["jitter"])
        gp._alpha, gp._L_inv = arr("alpha"), arr("L_inv")
        gp.log_marginal_likelihood_value_ = float(state["log_marginal_likelihood"])
        n, d = gp.X_train_.shape
        if (
            gp.y_train_.shape != (n,)
            or gp.lower_.shape != (d,)
            or gp.width_.shape != (d,)
            or gp.theta_.shape != (d + 2,)
            or gp._alpha.shape != (n,)
            or gp._L_inv.shape != (n, n)
        ):
            raise ValueError("inconsistent GP state: array shapes do not match X")
        gp._U = (gp.X_train_ - gp.lower_) / gp.width_
        gp._ys = (gp.y_train_ - gp.y_mean_) / gp.y_std_
        gp._finish()
        return gp


class MultiOutputGP:
    """One independent `GaussianProcess` per output column (thesis section 2.5).

    The per-output models share bounds and options; output j is seeded with ``seed + j``.
    Prediction stacks the per-output precomputed arrays, so all outputs of a point cost one
    small set of numpy calls (the real-time surrogate query path).
    """

    def __init__(
        self,
        bounds: Any = None,
        n_restarts: int = 5,
        seed: int = 0,
        noise_bounds: tuple[float, float] = (1e-10, 1e-1),
        length_scale_bounds: tuple[float, float] = (1e-2, 1e2),
        signal_variance_bounds: tuple[float, float] = (1e-2, 1e2),
        normalize: bool = True,
    ):
        self._options = dict(
            bounds=bounds,
            n_restarts=n_restarts,
            noise_bounds=noise_bounds,
            length_scale_bounds=length_scale_bounds,
            signal_variance_bounds=signal_variance_bounds,
            normalize=normalize,
        )
        GaussianProcess(seed=seed, **self._options)  # validate the options now, not at fit
        self.seed = int(seed)
        self.gps: list[GaussianProcess] = []

    @property
    def n_outputs(self) -> int:
        return len(self.gps)

    def fit(self, X: Any, Y: Any, *, warm_start: bool = False, theta: Any = None) -> MultiOutputGP:
        """Fit one GP per column of Y (n, m); warm_start, theta (m, d+2) as in GaussianProcess."""
        Y = np.asarray(Y, dtype=float)
        if Y.ndim != 2:
            raise ValueError(f"Y must be a 2-D array (n, m), got shape {Y.shape}")
        m = Y.shape[1]
        if not (warm_start and len(self.gps) == m):
            self.gps = [GaussianProcess(seed=self.seed + j, **self._options) for j in range(m)]
        thetas = [None] * m if theta is None else np.asarray(theta, dtype=float)
        if theta is not None and (thetas.ndim != 2 or thetas.shape[0] != m):
            raise ValueError(f"theta must have shape ({m}, d + 2), got {thetas.shape}")
        for j, gp in enumerate(self.gps):
            gp.fit(X, Y[:, j], warm_start=warm_start, theta=thetas[j])
        self._predictor = _Predictor(self.gps)
        return self

    def predict(self, X: Any, return_std: bool = False):
        """Posterior means (n, m) at X (n, d), and latent stds (n, m) if return_std."""
        if not self.gps:
            raise RuntimeError("MultiOutputGP is not fitted")
        X = _as_2d(X, self.gps[0].lower_.shape[0])
        if X.shape[0] == 1:
            mean, std = self._predictor.point(X[0], return_std)
            mean = mean[None, :]
            std = std[None, :] if std is not None else None
        else:
            mean, std = self._predictor.batch(X, return_std)
        return (mean, std) if return_std else mean

    def scale_std(self, factors: Any) -> None:
        """Multiply each output's posterior std by its factor (see `GaussianProcess.scale_std`)."""
        for gp, factor in zip(self.gps, np.asarray(factors, dtype=float), strict=True):
            gp.scale_std(float(factor))
        self._predictor = _Predictor(self.gps)

    def predict_rows(self, X: Any, return_std: bool = False):
        """Like `predict`, but each row's mean has the same bits whatever the batch size (see
        `_Predictor.rows`): for simulations whose one-vehicle and many-vehicle runs must agree."""
        if not self.gps:
            raise RuntimeError("MultiOutputGP is not fitted")
        X = _as_2d(X, self.gps[0].lower_.shape[0])
        mean, std = self._predictor.rows(X, return_std)
        return (mean, std) if return_std else mean

    def predict_point(self, x: Any) -> tuple[np.ndarray, np.ndarray]:
        """Means and stds (m,) at one point x (d,), with no input checks: the real-time path."""
        return self._predictor.point(x, True)

    def get_state(self) -> dict[str, Any]:
        """Shared training inputs/outputs plus each output's state without its X/y copies."""
        if not self.gps:
            raise RuntimeError("MultiOutputGP is not fitted")
        outputs = []
        for gp in self.gps:
            s = gp.get_state()
            del s["X"], s["y"]
            outputs.append(s)
        return {
            "X": self.gps[0].X_train_.copy(),
            "Y": np.column_stack([gp.y_train_ for gp in self.gps]),
            "seed": self.seed,
            "outputs": outputs,
        }

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> MultiOutputGP:
        """Rebuild from `get_state` output; predictions are bit-identical, nothing is refitted."""
        X = np.asarray(state["X"], dtype=float)
        Y = np.asarray(state["Y"], dtype=float)
        outputs = state["outputs"]
        if Y.ndim != 2 or Y.shape[1] != len(outputs) or not outputs:
            raise ValueError("inconsistent MultiOutputGP state: Y columns do not match outputs")
        gps = [GaussianProcess.from_state({**s, "X": X, "y": Y[:, j]}) for j, s in enumerate(outputs)]
        first = gps[0]
        model = cls(
            bounds=first.bounds,
            n_restarts=first.n_restarts,
            seed=int(state["seed"]),
            noise_bounds=first.noise_bounds,
            length_scale_bounds=first.length_scale_bounds,
            signal_variance_bounds=first.signal_variance_bounds,
            normalize=first.normalize,
        )
        model.gps = gps
        model._predictor = _Predictor(gps)
        return model
