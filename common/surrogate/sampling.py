"""Posterior function samples of the surrogate's residual GP, consistent along a trajectory.

A sample is one plausible residual field delta(x) (HF - LF, thesis (2.14) with the exact LF in
the loop), a whole function: evaluated at every step and every vehicle of a run it stays the
same field, so K samples give K plausible runs (an envelope's spread), not independent noise
per query. Only a model of kind "lf_in_loop" (`modelfile.LFInLoopModel`) has them: its
prediction is LF(x) + delta(x), and the LF is exact, so all the uncertainty is in delta.

Pathwise conditioning (Wilson et al. 2020, "Efficiently sampling functions from Gaussian
process posteriors", ICML, eq. 13): per output GP and sample,

    f(u) = f_prior(u) + k(u, U) K^-1 (y - f_prior(U) - eps),   eps ~ N(0, sn2 I),

with K = k(U, U) + sn2 I the training covariance (plus the fit's jitter), u the warped input
on the GP's unit cube and y the standardised residuals. The prior sample uses random Fourier
features (Rahimi & Recht 2007): the GP's kernel s2 exp(-|u - u'|^2_l / 2) (ARD RBF, thesis
(2.5)) has the spectral density N(0, diag(1 / l^2)), so

    f_prior(u) = sqrt(2 s2 / D) sum_i w_i cos(omega_i . u + b_i),
    omega_i ~ N(0, diag(1 / l^2)), b_i ~ U(0, 2 pi), w_i ~ N(0, 1).

Every sample draws its own frequencies, so over samples the prior covariance is exactly the
kernel, and since the update is linear the samples' mean and covariance are exactly the GP
posterior's (a finite D only makes each sample slightly non-Gaussian). The data update is exact
at the training points. Samples are of the latent function (as the GP's std is).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.linalg import cho_factor, cho_solve

__all__ = ["DEFAULT_FEATURES", "PosteriorSamples", "draw_samples"]

DEFAULT_FEATURES = 256  # random Fourier features per sample and output (the moments are exact at any count)
_BLOCK = 1 << 16  # (rows x training points) elements per block: bounds the temporaries, in cache


class _OutputSamples:
    """K pathwise samples of one output's GP (standardised units, unit-cube inputs)."""

    def __init__(self, gp, k: int, n_features: int, rng: np.random.Generator):
        d = gp.lower_.shape[0]
        theta = np.asarray(gp.theta_, dtype=float)
        self.length = np.exp(theta[:d])
        self.s2, sn2 = math.exp(theta[d]), math.exp(theta[d + 1])
        self.lower, self.width = gp.lower_, gp.width_
        self.y_mean, self.y_std = gp.y_mean_, gp.y_std_
        self.U = (gp.X_train_ - gp.lower_) / gp.width_
        # The inputs over the length scales: a row divides its d inputs, not its d x n differences.
        self.U_scaled_t = np.ascontiguousarray((self.U / self.length).T)  # (d, n_train)
        n = len(self.U)
        if max(n, n_features) > _kernels().PAIRWISE_MAX:
            raise ValueError(f"at most {_kernels().PAIRWISE_MAX} training points and features, got {n}, {n_features}")
        K = self._kernel(self.U) + (sn2 + getattr(gp, "jitter_", 0.0)) * np.eye(n)
        omega = rng.standard_normal((k, n_features, d)) / self.length  # spectral density draws
        self.omega_t = np.ascontiguousarray(omega.transpose(0, 2, 1))  # (k, d, f)
        self.bound = np.abs(self.omega_t).max(axis=2)  # (k, d): bounds the cosines' arguments
        self.phase = rng.uniform(0.0, 2.0 * math.pi, (k, n_features))
        self.weights = rng.standard_normal((k, n_features))
        ys = (gp.y_train_ - gp.y_mean_) / gp.y_std_
        eps = math.sqrt(sn2) * rng.standard_normal((k, n))
        every = np.repeat(np.arange(k), n)
        residual = ys[None, :] - self._prior(every, np.tile(self.U, (k, 1))).reshape(k, n) - eps
        # (k, n): K^-1 (y - f(U) - eps)
        self.v = np.ascontiguousarray(cho_solve(cho_factor(K, lower=True), residual.T).T)

    def _kernel(self, Z: np.ndarray) -> np.ndarray:
        """s2 exp(-|z - u_i|^2_l / 2) for Z (n, d) against the training inputs: (n, n_train)."""
        sq = np.zeros((len(Z), self.U_scaled_t.shape[1]))
        for j in range(Z.shape[1]):
            diff = Z[:, j, None] / self.length[j] - self.U_scaled_t[None, j]
            sq += diff * diff
        return self.s2 * np.exp(-0.5 * sq)

    def _prior(self, sample: np.ndarray, Z: np.ndarray) -> np.ndarray:
        """Prior sample sample[r] at row Z[r] (n, d): (n,). Row by row (`sampling_kernel`), so a
        row's value does not depend on which other rows are asked with it (a batch split over
        workers gets the same bits)."""
        n_features = self.weights.shape[1]
        out = np.empty(len(Z))
        scale = math.sqrt(2.0 * self.s2 / n_features)
        scratch = np.empty(n_features)
        Z = np.ascontiguousarray(Z)
        _kernels().prior_rows(Z, sample, self.omega_t, self.phase, self.weights, scale, self.bound, scratch, out)
        return out

    def __call__(self, W: np.ndarray, sample: np.ndarray | None = None) -> np.ndarray:
        """Warped inputs W (n, d), in output units: every sample at every row (k, n) without
        `sample`, else sample `sample[r]` at row r (n,)."""
        Z = (W - self.lower) / self.width
        if sample is None:
            kernel = self._kernel(Z)  # one kernel matrix serves every sample
            every = np.repeat(np.arange(len(self.v)), len(Z))
            f = self._prior(every, np.tile(Z, (len(self.v), 1))).reshape(len(self.v), -1) + (kernel @ self.v.T).T
        else:
            f = self._update(np.asarray(sample, dtype=np.int64), Z)
            f += self._prior(np.asarray(sample, dtype=np.int64), Z)
        return self.y_mean + self.y_std * f

    def _update(self, sample: np.ndarray, Z: np.ndarray) -> np.ndarray:
        """k(z_r, U) v[sample[r]] (n,), row by row, in blocks of rows that bound the temporaries;
        the exponential is numpy's (`sampling_kernel`)."""
        kernels = _kernels()
        Z = np.ascontiguousarray(Z)
        out = np.empty(len(Z))
        scratch = np.empty(len(self.U))
        rows = max(1, _BLOCK // len(self.U))
        for start in range(0, len(Z), rows):
            block = slice(start, start + rows)
            exponent = np.empty((len(Z[block]), len(self.U)))
            kernels.kernel_exponents(Z[block], self.U_scaled_t, self.length, exponent)
            np.exp(exponent, out=exponent)
            kernels.update_rows(exponent, self.s2, sample[block], self.v, scratch, out[block])
        return out


def _kernels():
    """The compiled kernels (`sampling_kernel`), imported on first use."""
    from nearsub.common.surrogate import sampling_kernel

    return sampling_kernel


class PosteriorSamples:
    """K posterior function samples of delta, the residual GP of an "lf_in_loop" model.

    Draw with `draw_samples`; `delta(X)` evaluates all K samples at once.
    """

    def __init__(self, model: Any, k: int, seed: Any = 0, n_features: int = DEFAULT_FEATURES):
        if k < 1 or n_features < 1:
            raise ValueError(f"need k >= 1 samples and n_features >= 1, got k={k}, n_features={n_features}")
        self.model = model
        self.k = int(k)
        rng = np.random.default_rng(seed)
        self._outputs = [_OutputSamples(gp, self.k, n_features, rng) for gp in model.delta.gps]

    def delta(self, X: Any) -> np.ndarray:
        """The K samples of delta [X', Y', N'] (K, n, 3) at raw surrogate inputs X.

        X (n, 6): every sample at the same points. X (K, n, 6): sample i at its own points X[i]
        (one set of vehicles per sample, as a batch run with K sampled force fields has: the
        trajectories differ). The model's input warping is applied first, as in its prediction.
        """
        X = np.asarray(X, dtype=float)
        if X.ndim not in (2, 3) or X.shape[-1] != 6 or (X.ndim == 3 and X.shape[0] != self.k):
            raise ValueError(f"inputs must be (n, 6) or ({self.k}, n, 6), got {X.shape}")
        W = self.model.warping.forward(X.reshape(-1, 6))
        if X.ndim == 2:
            return np.stack([f(W) for f in self._outputs], axis=-1)
        sample = np.repeat(np.arange(self.k), X.shape[1])
        return self.rows(X.reshape(-1, 6), sample).reshape(X.shape[:2] + (3,))

    def rows(self, X: Any, sample: Any) -> np.ndarray:
        """delta [X', Y', N'] (n, 3) of sample `sample[r]` at raw input row X[r] (n, 6): a batch of
        UUVs, each flying in its own sampled field (the batch engine's `delta`). A row's value
        does not depend on the other rows."""
        X, sample = np.asarray(X, dtype=float), np.asarray(sample, dtype=int)
        W = self.model.warping.forward(X)
        return np.stack([f(W, sample) for f in self._outputs], axis=-1)


def draw_samples(model: Any, k: int, seed: Any = 0, n_features: int = DEFAULT_FEATURES) -> PosteriorSamples:
    """K posterior function samples of the residual GP of `model` (a `Surrogate` or an
    `LFInLoopModel` of kind "lf_in_loop"); the same seed gives the same samples.

    For a batch engine: draw once per run, then per step call `samples.rows(X, sample)` with the
    inputs of the UUVs flying and the sample of each, where the mean delta would be used."""
    inner = getattr(model, "model", model)
    if getattr(inner, "kind", None) != "lf_in_loop":
        raise TypeError(f"posterior samples need a model of kind 'lf_in_loop', got {getattr(inner, 'kind', None)!r}")
    return PosteriorSamples(inner, k, seed, n_features)
