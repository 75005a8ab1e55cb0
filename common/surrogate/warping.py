"""Input warpings of the residual GP, applied before the unit-cube scaling (docs/design.md,
"Hydrodynamic fidelities").

The HF - LF residual of Y' grows like a power law as the gap between the hulls closes and as the
UUV grows, which a stationary kernel on raw (R_lat, D_sub/D_uuv) fits with ringing. Per input
column a warping is one of

* "identity": the input as it is;
* "log": log of the input (D_sub/D_uuv -> log(D_sub/D_uuv));
* "log_clearance": R_lat -> log(c0 / D_uuv), c0 the clearance between the hulls at psi = 0 that
  constraint (4.4) bounds: c0 = R_lat L_sub - D_sub/2 - D_uuv/2 (thesis (4.3)-(4.4)), so
  c0 / D_uuv = d (R_lat L_sub/D_sub - 1/2) - 1/2 with d = D_sub/D_uuv. It needs the d_ratio
  column. Over (4.4)-(4.5) c0/D_uuv lies in [0.0048 d + 9.425e-3 L/D_uuv, 1.5] (>= 0.0645);
  below `_CLEARANCE_FLOOR` (outside (4.4), where predictions are flagged anyway) it is clamped
  there, so the warp stays finite everywhere.

A warping is stored in the model file as one name per input column; `Warping.bounds` maps the
box of table 4.2 restricted to (4.4)-(4.7) to the warped box the GP scales to the unit cube.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from nearsub.common.physics.hull import D_SUB, L_SUB
from nearsub.common.surrogate.domain import BOUNDS, INPUT_NAMES

WARPS = ("identity", "log", "log_clearance")
_LSUB_OVER_DSUB = L_SUB / D_SUB  # 8.575 (thesis (4.4)'s coefficient)
_CLEARANCE_FLOOR = 1e-3  # c0 / D_uuv clamp below the feasible minimum 0.0645
# Warped box of log_clearance: c0/D_uuv from its minimum over (4.4) (D_sub/D_uuv = 5,
# L/D_uuv = 4.3: 0.0048 * 5 + 9.425e-3 * 4.3) to its maximum under (4.5) (1.5).
_CLEARANCE_RANGE = (0.0048 * 5.0 + 9.425e-3 * 4.3, 1.5)
_D_COLUMN = INPUT_NAMES.index("d_ratio")
DEFAULT_WARPING = ("identity", "log_clearance", "identity", "identity", "log", "identity")
NO_WARPING = ("identity",) * len(INPUT_NAMES)


def clearance_ratio(r_lat: np.ndarray, d_ratio: np.ndarray) -> np.ndarray:
    """c0 / D_uuv at psi = 0 (module doc), unclamped."""
    return d_ratio * (r_lat * _LSUB_OVER_DSUB - 0.5) - 0.5


class Warping:
    """One warp name per input column (WARPS); forward/inverse on (n, 6) input arrays."""

    def __init__(self, names: Sequence[str] = DEFAULT_WARPING):
        names = tuple(str(n) for n in names)
        if len(names) != len(INPUT_NAMES):
            raise ValueError(f"warping needs {len(INPUT_NAMES)} names (one per input), got {len(names)}")
        for column, name in zip(INPUT_NAMES, names, strict=True):
            if name not in WARPS:
                raise ValueError(f"warping of {column}: unknown {name!r}; choose from {WARPS}")
        if "log_clearance" in names and names.index("log_clearance") != INPUT_NAMES.index("R_lat"):
            raise ValueError("warping: log_clearance applies to R_lat only")
        self.names = names

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Warping) and other.names == self.names

    def __repr__(self) -> str:
        return f"Warping({self.names})"

    def describe(self) -> dict[str, str]:
        """{input: warp} for the columns that are warped."""
        return {c: n for c, n in zip(INPUT_NAMES, self.names, strict=True) if n != "identity"}

    def forward(self, X: np.ndarray) -> np.ndarray:
        """Warped inputs (n, 6) of raw inputs X (n, 6)."""
        X = np.asarray(X, dtype=float)
        W = X.copy()
        d = X[:, _D_COLUMN]
        with np.errstate(divide="ignore", invalid="ignore"):
            for k, name in enumerate(self.names):
                if name == "log":
                    W[:, k] = np.log(X[:, k])
                elif name == "log_clearance":
                    W[:, k] = np.log(np.maximum(clearance_ratio(X[:, k], d), _CLEARANCE_FLOOR))
        return W

    def inverse(self, W: np.ndarray) -> np.ndarray:
        """Raw inputs of warped ones (exact where the clearance is above the clamp)."""
        W = np.asarray(W, dtype=float)
        X = W.copy()
        for k, name in enumerate(self.names):
            if name == "log":
                X[:, k] = np.exp(W[:, k])
        d = X[:, _D_COLUMN]
        for k, name in enumerate(self.names):
            if name == "log_clearance":
                X[:, k] = ((np.exp(W[:, k]) + 0.5) / d + 0.5) / _LSUB_OVER_DSUB
        return X

    @property
    def bounds(self) -> np.ndarray:
        """(6, 2) the warped box: table 4.2's bounds warped, log_clearance over (4.4)-(4.5)."""
        out = BOUNDS.copy()
        for k, name in enumerate(self.names):
            if name == "log":
                out[k] = np.log(BOUNDS[k])
            elif name == "log_clearance":
                out[k] = np.log(_CLEARANCE_RANGE)
        return out
