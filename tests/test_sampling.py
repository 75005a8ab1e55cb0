"""Posterior function samples of the residual GP (common/surrogate/sampling.py)."""

import numpy as np
import pytest

from nearsub.common.hydro import low_fidelity as hydro_lf
from nearsub.common.surrogate.domain import sample_feasible
from nearsub.common.surrogate.model import analytic_model, load_surrogate
from nearsub.common.surrogate.modelfile import LFInLoopModel
from nearsub.common.surrogate.sampling import draw_samples
from nearsub.common.surrogate.warping import DEFAULT_WARPING, Warping

K = 300  # samples in the statistical test
FEATURES = 256  # the mean and covariance are exact for any D (fresh frequencies per sample)


@pytest.fixture(scope="module")
def surrogate():
    return load_surrogate()


def _posterior_covariance(gp, W):
    """k(W, W) - k(W, U) K^-1 k(U, W) of one output GP, in output units (R&W (2.24))."""
    d = gp.lower_.shape[0]
    length, s2, sn2 = np.exp(gp.theta_[:d]), np.exp(gp.theta_[d]), np.exp(gp.theta_[d + 1])

    def k(A, B):
        diff = ((A - gp.lower_) / gp.width_)[:, None, :] - ((B - gp.lower_) / gp.width_)[None, :, :]
        return s2 * np.exp(-0.5 * np.sum((diff / length) ** 2, axis=2))

    U = gp.X_train_
    Kuu = k(U, U) + (sn2 + gp.jitter_) * np.eye(len(U))
    Kwu = k(W, U)
    return gp.y_std_**2 * (k(W, W) - Kwu @ np.linalg.solve(Kuu, Kwu.T))


def test_samples_match_the_gp_posterior(surrogate):
    """Mean and covariance of K samples at 6 points (5 feasible, 1 training point) against the
    residual GP's posterior, per output. Tolerances from K: the sample mean has standard error
    sigma / sqrt(K), a sample covariance sqrt((S_ii S_jj + S_ij^2) / K) (Gaussian samples, which
    D = 256 features nearly are); every entry must lie within 5 standard errors (fixed seed; a
    chance failure of one of the 81 entries has probability below 1e-4)."""
    model = surrogate.model
    X = np.vstack([sample_feasible(5, seed=11), model.X[:1]])
    samples = draw_samples(surrogate, K, seed=5, n_features=FEATURES).delta(X)
    assert samples.shape == (K, 6, 3)
    mean, std = surrogate.discrepancy(X)
    assert np.all(np.abs(samples.mean(axis=0) - mean) <= 5.0 * std / np.sqrt(K))
    W = model.warping.forward(X)
    for j, gp in enumerate(model.delta.gps):
        S = _posterior_covariance(gp, W)
        np.testing.assert_allclose(np.sqrt(np.diag(S)), std[:, j], rtol=1e-6)  # same posterior
        C = np.cov(samples[:, :, j], rowvar=False)
        se = np.sqrt((np.outer(np.diag(S), np.diag(S)) + S**2) / K)
        assert np.all(np.abs(C - S) <= 5.0 * se), (j, (C - S) / se)


def test_a_sample_is_one_function_along_a_trajectory(surrogate):
    """Consistent samples: sample i gives the same value at the same point whatever else is
    asked with it, and per-sample inputs (K, n, 6) agree with shared ones (n, 6)."""
    s = draw_samples(surrogate, 4, seed=1, n_features=64)
    X = sample_feasible(7, seed=2)
    shared = s.delta(X)
    np.testing.assert_allclose(s.delta(X[3:5])[:, 1], shared[:, 4], rtol=1e-9, atol=1e-15)
    own = s.delta(np.broadcast_to(X, (4, 7, 6)))
    np.testing.assert_allclose(own, shared, rtol=1e-9, atol=1e-15)
    mixed = np.stack([X[[i, 0]] for i in range(4)])  # sample i at point i and point 0
    out = s.delta(mixed)
    np.testing.assert_allclose(out[:, 0], shared[np.arange(4), np.arange(4)], rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(out[:, 1], shared[:, 0], rtol=1e-9, atol=1e-15)
    np.testing.assert_array_equal(draw_samples(surrogate, 4, seed=1, n_features=64).delta(X), shared)
    assert not np.allclose(draw_samples(surrogate, 4, seed=2, n_features=64).delta(X), shared)


def test_any_lf_in_loop_model_and_bad_requests():
    """A small model fitted here (other hyperparameters than the shipped one): samples at its
    training points sit within the posterior's small spread of the data."""
    X = sample_feasible(25, seed=4)
    residual = 1e-4 * np.column_stack([np.sin(3 * X[:, 0]), X[:, 1], np.cos(X[:, 3])])
    model = LFInLoopModel.fit(X, hydro_lf.lf_coefficients(X) + residual, Warping(DEFAULT_WARPING), n_restarts=1, seed=0)
    at_data = draw_samples(model, 8, seed=0, n_features=64).delta(X)
    std = model.discrepancy(X, return_std=True)[1]
    assert np.all(np.abs(at_data - residual) <= 6.0 * std + 1e-9)
    with pytest.raises(TypeError, match="lf_in_loop"):
        draw_samples(analytic_model().model, 2)
    with pytest.raises(ValueError, match=r"\(3, n, 6\)"):
        draw_samples(model, 3, n_features=8).delta(np.zeros((2, 4, 6)))


def test_per_row_samples_give_the_bits_of_the_numpy_expressions(surrogate):
    """`rows` (compiled, row by row) against the numpy expressions of pathwise conditioning it
    replaced, bit for bit: the data update and the prior features of each row's own sample."""
    import math

    from nearsub.common.surrogate import sampling_kernel

    samples = draw_samples(surrogate, 5, seed=3)
    X = sample_feasible(40, seed=4)
    sample = np.random.default_rng(5).integers(0, 5, len(X))
    W = surrogate.model.warping.forward(X)
    got = samples.rows(X, sample)
    for j, out in enumerate(samples._outputs):
        Z = (W - out.lower) / out.width
        sq = np.zeros((len(Z), len(out.U)))
        for i in range(Z.shape[1]):
            diff = (Z[:, i, None] - out.U[None, :, i]) / out.length[i]
            sq += diff * diff
        f = np.sum(out.s2 * np.exp(-0.5 * sq) * out.v[sample], axis=-1)
        proj = out.phase[sample] + Z[:, 0, None] * out.omega_t[sample, 0]
        for i in range(1, Z.shape[1]):
            proj += Z[:, i, None] * out.omega_t[sample, i]
        n_features = out.weights.shape[1]
        f += math.sqrt(2.0 * out.s2 / n_features) * np.sum(np.cos(proj) * out.weights[sample], axis=-1)
        assert (out.y_mean + out.y_std * f).tobytes() == got[:, j].tobytes(), j
    rng = np.random.default_rng(6)
    for n in [*range(1, 300), 512, 1000, sampling_kernel.PAIRWISE_MAX]:  # numpy's summation order
        a = rng.standard_normal(n) * rng.exponential(1.0, n)
        assert sampling_kernel._pairwise(a, 0, n).hex() == np.sum(a).hex(), n
