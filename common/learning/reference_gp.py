"""An independent multi-fidelity GP for the benchmark: emukit's linear AR(1) model on GPy.

`nearsub al-bench --reference` refits every method's training sets with it, so a ranking of
the methods cannot come from a flaw of nearsub's own GP core (`mfgp.MultiFidelityGP`). The model
form is the same: ARD RBF kernels for the LF and for delta, rho fixed to 1 (thesis 2.2.4),
inputs on the unit cube of the known bounds; the implementation, the likelihood (emukit fits LF
and delta jointly, nearsub in two steps) and the optimiser are not. Outputs are standardised
with the LF data's mean and std, one affine map for both fidelities, which keeps rho = 1. The
noise is fixed to 1e-6 of the output variance (deterministic simulators). With an exact LF the
LF needs no model: a GPy GP of the residual HF - LF, added to the exact LF; without LF data
(HF-only methods), a GPy GP of the HF data.

Optional: GPy and emukit come with the `bench` extra (`pip install 'nearsub[bench]'`).
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["missing", "predict_hf"]

_NOISE = 1e-6  # fixed noise variance, in standardised output units


def missing() -> str | None:
    """Why the reference model cannot run here (a missing package), or None if it can."""
    try:
        import emukit.multi_fidelity  # noqa: F401
        import GPy  # noqa: F401
    except ImportError as exc:
        return f"{exc.name} is not installed (pip install 'nearsub[bench]')"
    return None


def predict_hf(
    bounds: Any,
    X_hf: np.ndarray,
    Y_hf: np.ndarray,
    X: np.ndarray,
    *,
    lf_data: tuple[np.ndarray, np.ndarray] | None = None,
    lf: Callable[[np.ndarray], np.ndarray] | None = None,
    restarts: int = 2,
    seed: int = 0,
) -> np.ndarray:
    """The reference model's HF mean (n, m) at X, fitted per output on the given data.

    lf_data: (X_lf, Y_lf) for emukit's two-fidelity model. lf: the exact LF function (then
    delta is fitted to HF - LF). Neither: a single-fidelity GP of the HF data.
    """
    import GPy

    logging.getLogger("GPy").setLevel(logging.ERROR)
    logging.getLogger("paramz").setLevel(logging.ERROR)
    bounds = np.asarray(bounds, dtype=float)
    lower, width = bounds[:, 0], bounds[:, 1] - bounds[:, 0]
    unit = lambda Z: (np.asarray(Z, dtype=float) - lower) / width  # noqa: E731
    Y_hf = np.asarray(Y_hf, dtype=float).reshape(len(X_hf), -1)
    out = np.empty((len(X), Y_hf.shape[1]))
    np.random.seed(seed)  # GPy's random restarts draw from numpy's global generator
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # GPy's overflow warnings at far-off restarts
        if lf_data is None:
            base_hf, base = np.zeros_like(Y_hf), np.zeros((len(X), Y_hf.shape[1]))
            if lf is not None:
                base_hf, base = lf(X_hf).reshape(Y_hf.shape), lf(X).reshape(len(X), -1)
            for j in range(Y_hf.shape[1]):
                r = Y_hf[:, j] - base_hf[:, j]
                mu, sd = r.mean(), r.std() or 1.0
                model = GPy.models.GPRegression(
                    unit(X_hf), ((r - mu) / sd)[:, None], GPy.kern.RBF(len(lower), ARD=True)
                )
                model.Gaussian_noise.variance.fix(_NOISE)
                model.optimize_restarts(num_restarts=restarts, verbose=False, robust=True)
                out[:, j] = base[:, j] + mu + sd * model.predict(unit(X))[0][:, 0]
            return out
        from emukit.multi_fidelity.convert_lists_to_array import convert_x_list_to_array, convert_y_list_to_array
        from emukit.multi_fidelity.models import GPyLinearMultiFidelityModel

        kernel_class = _fixed_rho_kernel_class()

        X_lf, Y_lf = lf_data
        Y_lf = np.asarray(Y_lf, dtype=float).reshape(len(X_lf), -1)
        X_train = convert_x_list_to_array([unit(X_lf), unit(X_hf)])
        X_query = convert_x_list_to_array([unit(X[:0]), unit(X)])  # fidelity index 1 (HF) on every row
        for j in range(Y_hf.shape[1]):
            mu, sd = Y_lf[:, j].mean(), Y_lf[:, j].std() or 1.0
            Y_train = convert_y_list_to_array([(Y_lf[:, [j]] - mu) / sd, (Y_hf[:, [j]] - mu) / sd])
            kernel = kernel_class([GPy.kern.RBF(len(lower), ARD=True) for _ in range(2)])
            kernel.scale.fix(1.0)  # rho = 1, as in nearsub's model
            model = GPyLinearMultiFidelityModel(X_train, Y_train, kernel, n_fidelities=2)
            model.mixed_noise.Gaussian_noise.fix(_NOISE)
            model.mixed_noise.Gaussian_noise_1.fix(_NOISE)
            model.optimize_restarts(num_restarts=restarts, verbose=False, robust=True)
            mean = model.predict(X_query, Y_metadata={"output_index": X_query[:, -1].astype(int)})[0]
            out[:, j] = mu + sd * mean[:, 0]
    return out


_KERNEL_CLASS: list[type] = []


def _fixed_rho_kernel_class() -> type:
    """emukit's `LinearMultiFidelityKernel`, minus work whose result the fit does not use, so
    the fit is bit-identical and cheaper (about a tenth of a reference fit, see
    docs/al-bench/README.md "Timing"): the sub-kernels' gradient masks (which blocks of K each
    kernel enters, and with which power of rho) depend only on the fidelity column and rho, so
    they are built once per training set instead of at every likelihood evaluation; and the
    gradient of a fixed rho, which the optimiser drops, is not computed (emukit builds every
    sub-kernel's full K for it)."""
    if _KERNEL_CLASS:
        return _KERNEL_CLASS[0]
    from emukit.multi_fidelity.kernels import LinearMultiFidelityKernel

    class FixedRhoKernel(LinearMultiFidelityKernel):
        _masks: tuple[bytes, list[np.ndarray]] | None = None

        def _update_sub_kernel_gradients_full(self, X, X2, dL_dK):
            rho = np.asarray(self.scaling_param, dtype=float)
            key = X[:, -1].tobytes() + b"|" + X2[:, -1].tobytes() + b"|" + rho.tobytes()
            if self._masks is None or self._masks[0] != key:
                self._masks = (key, _gradient_masks(X[:, -1], X2[:, -1], rho, self.n_fidelities))
            for kernel, mask in zip(self.kernels, self._masks[1], strict=True):
                kernel.update_gradients_full(dL_dK * mask, X, X2)

        def _update_scaling_parameter_gradients_full(self, X, X2, dL_dK):
            if not self.scaling_param.is_fixed:
                super()._update_scaling_parameter_gradients_full(X, X2, dL_dK)
            else:
                self.scaling_param.gradient = np.zeros(self.n_fidelities - 1)

    _KERNEL_CLASS.append(FixedRhoKernel)
    return FixedRhoKernel


def _gradient_masks(f: np.ndarray, f2: np.ndarray, rho: np.ndarray, n_fidelities: int) -> list[np.ndarray]:
    """d K / d K_k for each sub-kernel k: emukit 0.5.1's `_update_sub_kernel_gradients_full`
    loop (Kennedy & O'Hagan 2000, section 2.5), the same additions in the same order."""
    masks = [np.zeros((len(f), len(f2))) for _ in range(n_fidelities)]
    for i in range(n_fidelities):
        for j in range(i + 1):
            idx, idx_t = np.ix_(f == j, f2 == i), np.ix_(f == i, f2 == j)
            for k in range(j + 1):
                scale = np.prod(rho[k:i]) * np.prod(rho[k:j])
                masks[k][idx] += scale
                if i != j:
                    masks[k][idx_t] += scale
    return masks
