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


def _same_cos(a):
    """The kernels' cos, element by element in Python floats (IEEE double, no FMA): a reference
    for the compiled, vectorised loop."""
    from nearsub.common.surrogate import sampling_kernel

    return np.vectorize(sampling_kernel.cos.py_func, otypes=[float])(a)


def test_per_row_samples_give_the_bits_of_the_numpy_expressions(surrogate):
    """`rows` (compiled, row by row) against the numpy expressions of pathwise conditioning it
    replaced, bit for bit: the data update and the prior features of each row's own sample,
    with the kernels' cos."""
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
            diff = Z[:, i, None] / out.length[i] - out.U[None, :, i] / out.length[i]
            sq += diff * diff
        f = np.sum(out.s2 * np.exp(-0.5 * sq) * out.v[sample], axis=-1)
        proj = out.phase[sample] + Z[:, 0, None] * out.omega_t[sample, 0]
        for i in range(1, Z.shape[1]):
            proj += Z[:, i, None] * out.omega_t[sample, i]
        n_features = out.weights.shape[1]
        f += math.sqrt(2.0 * out.s2 / n_features) * np.sum(_same_cos(proj) * out.weights[sample], axis=-1)
        assert (out.y_mean + out.y_std * f).tobytes() == got[:, j].tobytes(), j
    rng = np.random.default_rng(6)
    for n in [*range(1, 300), 512, 1000, sampling_kernel.PAIRWISE_MAX]:  # numpy's summation order
        a = rng.standard_normal(n) * rng.exponential(1.0, n)
        assert sampling_kernel._pairwise(a, 0, n).hex() == np.sum(a).hex(), n


def _ulps(got, x):
    import math

    want = np.array([math.cos(v) for v in x])
    return np.abs(got - want) / np.spacing(np.abs(want))


def test_the_features_cos_is_within_one_ulp_of_the_c_library():
    """`sampling_kernel.cos` against math.cos: random arguments up to the features' range (a few
    hundred: omega ~ N(0, 1 / l^2) on the unit cube plus the phase) and up to COS_LIMIT, the
    doubles next to k pi / 2 (where the reduction cancels most), zero and tiny ones. The compiled
    loop gives the bits of the Python function (no FMA, no dependence on the position)."""
    from numba import njit

    from nearsub.common.surrogate.sampling_kernel import COS_LIMIT, cos

    @njit
    def each(x, out):
        for i in range(x.shape[0]):
            out[i] = cos(x[i])

    rng = np.random.default_rng(7)
    near = np.arange(1, 20001) * (np.pi / 2)
    edges = [0.0, -0.0, 5e-324, 1e-300, 1e-8, -1e-8, np.pi / 4, -np.pi / 4, COS_LIMIT, -COS_LIMIT]
    x = np.concatenate(
        [
            rng.uniform(-700.0, 700.0, 200_000),
            rng.uniform(-COS_LIMIT, COS_LIMIT, 50_000),
            np.nextafter(near, 0.0),
            near,
            np.nextafter(near, np.inf),
            edges,
        ]
    )
    got = np.empty_like(x)
    each(x, got)
    assert _ulps(got, x).max() <= 1.0
    assert got[:2000].tobytes() == _same_cos(x[:2000]).tobytes()
    assert got[-len(edges) :].tobytes() == _same_cos(edges).tobytes()


def test_prior_rows_take_the_c_library_cos_beyond_the_limit():
    """A row whose arguments may pass COS_LIMIT goes element by element: math.cos beyond the
    limit (and for NaN), the same cos within it; an ordinary row is the vectorised loop."""
    import math

    from nearsub.common.surrogate import sampling_kernel
    from nearsub.common.surrogate.sampling_kernel import COS_LIMIT

    rng = np.random.default_rng(8)
    n_features = 37
    omega_t = rng.standard_normal((2, 2, n_features))
    phase = rng.uniform(0.0, 2.0 * np.pi, (2, n_features))
    weights = rng.standard_normal((2, n_features))
    bound = np.abs(omega_t).max(axis=2)
    Z = np.array([[0.3, 0.7], [COS_LIMIT, 0.2], [np.nan, 0.1]])
    sample = np.array([0, 1, 0])
    out = np.empty(3)
    sampling_kernel.prior_rows(Z, sample, omega_t, phase, weights, 1.0, bound, np.empty(n_features), out)
    for r in range(2):
        arg = phase[sample[r]] + Z[r, 0] * omega_t[sample[r], 0] + Z[r, 1] * omega_t[sample[r], 1]
        cos = [sampling_kernel.cos.py_func(a) if abs(a) <= COS_LIMIT else math.cos(a) for a in arg]
        assert (r == 1) == (np.abs(arg) > COS_LIMIT).any()
        assert out[r] == 0.0 + sampling_kernel._pairwise(np.array(cos) * weights[sample[r]], 0, n_features)
    assert np.isnan(out[2])
