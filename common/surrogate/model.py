"""The loaded surrogate: predictions with their domain flags, and the surrogate server's messages.

The thesis's reduced-order model (chapter 4) maps six inputs to the non-dimensional interaction
coefficients X', Y', N' of the UUV (thesis section 5.2). This module is pure numpy (no Zenoh): it
says which inputs are valid (table 4.2, constraints (4.4)-(4.7) as corrected in docs/design.md,
"Thesis errata"), converts a dimensional state to inputs and coefficients back to forces
(mirroring the -y side, section 4.2.1), wraps a model file as a `Surrogate`, and defines the
query/reply messages of the surrogate server (`apps/surrogate.py`; defined in `surrogate.query`).

A `Surrogate` is one of three kinds (`Surrogate.kind`): "lf_in_loop", the exact low fidelity plus
a residual GP (the shipped kind; `low_fidelity` and `discrepancy` give its two parts);
"multi_fidelity", the thesis's GP of the LF plus a GP of the discrepancy (2.11); "gp", one GP per
output (a user's table, the analytic fixture).

A point outside the domain or the constraints is never refused and never extrapolated silently:
it is answered with the model's value at that point and flagged (`in_domain`,
`constraints_ok`); the consumer (the sim's interaction modes, docs/design.md, "Physics
decisions") decides what to do with it.

Without a shipped model (`default_model_path()`), the server, CLI and tests fall back to
`analytic_model()`: a GP fitted to a made-up smooth function. It is a test fixture, it says so in
its provenance, and whoever falls back to it says so on stderr.
"""

from __future__ import annotations

import hashlib
import math
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

import nearsub
from nearsub.common.learning.gp import MultiOutputGP
from nearsub.common.physics.hull import D_SUB, L_SUB
from nearsub.common.surrogate.domain import (
    BOUNDS,
    CONSTRAINTS,
    INPUT_NAMES,
    OUTPUT_NAMES,
    RHO_SEA,
    UNITS,
    _as_inputs,
    _flat_broadcast,
    _force_scales,
    constraints_ok,
    in_domain,
    sample_feasible,
    to_forces,
    to_inputs,
)
from nearsub.common.surrogate.modelfile import (
    LFInLoopModel,
    LoadedModel,
    ModelFileError,
    MultiFidelitySurrogate,
    lf_hash,
    lf_identity,
    load_model,
    save_model,
)

# The server's messages live in surrogate.query (light to import); they are part of this API too.
from nearsub.common.surrogate.query import (  # noqa: F401
    MAX_QUERY_POINTS,
    Prediction,
    SurrogateQuery,
    SurrogateReply,
    decode_query,
    decode_reply,
    encode_query,
    encode_reply,
    surrogate_key,
)


def default_model_path() -> Path:
    """Where the shipped model lives inside the installed package (package data `data/*`)."""
    return Path(nearsub.__file__).resolve().parent / "data" / "surrogate.npz"


def companion_path(model_path: str | os.PathLike, suffix: str) -> Path:
    """A file made for one model, next to its file: `<stem><suffix>`."""
    model_path = Path(model_path)
    return model_path.with_name(f"{model_path.stem}{suffix}")


def find_companion(
    model_id: str | None, model_path: str | os.PathLike | None, suffix: str, load: Callable[[Path], Any]
) -> tuple[Any | None, list[Path]]:
    """A file made for the model `model_id` (its free-stream table, its viscous correction): the
    one next to the model file (`companion_path`), else the shipped one beside the shipped model
    (`surrogate<suffix>`), used only if it names that model (its `surrogate_model_id`); None if
    neither. Also returns where it looked."""
    candidates = [companion_path(model_path, suffix)] if model_path is not None else []
    candidates.append(companion_path(default_model_path(), suffix))
    searched: list[Path] = []
    for path in dict.fromkeys(p.resolve() for p in candidates):
        searched.append(path)
        if model_id is not None and path.exists():
            found = load(path)
            if found.surrogate_model_id == model_id:
                return found, searched
    return None, searched


def _model_id(model: MultiOutputGP | MultiFidelitySurrogate | LFInLoopModel) -> str:
    """A short content hash of a fitted model (data and hyperparameters; for the LF-in-the-loop
    kind also the warping and the LF's identity): names a model in replies independently of where
    its file lives."""
    digest = hashlib.sha256()
    if isinstance(model, LFInLoopModel):
        digest.update(",".join(model.warping.names).encode())
        digest.update(lf_hash(lf_identity()).encode())
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

    @property
    def kind(self) -> str:
        """ "lf_in_loop" (exact LF + residual GP), "multi_fidelity" (GP of the LF + GP of the
        discrepancy, thesis (2.11)) or "gp" (one GP per output)."""
        if isinstance(self.model, LFInLoopModel):
            return "lf_in_loop"
        return "multi_fidelity" if isinstance(self.model, MultiFidelitySurrogate) else "gp"

    def _in_loop(self, what: str) -> LFInLoopModel:
        if not isinstance(self.model, LFInLoopModel):
            raise TypeError(f"{what}: only an LF-in-the-loop model has it; {self.source} is of kind {self.kind!r}")
        return self.model

    def low_fidelity(self, inputs: Any) -> np.ndarray:
        """The exact LF coefficients [X', Y', N'] (n, 3) at inputs (n, 6) or (6,)
        (`hydro.low_fidelity.lf_coefficients`; NaN where the UUV is within 1 cm of the hull).
        Raises TypeError for another kind of model."""
        return self._in_loop("low_fidelity").low_fidelity(_as_inputs(inputs))

    def discrepancy(self, inputs: Any, return_std: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """The residual GP alone: mean (n, 3) of HF - LF and its std (n, 3) (None unless asked).
        Raises TypeError for another kind of model."""
        model = self._in_loop("discrepancy")
        X = _as_inputs(inputs)
        if return_std:
            return model.discrepancy(X, return_std=True)
        return model.discrepancy(X), None

    def predict(self, inputs: Any, return_std: bool = True) -> Prediction:
        """Mean (and std) of [X', Y', N'] at inputs (n, 6) or (6,), flagged (see `Prediction`): the
        GP's, or for the LF-in-the-loop kind LF(x) + delta(x) with std = std_delta. `in_domain`
        uses the model file's bounds (table 4.2 for models saved by `save_surrogate`)."""
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
def save_surrogate(path: str | os.PathLike, model: MultiOutputGP | LFInLoopModel, provenance: dict[str, Any]) -> Path:
    """Save a fitted (n, 6) -> (n, 3) model as a surrogate model file with this domain's metadata."""
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
        "method": "ANALYTIC TEST FIXTURE: GP fitted to nearsub.common.surrogate.model.analytic_coefficients, "
        "a made-up smooth function; NOT hydrodynamics",
        "command": f"nearsub.common.surrogate.model.analytic_model(n={n}, seed={seed})",
        "notes": "For tests and plumbing only. Do not use its numbers.",
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


def answer_query(
    surrogate: Surrogate, payload: bytes, source: str = "surrogate", max_points: int = MAX_QUERY_POINTS
) -> bytes:
    """The server's work for one query: check it, predict the whole batch, encode the reply.
    Raises MessageError (naming the field and value) for a malformed query or one of more than
    `max_points` points."""
    query = decode_query(payload, max_points)
    prediction = surrogate.predict(query.points, return_std=True)
    return encode_reply(query, prediction, surrogate.output_names, surrogate.model_id, source)
