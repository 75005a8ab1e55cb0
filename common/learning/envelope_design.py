"""The acquisition of the envelope design: where one more HF sample most reduces the doubt about
the outcome classes of an envelope's cells (docs/hydro/envelope-design.md has the derivation).

Given, for each doubtful cell c, its weight G_c (the Gini impurity of its outcome under the
posterior samples: 2 P (1 - P) for two classes) and the points z its trajectories ask the residual
GP about, the value of an HF sample at the candidate x* is

    a(x*) = sum_c G_c rho_c(x*),
    rho_c(x*) = (1 / m) sum_i [sum_{z in c} cov_i(z, x*)^2 / (var_i(x*) + sn2_i)] / [sum_{z in c} var_i(z)],

the share of the posterior variance of output i of delta along cell c's trajectories that an
observation at x* removes (thesis (2.9)'s variance, conditioned on one more point; m outputs,
each scale-free as (2.31) asks). A batch is greedy: after each pick the GP is conditioned on it
at fixed hyperparameters (the variance does not depend on the value observed) and each G_c
shrinks by (1 - rho_c) of the pick. Plain numpy on a fitted `gp.MultiOutputGP`; no hydrodynamics.
"""

from __future__ import annotations

import math

import numpy as np

from nearsub.common.learning.gp import GaussianProcess, MultiOutputGP


def condition_on_mean(model: MultiOutputGP, W: np.ndarray) -> MultiOutputGP:
    """`model` conditioned at its own hyperparameters on extra inputs W (k, d), with its posterior
    mean there as the placeholder value: the posterior variance of the look-ahead (it does not
    depend on the values)."""
    thetas = np.stack([gp.theta_ for gp in model.gps])
    X = np.vstack([model.gps[0].X_train_, W])
    Y = np.vstack([np.column_stack([gp.y_train_ for gp in model.gps]), model.predict(W)])
    return MultiOutputGP(bounds=model.gps[0].bounds, seed=model.seed).fit(X, Y, theta=thetas)


def _kernel(gp: GaussianProcess, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The fitted ARD RBF kernel (thesis (2.5)) between unit-cube inputs A (a, d) and B (b, d)."""
    d = A.shape[1]
    sq = np.zeros((len(A), len(B)))
    for j, length in enumerate(np.exp(gp.theta_[:d])):  # one dimension at a time: no (a, b, d) temporary
        diff = (A[:, j, None] - B[None, :, j]) / length
        sq += diff * diff
    return math.exp(gp.theta_[d]) * np.exp(-0.5 * sq)


def posterior_covariance(gp: GaussianProcess, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Latent posterior covariance (a, b) between GP inputs A and B, in standardised output units."""
    scale = lambda X: (X - gp.lower_) / gp.width_  # noqa: E731
    U, A, B = scale(gp.X_train_), scale(A), scale(B)
    d = U.shape[1]
    K = _kernel(gp, U, U) + (math.exp(gp.theta_[d + 1]) + getattr(gp, "jitter_", 0.0)) * np.eye(len(U))
    L = np.linalg.cholesky(K)
    left = np.linalg.solve(L, _kernel(gp, U, A))
    right = np.linalg.solve(L, _kernel(gp, U, B))
    return _kernel(gp, A, B) - left.T @ right


def posterior_variance(gp: GaussianProcess, A: np.ndarray) -> np.ndarray:
    """Latent posterior variance (a,) at GP inputs A, in standardised output units."""
    scale = lambda X: (X - gp.lower_) / gp.width_  # noqa: E731
    U, Z = scale(gp.X_train_), scale(A)
    d = U.shape[1]
    K = _kernel(gp, U, U) + (math.exp(gp.theta_[d + 1]) + getattr(gp, "jitter_", 0.0)) * np.eye(len(U))
    left = np.linalg.solve(np.linalg.cholesky(K), _kernel(gp, U, Z))
    return np.maximum(math.exp(gp.theta_[d]) - np.sum(left * left, axis=0), 0.0)


def explained_shares(
    model: MultiOutputGP, candidates: np.ndarray, targets: np.ndarray, cell: np.ndarray, n_cells: int
) -> np.ndarray:
    """rho (n_candidates, n_cells): the share of the posterior variance along each cell's target
    points that one observation at each candidate removes, averaged over the outputs. `candidates`
    and `targets` are GP inputs (warped); cell[t] is the cell (0..n_cells-1) of target t."""
    rho = np.zeros((len(candidates), n_cells))
    if not len(cell):
        return rho
    for gp in model.gps:
        d = candidates.shape[1]
        cov = posterior_covariance(gp, candidates, targets)
        own = posterior_variance(gp, candidates) + math.exp(gp.theta_[d + 1])
        removed = cov * cov / own[:, None]  # the variance at each target removed by the candidate
        per_cell = np.zeros((len(candidates), n_cells))
        np.add.at(per_cell.T, cell, removed.T)
        total = np.bincount(cell, weights=posterior_variance(gp, targets), minlength=n_cells)
        rho += np.divide(per_cell, total, out=np.zeros_like(per_cell), where=total > 0.0)
    return np.clip(rho / len(model.gps), 0.0, 1.0)


def envelope_picks(
    model: MultiOutputGP, candidates: np.ndarray, targets: np.ndarray, cell: np.ndarray, weight: np.ndarray, k: int
) -> tuple[list[int], list[float]]:
    """k greedy picks (indices into `candidates`) maximising a(x*) = sum_c G_c rho_c(x*) (module
    doc), and each pick's value. `weight` (n_cells,): G_c."""
    G = np.asarray(weight, dtype=float).copy()
    look, picks, values = model, [], []
    for _ in range(k):
        rho = explained_shares(look, candidates, targets, cell, len(G))
        value = rho @ G
        value[picks] = -np.inf
        best = int(np.argmax(value))
        picks.append(best)
        values.append(float(value[best]))
        G *= 1.0 - rho[best]
        look = condition_on_mean(model, candidates[picks])
    return picks, values
