"""The surrogate's domain: inputs, bounds, constraints, unit conversions, prediction and wire messages.

The thesis's reduced-order model (chapter 4) maps six inputs to the non-dimensional interaction
coefficients X', Y', N' of the UUV (SPEC section 2). This module is pure numpy (no Zenoh): it says
which inputs are valid (table 4.2, constraints (4.4)-(4.7) with SPEC errata 3 and 7), converts a
dimensional state to inputs and coefficients back to forces (mirroring the -y side, section
4.2.1), wraps a model file as a `Surrogate`, and defines the query/reply messages of the
surrogate server (`apps/surrogate.py`).

A point outside the domain or the constraints is never refused and never extrapolated silently:
it is answered with the GP's value at that point and flagged (`in_domain`, `constraints_ok`);
the consumer (the sim's blend, SPEC section 5) decides what to do with it.

Until the hydrodynamics issue trains and ships the real model (`default_model_path()`), the
server, CLI and tests use `analytic_model()`: a GP fitted to a made-up smooth function. It is a
test fixture, it says so in its provenance, and whoever falls back to it says so on stderr.
"""

from __future__ import annotations

import hashlib
import math
import os
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import Field, model_validator
from pydantic.types import FiniteFloat

import nearsub
from nearsub.common import keys
from nearsub.common.gp import MultiOutputGP
from nearsub.common.hull import D_SUB, L_SUB
from nearsub.common.messages import FiniteMessage, decode, encode
from nearsub.common.modelfile import LoadedModel, ModelFileError, load_model, save_model

# The six inputs in model-column order, and their bounds (thesis table 4.2; SPEC section 5).
INPUT_NAMES = ("R_long", "R_lat", "u_kn", "psi_deg", "d_ratio", "ld_ratio")
BOUNDS = np.array(
    [
        [-0.7, 0.7],  # R_long = x / L_sub (SPEC errata 2)
        [0.059, 0.105],  # R_lat = |y| / L_sub, centre-to-centre (SPEC errata 2 and 7)
        [2.0, 5.0],  # u: UUV speed through the water [kn]
        [-2.0, 2.0],  # psi: heading relative to the submarine axis, + = bow away [deg] (section 4.2.1)
        [5.0, 50.0],  # D_sub / D_uuv
        [4.3, 13.0],  # L / D_uuv
    ]
)
# X' = X / (0.5 rho u^2 L_uuv^2), Y' likewise, N' = N / (0.5 rho u^2 L_uuv^3) (SPEC section 2).
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
    "(clearance >= 0.05 m; no speed term, SPEC errata 3)",
    "(4.5)": "-8.575 R_lat + 2 (D_sub/D_uuv)^-1 + 0.5 >= 0 (y_dist <= 2 D_uuv + D_sub/2)",
    "(4.6)": "65.44 (D_sub/D_uuv)^-1 + L/D_uuv - 8 >= 0 (not too short)",
    "(4.7)": "-58.81 (D_sub/D_uuv)^-1 - L/D_uuv + 17 >= 0 (not too long)",
    "R_lat": "centre-to-centre: y_dist between the centres of buoyancy over L_sub (SPEC errata 7)",
}

KNOT = 1852.0 / 3600.0  # international knot [m/s]; thesis 4.2.3: 2-5 kn ~ 1.03-2.57 m/s
RHO_SEA = 1025.0  # sea water [kg/m^3] (SPEC section 2)
# Largest batch one query may carry (a nearsub choice: bounds the server's memory per query,
# about 1 MB of msgpack; a 10,000-point sweep is 10 queries).
MAX_QUERY_POINTS = 100_000


def surrogate_key(community: str) -> str:
    """The server's queryable: nearsub/<community>/surrogate (SPEC section 3, a service key)."""
    return f"{keys.community_root(community)}/surrogate"


def default_model_path() -> Path:
    """Where the shipped model lives inside the installed package (package data `data/*`)."""
    return Path(nearsub.__file__).resolve().parent / "data" / "surrogate.npz"


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
# (4.4) is the corrected form of SPEC errata 3 (no speed term): 8.575 = L_sub/D_sub,
# 0.5048 = 0.5 + 0.05 m/D_sub (clearance c >= 0.05 m, thesis (4.3)), 9.425e-3 = 0.27 sin(2 deg)
# ((1 - CB) L_uuv sin psi_max over D_sub).
_CONSTRAINT_COEFFICIENTS = np.array(
    [
        # R_lat  1/d_ratio  ld/d_ratio  ld_ratio  1
        [8.575, -0.5, -9.425e-3, 0.0, -0.5048],  # (4.4), SPEC errata 3
        [-8.575, 2.0, 0.0, 0.0, 0.5],  # (4.5)
        [0.0, 65.44, 0.0, 1.0, -8.0],  # (4.6)
        [0.0, -58.81, 0.0, -1.0, 17.0],  # (4.7)
    ]
)


def constraint_values(X: Any) -> np.ndarray:
    """(n, 4) left-hand sides of (4.4)-(4.7), feasible where >= 0 (columns as CONSTRAINT_NAMES).

    With R_lat centre-to-centre (SPEC errata 7) the low corner R_lat = 0.059 is infeasible
    everywhere in the domain: (4.4) needs R_lat >= 0.5048 / 8.575 = 0.0589 plus the UUV's share.
    """
    X = _as_inputs(X)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_d = 1.0 / X[:, 4]  # (D_sub/D_uuv)^-1
        features = np.column_stack([X[:, 1], inv_d, inv_d * X[:, 5], X[:, 5]])
        return features @ _CONSTRAINT_COEFFICIENTS[:, :4].T + _CONSTRAINT_COEFFICIENTS[:, 4]


def constraints_ok(X: Any) -> np.ndarray:
    """(n,) True where (4.4)-(4.7) all hold (they use R_lat, d_ratio and ld_ratio; NaN there fails)."""
    return (constraint_values(X) >= 0.0).all(axis=1)


def sample_feasible(n: int, seed: int = 0) -> np.ndarray:
    """n points (n, 6) uniform in table 4.2's box restricted to (4.4)-(4.7), by rejection: every
    sampler must respect the constraints (SPEC errata 7). About 1 box draw in 6 is feasible."""
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
    return [a.ravel() for a in np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, dtype=float)) for v in values))]


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
    +y (SPEC section 2); the arguments broadcast together and are flattened. On the -y side the
    geometry is mirrored (SPEC section 2, thesis 4.2.1): R_lat uses |y| and psi changes sign, so
    that + always means bow away from the submarine; `to_forces` flips Y' and N' back.
    """
    x, y, u, psi, length, diameter = _flat_broadcast(x, y, u, psi, uuv_length, uuv_diameter)
    mirror = np.where(y < 0.0, -1.0, 1.0)
    psi_wrapped = np.remainder(psi + math.pi, 2.0 * math.pi) - math.pi  # heading in [-pi, pi)
    inputs = np.column_stack(
        [
            x / l_sub,  # R_long (3.3), SPEC errata 2
            np.abs(y) / l_sub,  # R_lat (3.4), centre-to-centre (errata 7)
            u / KNOT,
            mirror * np.degrees(psi_wrapped),
            d_sub / diameter,
            length / diameter,
        ]
    )
    return inputs, mirror


def _force_scales(u: Any, uuv_length: Any, rho: float) -> np.ndarray:
    """(n, 3) factors [q L^2, q L^2, q L^3], q = 0.5 rho u^2: coefficient -> force (SPEC section 2)."""
    u, length = _flat_broadcast(u, uuv_length)
    ql2 = 0.5 * rho * u**2 * length**2
    return np.column_stack([ql2, ql2, ql2 * length])


def to_forces(coeffs: Any, mirror: Any, u: Any, uuv_length: Any, rho: float = RHO_SEA) -> np.ndarray:
    """Coefficients (n, 3) [X', Y', N'] -> dimensional [X_s N, Y_s N, N_s N m] (n, 3), with Y and N
    flipped on the -y side (mirror = -1), undoing the mirroring of `to_inputs`."""
    coeffs = np.atleast_2d(np.asarray(coeffs, dtype=float))
    mirror = np.asarray(mirror, dtype=float).reshape(-1, 1)
    signs = np.hstack([np.ones_like(mirror), mirror, mirror])
    return coeffs * _force_scales(u, uuv_length, rho) * signs


def to_coefficients(forces: Any, u: Any, uuv_length: Any, rho: float = RHO_SEA) -> np.ndarray:
    """Dimensional [X N, Y N, N N m] (n, 3) in the mirrored frame of the inputs -> [X', Y', N'] (n, 3):
    the inverse of `to_forces` with mirror = +1 (for answers of external simulations)."""
    return np.atleast_2d(np.asarray(forces, dtype=float)) / _force_scales(u, uuv_length, rho)


# ------------------------------------------------------------------------------- prediction
@dataclass(frozen=True)
class Prediction:
    """Answers for n points: mean and std (n, 3) (None if not asked), and the two flags (n,).

    For points outside the bounds or constraints, mean and std are still the GP's posterior at
    that very point (no clipping, no substitution): far from the data the RBF GP reverts to the
    training mean and its std grows towards the prior std, so the numbers stay finite and honest,
    and the flags say not to trust them. Non-finite inputs give NaN mean and std.
    """

    mean: np.ndarray
    std: np.ndarray | None
    in_domain: np.ndarray
    constraints_ok: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """(n,) inside the bounds and the constraints: the region the model was trained on."""
        return self.in_domain & self.constraints_ok


def _model_id(model: MultiOutputGP) -> str:
    """A short content hash of a fitted model (data and hyperparameters): names a model in replies
    independently of where its file lives."""
    digest = hashlib.sha256()
    for gp in getattr(model, "all_gps", model.gps):
        for array in (gp.X_train_, gp.y_train_, gp.lower_, gp.width_, gp.theta_):
            digest.update(np.ascontiguousarray(array, dtype=float).tobytes())
    return digest.hexdigest()[:16]


class Surrogate:
    """A loaded surrogate model file with the domain checks around every prediction."""

    def __init__(self, loaded: LoadedModel, source: str | None = None):
        if loaded.input_names != INPUT_NAMES or len(loaded.output_names) != len(OUTPUT_NAMES):
            raise ModelFileError(
                f"{loaded.path}: not a surrogate of this domain: inputs {loaded.input_names} and "
                f"{len(loaded.output_names)} outputs, expected inputs {INPUT_NAMES} and {len(OUTPUT_NAMES)} outputs"
            )
        self.loaded = loaded
        self.model = loaded.model
        self.bounds = np.asarray(loaded.bounds, dtype=float)
        self.output_names = loaded.output_names
        self.model_id = _model_id(loaded.model)
        self.source = source or str(loaded.path)

    def predict(self, inputs: Any, return_std: bool = True) -> Prediction:
        """GP mean (and std) of [X', Y', N'] at inputs (n, 6) or (6,), flagged (see `Prediction`).
        `in_domain` uses the model file's bounds (table 4.2 for models saved by `save_surrogate`)."""
        X = _as_inputs(inputs)
        # Row-wise arithmetic: a vehicle asking alone and a sweep asking for 800 get the same bits.
        if return_std:
            mean, std = self.model.predict_rows(X, return_std=True)
        else:
            mean, std = self.model.predict_rows(X), None
        inside = in_domain(X, self.bounds)
        if not inside.all():  # non-finite inputs are never inside: only then look for them
            finite = np.all(np.isfinite(X), axis=1)
            mean[~finite] = np.nan
            if std is not None:
                std[~finite] = np.nan
        return Prediction(mean, std, inside, constraints_ok(X))

    def predict_state(
        self,
        x: Any,
        y: Any,
        u: Any,
        psi: Any,
        uuv_length: Any,
        uuv_diameter: Any,
        rho: float = RHO_SEA,
        d_sub: float = D_SUB,
        l_sub: float = L_SUB,
    ) -> Prediction:
        """Dimensional state (as `to_inputs`) -> dimensional [X_s, Y_s, N_s] and their std (n, 3),
        in N and N m, with the flags of the underlying inputs."""
        inputs, mirror = to_inputs(x, y, u, psi, uuv_length, uuv_diameter, d_sub, l_sub)
        p = self.predict(inputs, return_std=True)
        speed, length = _flat_broadcast(u, uuv_length, x, y, psi, uuv_diameter)[:2]  # u, L_uuv per row
        return Prediction(
            to_forces(p.mean, mirror, speed, length, rho),
            p.std * _force_scales(speed, length, rho),
            p.in_domain,
            p.constraints_ok,
        )


# ----------------------------------------------------------------- model files and fixture
def save_surrogate(path: str | os.PathLike, model: MultiOutputGP, provenance: dict[str, Any]) -> Path:
    """Save a fitted (n, 6) -> (n, 3) GP as a surrogate model file with this domain's metadata."""
    return save_model(
        path,
        model,
        input_names=INPUT_NAMES,
        output_names=OUTPUT_NAMES,
        units=UNITS,
        bounds=BOUNDS,
        constraints=CONSTRAINTS,
        provenance=provenance,
    )


def analytic_coefficients(X: Any) -> np.ndarray:
    """A made-up smooth stand-in for [X', Y', N'] (n, 3) at inputs (n, 6): NOT hydrodynamics.

    Only the shape is plausible (magnitudes ~1e-3 as REMUS-size coefficients; thesis chapter 4
    trends): a drag X' < 0 growing with |psi|; an interaction that decays over ~0.015 in R_lat
    away from the hull, grows for larger UUVs (smaller D_sub/D_uuv); Y' < 0 (towards the
    submarine) amidships and > 0 near the bow and stern, changing sign at |R_long| = 0.7/3;
    N' changing sign at R_long = 0. Heading adds a linear sway force and moment.
    """
    X = _as_inputs(X)
    s = X[:, 0] / 0.7  # position along the domain, -1..1
    near = np.exp(-(X[:, 1] - 0.059) / 0.015) * (20.0 / X[:, 4]) ** 0.25 * (X[:, 5] / 8.0) ** 0.3
    heading = X[:, 3] / 2.0
    drag = -1.2e-3 * (1.0 + 0.3 * heading**2) * (1.0 - 0.05 * (X[:, 2] - 3.5))
    return np.column_stack(
        [
            drag + 0.4e-3 * near * np.sin(math.pi * s),
            -1.0e-3 * near * np.cos(1.5 * math.pi * s) + 0.6e-3 * heading,
            0.5e-3 * near * np.sin(math.pi * s) + 0.3e-3 * heading,
        ]
    )


def analytic_model(n: int = 100, seed: int = 0, path: str | os.PathLike | None = None) -> LoadedModel:
    """TEST FIXTURE: a MultiOutputGP fitted to `analytic_coefficients` at n feasible points, saved
    as a model file (at `path`, or a temporary file that is removed again) and read back, so it
    goes through exactly the path a real model does. Stands in until the real model ships."""
    X = sample_feasible(n, seed)
    model = MultiOutputGP(bounds=BOUNDS, n_restarts=5, seed=seed).fit(X, analytic_coefficients(X))
    provenance = {
        "method": "ANALYTIC TEST FIXTURE: GP fitted to nearsub.common.surrogate.analytic_coefficients, "
        "a made-up smooth function; NOT hydrodynamics",
        "command": f"nearsub.common.surrogate.analytic_model(n={n}, seed={seed})",
        "notes": "For tests and plumbing only, until the hydrodynamics issue trains and ships the real "
        "model (SPEC section 7). Do not use its numbers.",
        "n_train": n,
        "seed": seed,
    }
    if path is not None:
        return load_model(save_surrogate(path, model, provenance))
    with tempfile.TemporaryDirectory(prefix="nearsub-analytic-") as folder:
        return load_model(save_surrogate(Path(folder) / "analytic.npz", model, provenance))


def load_surrogate(path: str | os.PathLike | None = None) -> Surrogate:
    """The model at `path`; without one the shipped model, or, if none is shipped yet, the analytic
    test fixture, with a loud warning on stderr. Raises ModelFileError for a bad file."""
    if path is not None:
        return Surrogate(load_model(path))
    shipped = default_model_path()
    if shipped.exists():
        return Surrogate(load_model(shipped))
    print(
        f"WARNING: no shipped surrogate model at {shipped}; using the ANALYTIC TEST FIXTURE "
        "(a made-up function, not hydrodynamics). Its predictions are meaningless.",
        file=sys.stderr,
        flush=True,
    )
    return Surrogate(analytic_model(), source=f"analytic test fixture (no model at {shipped})")


# -------------------------------------------------------------------------------- messages
Point = Annotated[list[FiniteFloat], Field(min_length=len(INPUT_NAMES), max_length=len(INPUT_NAMES))]


class SurrogateQuery(FiniteMessage):
    """A batch of points to predict at: `points` is a list of rows [R_long, R_lat, u_kn, psi_deg,
    d_ratio, ld_ratio] (INPUT_NAMES order, units of table 4.2), finite, 1..MAX_QUERY_POINTS rows.

    Rows rather than a dict of columns: a row is one vehicle state, maps to a numpy (n, 6) array
    without reordering, and a bad value is named by its position (field 'points.<row>.<column>').
    The header (schema_version, step, t, source) is the sender's; the reply echoes step and t.
    """

    points: Annotated[list[Point], Field(min_length=1, max_length=MAX_QUERY_POINTS)]


class SurrogateReply(FiniteMessage):
    """Answers to a `SurrogateQuery`, row for row: mean and std (n, len(output_names)) of the
    non-dimensional coefficients, and the flags (n,) (see `Prediction` for out-of-domain points).
    model_id names the model (a content hash), source is the server instance."""

    mean: list[list[FiniteFloat]]
    std: list[list[FiniteFloat]]
    in_domain: list[bool]
    constraints_ok: list[bool]
    output_names: list[str]
    model_id: str

    @model_validator(mode="after")
    def _consistent_shapes(self) -> SurrogateReply:
        n, m = len(self.mean), len(self.output_names)
        if len(self.std) != n or len(self.in_domain) != n or len(self.constraints_ok) != n:
            raise ValueError(
                f"mean has {n} rows but std has {len(self.std)}, in_domain {len(self.in_domain)}, "
                f"constraints_ok {len(self.constraints_ok)}"
            )
        bad = next((i for i, row in enumerate(self.mean + self.std) if len(row) != m), None)
        if bad is not None:
            raise ValueError(f"row {bad % n} of {'mean' if bad < n else 'std'} does not have {m} values")
        return self

    def prediction(self) -> Prediction:
        """The reply as numpy arrays."""
        return Prediction(
            np.array(self.mean, dtype=float).reshape(-1, len(self.output_names)),
            np.array(self.std, dtype=float).reshape(-1, len(self.output_names)),
            np.array(self.in_domain, dtype=bool),
            np.array(self.constraints_ok, dtype=bool),
        )


def encode_query(points: Any, step: int = 0, t: float = 0.0, source: str = "") -> bytes:
    """msgpack bytes of a SurrogateQuery for points (n, 6) or (6,)."""
    rows = _as_inputs(points).tolist()
    return encode(SurrogateQuery(step=step, t=t, source=source, points=rows))


def answer_query(surrogate: Surrogate, payload: bytes, source: str = "surrogate") -> bytes:
    """The server's work for one query: validate, predict the whole batch, encode the reply.
    Raises MessageError (naming the field and value) for a malformed query."""
    query = decode(payload, SurrogateQuery, "surrogate query")
    p = surrogate.predict(np.array(query.points, dtype=float), return_std=True)
    reply = SurrogateReply(
        step=query.step,
        t=query.t,
        source=source,
        mean=p.mean.tolist(),
        std=p.std.tolist(),
        in_domain=p.in_domain.tolist(),
        constraints_ok=p.constraints_ok.tolist(),
        output_names=list(surrogate.output_names),
        model_id=surrogate.model_id,
    )
    return encode(reply)


def decode_reply(payload: bytes) -> SurrogateReply:
    """Validate a server reply (raises MessageError naming the field and value)."""
    return decode(payload, SurrogateReply, "surrogate reply")
