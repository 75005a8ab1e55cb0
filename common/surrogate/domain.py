"""The surrogate's domain: its six inputs, their bounds (thesis table 4.2), the constraints
(4.4)-(4.7), and the conversions between a dimensional state and inputs, and between the
non-dimensional coefficients X', Y', N' and forces (thesis section 5.2), mirrored on the -y side
(thesis section 4.2.1). The row arithmetic is compiled (`interaction_kernel`), shared with the
sim's and the batch engine's interaction.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from nearsub.common.physics.hull import D_SUB, L_SUB

# The six inputs in model-column order, and their bounds (thesis table 4.2; docs/design.md, "Physics decisions").
INPUT_NAMES = ("R_long", "R_lat", "u_kn", "psi_deg", "d_ratio", "ld_ratio")
BOUNDS = np.array(
    [
        [-0.7, 0.7],  # R_long = x / L_sub (docs/design.md, "Thesis errata" 2)
        [0.059, 0.105],  # R_lat = |y| / L_sub, centre-to-centre (docs/design.md, "Thesis errata" 2 and 7)
        [2.0, 5.0],  # u: UUV speed through the water [kn]
        [-2.0, 2.0],  # psi: heading relative to the submarine axis, + = bow away [deg] (section 4.2.1)
        [5.0, 50.0],  # D_sub / D_uuv
        [4.3, 13.0],  # L / D_uuv
    ]
)
# X' = X / (0.5 rho u^2 L_uuv^2), Y' likewise, N' = N / (0.5 rho u^2 L_uuv^3) (thesis section 5.2).
OUTPUT_NAMES = ("X_p", "Y_p", "N_p")
UNITS = {
    "R_long": "-",
    "R_lat": "-",
    "u_kn": "kn",
    "psi_deg": "deg",
    "d_ratio": "-",
    "ld_ratio": "-",
    "X_p": "X / (0.5 rho u^2 L_uuv^2)",
    "Y_p": "Y / (0.5 rho u^2 L_uuv^2)",
    "N_p": "N / (0.5 rho u^2 L_uuv^3)",
}
CONSTRAINT_NAMES = ("(4.4)", "(4.5)", "(4.6)", "(4.7)")
CONSTRAINTS = {
    "(4.4)": "8.575 R_lat - 0.5 (D_sub/D_uuv)^-1 - 9.425e-3 (D_sub/D_uuv)^-1 (L/D_uuv) - 0.5048 >= 0 "
    "(clearance >= 0.05 m; no speed term: the corrected form, docs/design.md)",
    "(4.5)": "-8.575 R_lat + 2 (D_sub/D_uuv)^-1 + 0.5 >= 0 (y_dist <= 2 D_uuv + D_sub/2)",
    "(4.6)": "65.44 (D_sub/D_uuv)^-1 + L/D_uuv - 8 >= 0 (not too short)",
    "(4.7)": "-58.81 (D_sub/D_uuv)^-1 - L/D_uuv + 17 >= 0 (not too long)",
    "R_lat": "centre-to-centre: y_dist between the centres of buoyancy over L_sub (docs/design.md)",
}


def _kernel():
    """The compiled row arithmetic (`interaction_kernel`), imported on first use: a process that
    only reads the domain's names and bounds does not pay numba's import."""
    from nearsub.common.surrogate import interaction_kernel

    return interaction_kernel


KNOT = 1852.0 / 3600.0  # international knot [m/s]; thesis 4.2.3: 2-5 kn ~ 1.03-2.57 m/s
RHO_SEA = 1025.0  # sea water [kg/m^3] (docs/design.md, "Frames, units and signs")


# ------------------------------------------------------------------------------- the domain
def _as_inputs(X: Any) -> np.ndarray:
    """Inputs as a float array (n, 6); one point (6,) becomes (1, 6)."""
    X = np.atleast_2d(np.asarray(X, dtype=float))
    if X.ndim != 2 or X.shape[1] != len(INPUT_NAMES):
        raise ValueError(f"inputs must have shape (n, {len(INPUT_NAMES)}) in the order {INPUT_NAMES}, got {X.shape}")
    return X


def in_domain(X: Any, bounds: Any = BOUNDS) -> np.ndarray:
    """(n,) True where every input lies within `bounds` (thesis table 4.2), ends included.
    Non-finite inputs are outside."""
    X = _as_inputs(X)
    bounds = np.asarray(bounds, dtype=float)
    return ((X >= bounds[:, 0]) & (X <= bounds[:, 1])).all(axis=1)


# Constraints (4.4)-(4.7), one row each: g = coefficients . [R_lat, (D_sub/D_uuv)^-1,
# (D_sub/D_uuv)^-1 L/D_uuv, L/D_uuv, 1], feasible where g >= 0 (thesis section 4.3).
# (4.4) is the corrected form of docs/design.md, "Thesis errata" 3 (no speed term): 8.575 = L_sub/D_sub,
# 0.5048 = 0.5 + 0.05 m/D_sub (clearance c >= 0.05 m, thesis (4.3)), 9.425e-3 = 0.27 sin(2 deg)
# ((1 - CB) L_uuv sin psi_max over D_sub).
CONSTRAINT_COEFFICIENTS = np.array(
    [
        # R_lat  1/d_ratio  ld/d_ratio  ld_ratio  1
        [8.575, -0.5, -9.425e-3, 0.0, -0.5048],  # (4.4), docs/design.md, "Thesis errata" 3
        [-8.575, 2.0, 0.0, 0.0, 0.5],  # (4.5)
        [0.0, 65.44, 0.0, 1.0, -8.0],  # (4.6)
        [0.0, -58.81, 0.0, -1.0, 17.0],  # (4.7)
    ]
)


def constraint_values(X: Any) -> np.ndarray:
    """(n, 4) left-hand sides of (4.4)-(4.7), feasible where >= 0 (columns as CONSTRAINT_NAMES).

    With R_lat centre-to-centre (docs/design.md, "Thesis errata" 7) the low corner R_lat = 0.059 is infeasible
    everywhere in the domain: (4.4) needs R_lat >= 0.5048 / 8.575 = 0.0589 plus the UUV's share.
    """
    X = np.ascontiguousarray(_as_inputs(X))
    values = np.empty((len(X), 4))
    _kernel().constraint_rows(X, CONSTRAINT_COEFFICIENTS, values)
    return values


def constraints_ok(X: Any) -> np.ndarray:
    """(n,) True where (4.4)-(4.7) all hold (they use R_lat, d_ratio and ld_ratio; NaN there fails)."""
    return (constraint_values(X) >= 0.0).all(axis=1)


def sample_feasible(n: int, seed: int = 0) -> np.ndarray:
    """n points (n, 6) uniform in table 4.2's box restricted to (4.4)-(4.7), by rejection: every
    sampler must respect the constraints (docs/design.md, "Thesis errata" 7). About 1 box draw in 6 is feasible."""
    rng = np.random.default_rng(seed)
    lower, width = BOUNDS[:, 0], BOUNDS[:, 1] - BOUNDS[:, 0]
    kept: list[np.ndarray] = []
    count = 0
    while count < n:
        X = lower + width * rng.uniform(size=(max(8 * (n - count), 64), len(INPUT_NAMES)))
        X = X[constraints_ok(X)]
        kept.append(X)
        count += X.shape[0]
    return np.concatenate(kept)[:n]


# ------------------------------------------------------------------------- unit conversions
def _flat_broadcast(*values: Any) -> list[np.ndarray]:
    """Float arrays broadcast together and flattened to one length n (scalars give n = 1)."""
    arrays = [np.asarray(v, dtype=float) for v in values]
    lengths = {len(a) for a in arrays if a.ndim == 1}
    if len(lengths) <= 1 and all(a.ndim <= 1 for a in arrays):  # vectors of one length and scalars (a vehicle's)
        n = lengths.pop() if lengths else 1
        return [a if a.ndim == 1 else np.full(n, a) for a in arrays]
    return [a.ravel() for a in np.broadcast_arrays(*(np.atleast_1d(a) for a in arrays))]


def to_inputs(
    x: Any,
    y: Any,
    u: Any,
    psi: Any,
    uuv_length: Any,
    uuv_diameter: Any,
    d_sub: float = D_SUB,
    l_sub: float = L_SUB,
) -> tuple[np.ndarray, np.ndarray]:
    """Dimensional state -> surrogate inputs (n, 6) and the mirror sign (n,) (+1, or -1 for y < 0).

    x, y [m] in the submarine frame, u [m/s] surge through the water, psi [rad] from +x towards
    +y; the arguments broadcast together and are flattened. On the -y side the geometry is
    mirrored (thesis 4.2.1; docs/design.md, "Frames, units and signs"): R_lat uses |y| and psi
    changes sign, so
    that + always means bow away from the submarine; `to_forces` flips Y' and N' back.
    """
    columns = [np.ascontiguousarray(a) for a in _flat_broadcast(x, y, u, psi, uuv_length, uuv_diameter)]
    inputs, mirror = np.empty((len(columns[0]), 6)), np.empty(len(columns[0]))
    _kernel().state_inputs(*columns, float(d_sub), float(l_sub), KNOT, inputs, mirror)
    return inputs, mirror


def _force_scales(u: Any, uuv_length: Any, rho: float) -> np.ndarray:
    """(n, 3) factors [q L^2, q L^2, q L^3], q = 0.5 rho u^2: coefficient -> force (thesis section 5.2)."""
    u, length = _flat_broadcast(u, uuv_length)
    ql2 = 0.5 * rho * u**2 * length**2
    scales = np.empty((len(ql2), 3))
    scales[:, 0] = scales[:, 1] = ql2
    np.multiply(ql2, length, out=scales[:, 2])
    return scales


def to_forces(coeffs: Any, mirror: Any, u: Any, uuv_length: Any, rho: float = RHO_SEA) -> np.ndarray:
    """Coefficients (n, 3) [X', Y', N'] -> dimensional [X_s N, Y_s N, N_s N m] (n, 3), with Y and N
    flipped on the -y side (mirror = -1), undoing the mirroring of `to_inputs`."""
    coeffs = np.atleast_2d(np.asarray(coeffs, dtype=float))
    rows = _flat_broadcast(mirror, u, uuv_length)
    n = max(len(coeffs), len(rows[0]))
    coeffs = np.ascontiguousarray(np.broadcast_to(coeffs, (n, 3)))[None]
    mirror, u, length = (np.ascontiguousarray(np.broadcast_to(a, (n,))) for a in rows)
    forces = np.empty((1, n, 3))
    _kernel().force_rows(coeffs, mirror, u, length, float(rho), forces)
    return forces[0]


def to_coefficients(forces: Any, u: Any, uuv_length: Any, rho: float = RHO_SEA) -> np.ndarray:
    """Dimensional [X N, Y N, N N m] (n, 3) in the mirrored frame of the inputs -> [X', Y', N'] (n, 3):
    the inverse of `to_forces` with mirror = +1 (for answers of external simulations)."""
    return np.atleast_2d(np.asarray(forces, dtype=float)) / _force_scales(u, uuv_length, rho)
