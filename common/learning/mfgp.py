"""Two-fidelity Gaussian-process model: Kennedy-O'Hagan AR(1) with rho fixed to 1 (thesis 2.2.4).

f_HF(x) = rho f_LF(x) + delta(x) (2.10), rho = 1 as in the thesis. Fitted in two steps, as three
independent GPs from `nearsub.common.learning.gp` (no joint likelihood, so each fit stays small):

* LF GP on D_LF (2.13),
* delta GP on the residuals y_delta = y_HF - y_LF at the HF points (2.14, 2.15),
* HF-only GP on D_HF (2.12), used by the inter-model acquisition (2.17) and as a baseline.

Prediction (2.11): y_MF = y_LF + y_delta and sigma_MF = sigma_delta (the LF uncertainty is
ignored, as in the thesis). The fidelities stay separate datasets; (2.15) needs an LF run at
every HF point, which is looked up by exact row match. With an exact LF (`lf=`, a cheap
LF function "in the loop") the LF GP is that function itself: y_MF = rho LF(x) + y_delta, and
no LF data are needed. Learning rho (least squares of y_HF on y_LF at the HF points) is an
ablation only: with the affine LFs of Park and Borehole it makes
delta nearly constant and trivialises the benchmark (in both, Q_LF is an affine function of Q_HF:
Park's LF is 1.2 HF - 1 exactly, Borehole's (Xiong, Qian & Wu 2013) is 0.796 HF to 0.1 %).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from nearsub.common.learning.gp import MultiOutputGP

__all__ = ["ExactLF", "MultiFidelityGP", "lf_at_points", "model_thetas"]

# Seed offsets so the three GPs draw different random restarts from one model seed.
_SEED_OFFSETS = {"lf": 0, "delta": 1000, "hf": 2000}


def _as_columns(Y: Any, n: int) -> np.ndarray:
    Y = np.asarray(Y, dtype=float)
    Y = Y[:, None] if Y.ndim == 1 else Y
    if Y.ndim != 2 or Y.shape[0] != n:
        raise ValueError(f"outputs must have shape ({n},) or ({n}, m), got {Y.shape}")
    return Y


def lf_at_points(X_lf: np.ndarray, Y_lf: np.ndarray, X: np.ndarray) -> np.ndarray:
    """LF outputs at the rows of X, found by exact match in D_LF (needed by (2.15))."""
    index = {row.tobytes(): i for i, row in enumerate(np.ascontiguousarray(X_lf))}
    rows = []
    for x in np.ascontiguousarray(X):
        i = index.get(x.tobytes())
        if i is None:
            raise ValueError(f"no LF run at HF point {x}: D_HF must be a subset of D_LF (2.15)")
        rows.append(i)
    return Y_lf[rows]


class ExactLF:
    """The LF function standing in for the LF GP: exact, so its std is zero."""

    def __init__(self, function: Callable[[np.ndarray], np.ndarray]):
        self.function = function

    def predict(self, X: Any, return_std: bool = False):
        X = np.atleast_2d(np.asarray(X, dtype=float))
        Y = _as_columns(self.function(X), len(X))
        return (Y, np.zeros_like(Y)) if return_std else Y


class MultiFidelityGP:
    """LF, delta and HF-only GPs over one input domain; see the module docstring.

    bounds: (d, 2) known design domain (fixed input scaling across active-learning steps).
    n_restarts, seed: per-GP optimiser starts and seed, as in `GaussianProcess`.
    rho: the AR(1) scale, 1.0 in the thesis; None learns it per output (ablation).
    lf: the exact LF function X (n, d) -> (n, m), used instead of an LF GP (LF data ignored).
    """

    def __init__(
        self,
        bounds: Any,
        *,
        n_restarts: int = 3,
        seed: int = 0,
        rho: float | None = 1.0,
        lf: Callable[[np.ndarray], np.ndarray] | None = None,
    ):
        self.bounds = np.asarray(bounds, dtype=float)
        self.n_restarts = int(n_restarts)
        self.seed = int(seed)
        self.rho = rho
        self.lf = self._new_gp("lf") if lf is None else ExactLF(lf)
        self.delta = self._new_gp("delta")
        self.hf = self._new_gp("hf")
        self.rho_: np.ndarray | None = None

    def _new_gp(self, role: str) -> MultiOutputGP:
        return MultiOutputGP(bounds=self.bounds, n_restarts=self.n_restarts, seed=self.seed + _SEED_OFFSETS[role])

    def fit(
        self,
        X_lf: Any,
        Y_lf: Any,
        X_hf: Any,
        Y_hf: Any,
        *,
        warm_start: bool = False,
        thetas: dict[str, Any] | None = None,
    ) -> MultiFidelityGP:
        """Fit the three GPs; Y (n,) or (n, m). thetas {"lf","delta","hf"}: condition only."""
        X_hf = np.asarray(X_hf, dtype=float)
        Y_hf = _as_columns(Y_hf, X_hf.shape[0])
        thetas = thetas or {}
        if self.exact_lf:
            lf_hf = self.lf.predict(X_hf)
        else:
            X_lf = np.asarray(X_lf, dtype=float)
            Y_lf = _as_columns(Y_lf, X_lf.shape[0])
            lf_hf = lf_at_points(X_lf, Y_lf, X_hf)
            self.lf.fit(X_lf, Y_lf, warm_start=warm_start, theta=thetas.get("lf"))
        if self.rho is None:
            self.rho_ = np.array([_slope(lf_hf[:, j], Y_hf[:, j]) for j in range(Y_hf.shape[1])])
        else:
            self.rho_ = np.full(Y_hf.shape[1], float(self.rho))
        self.delta.fit(  # (2.15) with rho
            X_hf, Y_hf - self.rho_ * lf_hf, warm_start=warm_start, theta=thetas.get("delta")
        )
        self.hf.fit(X_hf, Y_hf, warm_start=warm_start, theta=thetas.get("hf"))
        return self

    @property
    def exact_lf(self) -> bool:
        return isinstance(self.lf, ExactLF)

    @property
    def thetas(self) -> dict[str, np.ndarray]:
        """Log hyperparameters (m, d + 2) of each GP: enough to rebuild the fit from the data."""
        roles = [r for r in _SEED_OFFSETS if not (r == "lf" and self.exact_lf)]
        return {role: model_thetas(getattr(self, role)) for role in roles}

    def condition_lf(self, X_extra: Any, Y_extra: Any) -> MultiFidelityGP:
        """A copy whose LF GP also holds (X_extra, Y_extra), at fixed hyperparameters.

        This is Algorithm 1's temporary augmentation of D_LF: the look-ahead points move y_LF and
        so y_MF, but the model they came from (and its warm-start state) is left untouched.
        """
        if self.exact_lf:
            raise ValueError("an exact LF needs no look-ahead: it is known everywhere")
        lf = self.lf.gps[0]
        X = np.vstack([lf.X_train_, np.asarray(X_extra, dtype=float)])
        Y_base = np.column_stack([gp.y_train_ for gp in self.lf.gps])
        Y = np.vstack([Y_base, _as_columns(Y_extra, len(X) - len(Y_base))])
        copy = object.__new__(MultiFidelityGP)
        copy.__dict__.update(self.__dict__)
        copy.lf = self._new_gp("lf").fit(X, Y, theta=model_thetas(self.lf))
        return copy

    def predict(self, X: Any, return_std: bool = False):
        """y_MF = rho y_LF + y_delta (2.11), and sigma_MF = sigma_delta (2.14) if return_std."""
        y_lf = self.lf.predict(X)
        if return_std:
            y_delta, s_delta = self.delta.predict(X, return_std=True)
            return self.rho_ * y_lf + y_delta, s_delta
        return self.rho_ * y_lf + self.delta.predict(X)

    def inter_model_gap(self, X: Any) -> np.ndarray:
        """|y_HF - y_MF| (n, m): the absolute-difference acquisition q_AD (2.17) per output."""
        return np.abs(self.hf.predict(X) - self.predict(X))


def model_thetas(model: MultiOutputGP) -> np.ndarray:
    """Log hyperparameters (m, d + 2) of a fitted MultiOutputGP, one row per output."""
    return np.array([gp.theta_ for gp in model.gps])


def _slope(x: np.ndarray, y: np.ndarray) -> float:
    """Least-squares slope of y on x (with intercept): the learned-rho ablation."""
    xc = x - x.mean()
    denom = float(xc @ xc)
    return float(xc @ (y - y.mean()) / denom) if denom > 0.0 else 1.0
