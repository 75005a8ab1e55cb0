"""The two-step Kennedy-O'Hagan model (2.10)-(2.15) and its properties on the affine benchmarks."""

import numpy as np
import pytest

from nearsub.common.learning.active import initial_design
from nearsub.common.learning.gp import MultiOutputGP
from nearsub.common.learning.mfgp import MultiFidelityGP
from nearsub.common.learning.testproblems import get_problem

PARK = get_problem("park")


def _designs(n_lf, n_hf, seed=0):
    X_lf = initial_design(PARK, n_lf, [seed, 0])
    return X_lf, PARK.lf(X_lf), X_lf[:n_hf], PARK.hf(X_lf[:n_hf])


def _test_set(n=500):
    X = np.random.default_rng(9).uniform(size=(n, 4))
    return X, PARK.hf(X)


def test_prediction_is_lf_plus_delta_and_std_is_delta_std():
    X_lf, Y_lf, X_hf, Y_hf = _designs(20, 6)
    mf = MultiFidelityGP(PARK.bounds, n_restarts=2).fit(X_lf, Y_lf, X_hf, Y_hf)
    # (2.15): delta is trained on y_HF - y_LF at the HF points
    np.testing.assert_array_equal(mf.delta.gps[0].y_train_, (Y_hf - Y_lf[:6])[:, 0])
    X, _ = _test_set(50)
    mean, std = mf.predict(X, return_std=True)
    d_mean, d_std = mf.delta.predict(X, return_std=True)
    np.testing.assert_array_equal(mean, mf.lf.predict(X) + d_mean)  # (2.11)
    np.testing.assert_array_equal(std, d_std)  # sigma_MF = sigma_delta
    gap = mf.inter_model_gap(X)  # q_AD (2.17)
    np.testing.assert_allclose(gap, np.abs(mf.hf.predict(X) - mean))


def test_extra_lf_data_beats_hf_only():
    X_lf, Y_lf, X_hf, Y_hf = _designs(40, 8)
    mf = MultiFidelityGP(PARK.bounds, n_restarts=2).fit(X_lf, Y_lf, X_hf, Y_hf)
    X, Y = _test_set()
    err_mf = np.mean(np.abs(mf.predict(X) - Y) / Y)
    err_hf = np.mean(np.abs(mf.hf.predict(X) - Y) / Y)
    assert err_mf < 0.5 * err_hf


def test_nested_equal_designs_make_mf_equal_hf_only_on_park():
    """With X_LF = X_HF and LF = 1.2 HF - 1, the standardised LF and delta data are +/- the HF
    data, so (one deterministic start) all GPs share hyperparameters and y_MF = y_HF exactly:
    extra LF points are what makes the MF model better on Park."""
    X_lf, Y_lf, X_hf, Y_hf = _designs(8, 8)
    mf = MultiFidelityGP(PARK.bounds, n_restarts=1).fit(X_lf, Y_lf, X_hf, Y_hf)
    X, _ = _test_set(200)
    np.testing.assert_allclose(mf.predict(X), mf.hf.predict(X), rtol=1e-7, atol=1e-9)


def test_hf_points_need_lf_runs():
    X_lf, Y_lf, _, _ = _designs(10, 3)
    X_hf = np.full((1, 4), 0.123)
    with pytest.raises(ValueError, match="no LF run"):
        MultiFidelityGP(PARK.bounds).fit(X_lf, Y_lf, X_hf, PARK.hf(X_hf))


def test_condition_lf_is_temporary_and_interpolates():
    X_lf, Y_lf, X_hf, Y_hf = _designs(12, 5)
    mf = MultiFidelityGP(PARK.bounds, n_restarts=1).fit(X_lf, Y_lf, X_hf, Y_hf)
    X_new = np.random.default_rng(3).uniform(size=(4, 4))
    before = mf.predict(X_new)
    look = mf.condition_lf(X_new, PARK.lf(X_new))
    np.testing.assert_allclose(look.lf.predict(X_new), PARK.lf(X_new), rtol=1e-4)
    np.testing.assert_array_equal(mf.predict(X_new), before)  # the original is untouched
    assert len(mf.lf.gps[0].y_train_) == 12
    np.testing.assert_array_equal(look.lf.gps[0].theta_, mf.lf.gps[0].theta_)  # fixed theta


def test_learned_rho_recovers_park_scale():
    X_lf, Y_lf, X_hf, Y_hf = _designs(15, 6)
    mf = MultiFidelityGP(PARK.bounds, rho=None).fit(X_lf, Y_lf, X_hf, Y_hf)
    assert mf.rho_[0] == pytest.approx(1 / 1.2, rel=1e-10)  # HF = (LF + 1) / 1.2


def test_thetas_rebuild_the_fit_bit_for_bit():
    X_lf, Y_lf, X_hf, Y_hf = _designs(15, 6)
    mf = MultiFidelityGP(PARK.bounds, n_restarts=2, seed=4).fit(X_lf, Y_lf, X_hf, Y_hf)
    again = MultiFidelityGP(PARK.bounds, seed=4).fit(X_lf, Y_lf, X_hf, Y_hf, thetas=mf.thetas)
    X, _ = _test_set(100)
    np.testing.assert_array_equal(again.predict(X, True)[0], mf.predict(X, True)[0])
    np.testing.assert_array_equal(again.predict(X, True)[1], mf.predict(X, True)[1])
    np.testing.assert_array_equal(again.hf.predict(X), mf.hf.predict(X))


def test_multi_output_data():
    p = get_problem("multi-output")
    X = initial_design(p, 12, [0, 0])
    Y = p.hf(X)
    # Treat output 0 + 1 as a fake LF to exercise the (n, m) path with m = 3.
    mf = MultiFidelityGP(p.bounds, n_restarts=1).fit(X, Y + 1.0, X[:5], Y[:5])
    assert mf.predict(X[:3]).shape == (3, 3)
    assert isinstance(mf.hf, MultiOutputGP) and mf.hf.n_outputs == 3
