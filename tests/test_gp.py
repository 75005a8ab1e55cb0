"""Tests of the GP core against scikit-learn and against its own numerical contracts."""

import warnings

import numpy as np
import pytest
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, WhiteKernel
from sklearn.gaussian_process.kernels import ConstantKernel as C

from nearsub.common.learning import gp as gpmod
from nearsub.common.learning.gp import GaussianProcess, MultiOutputGP

BOUNDS = np.array([[-2.0, 3.0], [10.0, 50.0], [0.0, 0.1]])


def _data(seed, n=25, bounds=BOUNDS, noise=0.0):
    rng = np.random.default_rng(seed)
    lo, hi = bounds[:, 0], bounds[:, 1]
    X = lo + (hi - lo) * rng.uniform(size=(n, len(bounds)))
    U = (X - lo) / (hi - lo)
    w = rng.normal(size=len(bounds))
    y = 5.0 + 3.0 * np.sin(3.0 * U @ w) + U[:, 0] ** 2 + noise * rng.normal(size=n)
    return X, y


def _theta(d, seed):
    rng = np.random.default_rng(100 + seed)
    return np.log(np.r_[rng.uniform(0.2, 1.5, d), rng.uniform(0.5, 2.0), 1e-4])


def _sklearn_fixed(gp, X, y):
    """scikit-learn model with the same hyperparameters: raw inputs, so l_orig = l_unit * width.

    Our noise variance is in standardised units, which is exactly sklearn's `alpha` with
    normalize_y=True (population std); `alpha` keeps the noise out of the predicted std.
    """
    kernel = C(gp.signal_variance, "fixed") * RBF(gp.length_scales, "fixed")
    return GaussianProcessRegressor(kernel, alpha=gp.noise_variance, optimizer=None, normalize_y=True).fit(X, y)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("bounds", [BOUNDS, None])
def test_predictions_match_sklearn(seed, bounds):
    X, y = _data(seed)
    gp = GaussianProcess(bounds=bounds).fit(X, y, theta=_theta(3, seed))
    sk = _sklearn_fixed(gp, X, y)
    Xt, _ = _data(seed + 50, n=200)
    mean, std = gp.predict(Xt, return_std=True)
    mean_sk, std_sk = sk.predict(Xt, return_std=True)
    np.testing.assert_allclose(mean, mean_sk, rtol=1e-8)
    np.testing.assert_allclose(std, std_sk, rtol=1e-8)
    m1, s1 = gp.predict(Xt[:1], return_std=True)  # single-row path
    np.testing.assert_allclose(m1, mean_sk[:1], rtol=1e-8)
    np.testing.assert_allclose(s1, std_sk[:1], rtol=1e-8)


def test_multi_output_matches_per_output_sklearn():
    X, y = _data(0)
    Y = np.column_stack([y, np.cos(X[:, 0]) * X[:, 1], X[:, 2] * 1e3])
    thetas = np.stack([_theta(3, j) for j in range(3)])
    model = MultiOutputGP(bounds=BOUNDS).fit(X, Y, theta=thetas)
    Xt, _ = _data(9, n=50)
    mean, std = model.predict(Xt, return_std=True)
    assert mean.shape == std.shape == (50, 3)
    for j, gp in enumerate(model.gps):
        mean_sk, std_sk = _sklearn_fixed(gp, X, Y[:, j]).predict(Xt, return_std=True)
        np.testing.assert_allclose(mean[:, j], mean_sk, rtol=1e-8)
        np.testing.assert_allclose(std[:, j], std_sk, rtol=1e-8)
    m_pt, s_pt = model.predict_point(Xt[3])
    np.testing.assert_allclose(m_pt, mean[3], rtol=1e-10)
    np.testing.assert_allclose(s_pt, std[3], rtol=1e-10)
    m1, s1 = model.predict(Xt[3:4], return_std=True)
    assert np.array_equal(m1[0], m_pt) and np.array_equal(s1[0], s_pt)


@pytest.mark.parametrize("seed", range(5))
def test_fitted_lml_at_least_sklearn(seed):
    """Same parametrisation (unit cube, standardised y, log params), same number of starts."""
    d = 3
    X, y = _data(seed, n=30, bounds=np.array([[0.0, 1.0]] * d), noise=0.01)
    gp = GaussianProcess(bounds=[[0.0, 1.0]] * d, n_restarts=5, seed=seed).fit(X, y)
    kernel = C(1.0, (1e-2, 1e2)) * RBF(np.full(d, 0.5), (1e-2, 1e2)) + WhiteKernel(1e-6, (1e-10, 1e-1))
    sk = GaussianProcessRegressor(kernel, alpha=0.0, normalize_y=True, n_restarts_optimizer=4, random_state=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # sklearn's ConvergenceWarnings at bounds
        sk.fit(X, y)
    # sklearn's theta is [log s2, log l.., log sn2]; ours is [log l.., log s2, log sn2]
    t = sk.kernel_.theta
    ours_at_sk = gp.log_marginal_likelihood(np.r_[t[1 : d + 1], t[0], t[-1]], eval_gradient=False)
    ref = sk.log_marginal_likelihood_value_
    assert ours_at_sk == pytest.approx(ref, rel=1e-9, abs=1e-9)
    assert gp.log_marginal_likelihood_value_ >= ref - 1e-6 * abs(ref)


def test_gradient_matches_finite_differences():
    X, y = _data(4, n=20, noise=0.05)
    gp = GaussianProcess(bounds=BOUNDS).fit(X, y)
    rng = np.random.default_rng(0)
    for _ in range(3):
        theta = np.log(np.r_[rng.uniform(0.1, 2.0, 3), rng.uniform(0.5, 3.0), 1e-3])
        _, grad = gp.log_marginal_likelihood(theta)
        h = 1e-6
        fd = np.array(
            [
                (
                    gp.log_marginal_likelihood(theta + h * e, eval_gradient=False)
                    - gp.log_marginal_likelihood(theta - h * e, eval_gradient=False)
                )
                / (2 * h)
                for e in np.eye(len(theta))
            ]
        )
        np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-6)


def test_unfactorisable_kernel_gives_minus_inf_not_exception():
    X, y = _data(1)
    gp = GaussianProcess(bounds=BOUNDS).fit(X, y)
    lml, grad = gp.log_marginal_likelihood(np.full(5, np.nan))
    assert lml == -np.inf and grad is None
    f, g = gpmod._neg_lml(np.full(5, np.nan), gp._U, gp._ys)
    assert f == np.inf and np.array_equal(g, np.zeros(5))


def test_ill_conditioned_duplicates_fit_and_predict_finite():
    X, y = _data(2, n=15)
    X = np.vstack([X, X, X[:3]])  # exact duplicates ...
    y = np.r_[y, y + 1e-3, y[:3] - 1e-3]  # ... with conflicting outputs
    gp = GaussianProcess(bounds=BOUNDS, noise_bounds=(1e-14, 1e-12), n_restarts=3).fit(X, y)
    assert np.isfinite(gp.log_marginal_likelihood_value_)
    mean, std = gp.predict(np.vstack([X, _data(3, n=20)[0]]), return_std=True)
    assert np.all(np.isfinite(mean)) and np.all(np.isfinite(std)) and np.all(std >= 0)
    # zero noise with duplicates is singular: conditioning must fall back on the jitter ladder
    theta = np.r_[np.log([0.5, 0.5, 0.5, 1.0]), -np.inf]
    gp0 = GaussianProcess(bounds=BOUNDS).fit(X, y, theta=theta)
    assert gp0.jitter_ > 0
    assert np.all(np.isfinite(gp0.predict(X, return_std=True)))


def test_variance_is_clipped_at_zero():
    """At training points of a noiseless GP, s2 - k K^-1 k is ~1e-20, so it rounds to +/- 1e-16.

    Without the clip, sqrt would give NaN with a RuntimeWarning (turned into an error here).
    """
    X, y = _data(5, n=40)
    gp = GaussianProcess(bounds=BOUNDS).fit(X, y, theta=np.r_[np.log([0.5] * 3 + [1.0]), -46])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for _, std in (gp.predict(X, return_std=True), gp.predict(X[:1], return_std=True)):
            assert np.all(std >= 0) and np.all(np.isfinite(std))
        _, std = gp.predict(X, return_std=True)
    assert np.any(std == 0)  # the clip was exercised


def test_std_is_computed_only_when_asked(monkeypatch):
    X, y = _data(6)
    gp = GaussianProcess(bounds=BOUNDS).fit(X, y, theta=_theta(3, 6))
    model = MultiOutputGP(bounds=BOUNDS).fit(X, np.column_stack([y, y**2]))

    def boom(*args):
        raise AssertionError("variance computed although return_std=False")

    monkeypatch.setattr(gpmod._Predictor, "_point_std", boom)
    monkeypatch.setattr(gpmod._Predictor, "_batch_std", boom)
    for m in (gp, model):
        m.predict(X[:1])
        m.predict(X)
        with pytest.raises(AssertionError):
            m.predict(X[:1], return_std=True)
        with pytest.raises(AssertionError):
            m.predict(X, return_std=True)


def test_interpolates_training_data():
    X, y = _data(7, n=30)
    gp = GaussianProcess(bounds=BOUNDS, noise_bounds=(1e-10, 1e-8)).fit(X, y)
    mean, std = gp.predict(X, return_std=True)
    np.testing.assert_allclose(mean, y, atol=1e-4 * np.ptp(y))
    assert np.all(std < 1e-3 * np.std(y))


def test_hyperparameter_attributes_and_warm_start():
    X, y = _data(8, n=30, noise=0.01)
    gp = GaussianProcess(bounds=BOUNDS, n_restarts=3).fit(X, y)
    d = X.shape[1]
    np.testing.assert_allclose(gp.length_scales, gp.length_scales_unit * np.ptp(BOUNDS, axis=1))
    assert gp.signal_variance == pytest.approx(np.exp(gp.theta_[d]))
    assert gp.noise_variance == pytest.approx(np.exp(gp.theta_[d + 1]))
    assert gp.log_marginal_likelihood_value_ == pytest.approx(gp.log_marginal_likelihood(eval_gradient=False))
    # one start, from the previous optimum: a stationary point, so the fit stays there
    lml = gp.log_marginal_likelihood_value_
    gp.n_restarts = 1
    gp.fit(X, y, warm_start=True)
    assert gp.log_marginal_likelihood_value_ >= lml - 1e-9 * abs(lml)
    # refit after one more point
    Xn, yn = _data(9, n=1)
    gp.fit(np.vstack([X, Xn]), np.r_[y, yn], warm_start=True)
    assert np.isfinite(gp.log_marginal_likelihood_value_)


def test_fit_is_deterministic_for_a_seed():
    X, y = _data(10, n=20, noise=0.01)
    a = GaussianProcess(bounds=BOUNDS, seed=3).fit(X, y)
    b = GaussianProcess(bounds=BOUNDS, seed=3).fit(X, y)
    assert np.array_equal(a.theta_, b.theta_)


def test_state_round_trip_is_bit_identical():
    X, y = _data(11, n=30)
    Y = np.column_stack([y, np.sin(X[:, 1]), X[:, 0] * X[:, 2]])
    model = MultiOutputGP(bounds=BOUNDS, n_restarts=2).fit(X, Y)
    Xt, _ = _data(12, n=100)
    mean, std = model.predict(Xt, return_std=True)
    loaded = MultiOutputGP.from_state(model.get_state())
    m2, s2 = loaded.predict(Xt, return_std=True)
    assert np.array_equal(mean, m2) and np.array_equal(std, s2)
    for a, b in zip(model.predict_point(Xt[0]), loaded.predict_point(Xt[0]), strict=True):
        assert np.array_equal(a, b)
    gp = GaussianProcess().fit(X, y)  # data-derived scaling
    gp2 = GaussianProcess.from_state(gp.get_state())
    assert np.array_equal(gp.predict(Xt, return_std=True), gp2.predict(Xt, return_std=True))
    assert gp2.log_marginal_likelihood(eval_gradient=False) == pytest.approx(gp.log_marginal_likelihood_value_)


def test_input_validation():
    X, y = _data(0)
    with pytest.raises(RuntimeError):
        GaussianProcess().predict(X)
    with pytest.raises(ValueError):
        GaussianProcess(bounds=[[1.0, 0.0]])
    with pytest.raises(ValueError):
        GaussianProcess(noise_bounds=(0.0, 1e-3))
    with pytest.raises(ValueError):
        GaussianProcess().fit(X, y[:-1])
    with pytest.raises(ValueError):
        GaussianProcess(bounds=BOUNDS[:2]).fit(X, y)
    gp = GaussianProcess(bounds=BOUNDS).fit(X, y, theta=_theta(3, 0))
    with pytest.raises(ValueError):
        gp.predict(X[:, :2])
    with pytest.raises(ValueError):
        MultiOutputGP().fit(X, y)


def _three_outputs(rng, n: int, wave=np.sin) -> MultiOutputGP:
    """A 3-output GP fitted to wave(X w) on n uniform points in 6 inputs."""
    X = rng.uniform(size=(n, 6))
    return MultiOutputGP(n_restarts=1, seed=0).fit(X, np.column_stack([wave(X @ w) for w in rng.normal(size=(3, 6))]))


def test_rows_give_the_same_bits_alone_and_in_a_batch():
    """A vehicle asking alone and a sweep asking for many get identical means and stds (the
    multi-process run and the batch engine must agree), and they agree with the other paths to
    rounding."""
    rng = np.random.default_rng(3)
    model = _three_outputs(rng, 60)
    Xt = rng.uniform(size=(300, 6))
    together, together_std = model.predict_rows(Xt, return_std=True)
    alone = [model.predict_rows(Xt[i : i + 1], return_std=True) for i in range(len(Xt))]
    assert np.array_equal(together, np.vstack([mean for mean, _ in alone]))
    assert np.array_equal(together_std, np.vstack([std for _, std in alone]))
    assert np.array_equal(together, model.predict_rows(Xt))  # the mean does not depend on the std
    mean, std = model.predict(Xt, return_std=True)
    np.testing.assert_allclose(together, mean, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(together_std, std, rtol=1e-6, atol=1e-9)


def _rows_reference(model: MultiOutputGP, Xt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thesis (2.6) and (2.7) of `predict_rows` in numpy, from the predictor's arrays: the squared
    distances from differences, the whole (n, n) L^-1 in the variance; and the scale of the mean's
    rounding, y_std sum_i |e_i alpha_i| (the sum cancels: its terms are far larger than it)."""
    p = model._predictor
    zb = Xt[None, :, :] * p.A[:, None, :] + p.B[:, None, :]  # (3, a, d)
    sq = np.sum((p.Z[:, None, :, :] - zb[:, :, None, :]) ** 2, axis=-1)  # (3, a, n)
    e = np.exp(-sq)
    mean = (np.sum(e * p.alpha_s[:, None, :], axis=-1)).T * p.y_std + p.y_mean
    v = np.einsum("jni,jai->jan", p.Linv_s, e)  # L^-1 e
    std = (np.sqrt(np.maximum(p.s2[:, None] - np.sum(v * v, axis=-1), 0.0)) * p.y_std[:, None]).T
    return mean, std, np.sum(np.abs(e * p.alpha_s[:, None, :]), axis=-1).T * p.y_std


def test_rows_equal_the_numpy_reference():
    """The compiled rows (`gp_kernel.posterior_rows`: C library exp, packed triangular columns of
    L^-1) against thesis (2.6)-(2.7) in numpy, computed here: equal to a few units in the last
    place: the mean to 1e-14 of the sum of its terms' magnitudes (its 80 terms are summed in
    another order; 1e-14 is about 80 units of the last place), the std to rtol 1e-9 (a difference
    of sums of squares), inside and outside the training box."""
    rng = np.random.default_rng(5)
    model = _three_outputs(rng, 80)
    Xt = rng.uniform(-0.2, 1.2, size=(100, 6))
    mean, std = model.predict_rows(Xt, return_std=True)
    expected_mean, expected_std, scale = _rows_reference(model, Xt)
    assert np.all(np.abs(mean - expected_mean) <= 1e-14 * scale)
    np.testing.assert_allclose(std, expected_std, rtol=1e-9, atol=1e-12)


def test_a_fit_with_all_length_scales_at_a_bound_is_rejected():
    from nearsub.common.learning.gp import DegenerateFitError, all_length_scales_at_bound

    bounds = np.log([[0.01, 100.0], [0.01, 100.0]])
    assert all_length_scales_at_bound(np.log([0.01, 100.0]), bounds)
    assert not all_length_scales_at_bound(np.log([0.01, 0.3]), bounds)
    rng = np.random.default_rng(0)
    X = rng.uniform(size=(15, 2))
    y = np.sin(4 * X[:, 0]) + X[:, 1]
    # Length scales pinned to one value: every optimum has them all at the bound, so every start is
    # rejected, fresh starts are tried, and the fit fails rather than return the degenerate optimum.
    gp = GaussianProcess(n_restarts=3, length_scale_bounds=(0.05, 0.05))
    with pytest.raises(DegenerateFitError, match="all length scales at a bound"):
        gp.fit(X, y)
    assert gp.n_rejected_ == 9  # 3 rounds of 3 starts
    ok = GaussianProcess(n_restarts=3).fit(X, y)
    assert ok.n_rejected_ == 0 and not all_length_scales_at_bound(ok.theta_[:2], np.log([[0.01, 100.0]] * 2))


def test_kernel_matrix_and_stored_lml_agree_with_numpy():
    """The compiled K is exactly symmetric and equals the numpy formula to rounding; the LML a
    fit stores (taken from its conditioning factor) is the one _lml computes afresh."""
    X, y = _data(3, n=40)
    gp = GaussianProcess(bounds=BOUNDS).fit(X, y)
    theta, U = gp.theta_, gp._U
    d = U.shape[1]
    K = gpmod._rbf(theta, U)
    sq = (((U[:, None, :] - U[None, :, :]) ** 2) * np.exp(-2.0 * theta[:d])).sum(axis=2)
    ref = np.exp(theta[d]) * np.exp(-0.5 * sq) + np.exp(theta[d + 1]) * np.eye(len(U))
    assert np.array_equal(K, K.T)
    np.testing.assert_allclose(K, ref, rtol=1e-13, atol=0.0)
    assert gp.log_marginal_likelihood_value_ == gp.log_marginal_likelihood(eval_gradient=False)
