"""One versioned file per trained surrogate: data, fitted GPs and the metadata to trust them.

Format ``nearsub.gp-surrogate`` version 1 is an uncompressed numpy ``.npz`` archive (a zip of
``.npy`` arrays; read with ``allow_pickle=False``, so loading never executes code). Chosen
over msgpack because every number stays a raw IEEE array (bit-exact round trip) and any numpy
can inspect it. Entries:

* ``metadata``: UTF-8 JSON as a uint8 array: ``format``, ``version``, ``saved_utc``,
  ``input_names``, ``output_names``, ``units`` (name -> unit), ``constraints`` (free-form),
  ``provenance`` (free-form; ``created_utc`` is filled in if missing; by convention also
  ``method``, ``command``, ``notes``), ``software`` (versions), ``n_outputs``.
* ``bounds`` (d, 2): the input domain; ``X`` (n, d) and ``Y`` (n, m): the training data.
* ``model/seed`` and ``model/gp<j>/<key>``: each output's `GaussianProcess.get_state()` minus
  its X/y copies, including the precomputed alpha and L^-1, so predictions after loading are
  bit-identical to the saved model's, without refitting.
* An LF-in-the-loop model (metadata ``kind = "lf-in-loop"``): y = LF(x) + delta(x), sigma =
  sigma_delta, with LF the exact low fidelity (`hydro.low_fidelity.lf_coefficients`) and delta a
  GP set ``delta/...`` on warped inputs (metadata ``warping``, one name per input; the GP state
  holds the warped bounds) and the residuals y_HF - y_LF. ``X``/``Y`` are the raw HF inputs and
  HF values. Metadata ``low_fidelity`` is the LF's identity (module, function, version,
  N_STRIPS, N_FRUSTA) and ``lf_hash`` its hash; ``lf_probe/X``, ``lf_probe/Y`` are LF values at a
  few points. Loading refuses a file whose identity, hash or probe values differ from this
  nearsub's LF, naming both. ``fit`` records each output's log marginal likelihood.
* A multi-fidelity model (metadata ``kind = "multi-fidelity"``, thesis (2.10)-(2.15)) stores two
  such GP sets with their own data, ``lf/...`` and ``delta/...``, and ``rho``; ``X``/``Y`` are then
  the high-fidelity sample points and the discrepancy targets y_HF - rho y_LF (2.15). It loads
  as a `MultiFidelitySurrogate`: y = rho y_LF + y_delta, sigma = sigma_delta.

The zip CRC-32 of every entry is checked on reading, so truncation and bit rot are detected.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import scipy
from numpy.lib.npyio import NpzFile

from nearsub import __version__ as nearsub_version
from nearsub.common.hydro import low_fidelity as hydro_lf
from nearsub.common.learning.gp import MultiOutputGP
from nearsub.common.physics.hull import D_SUB, L_SUB
from nearsub.common.surrogate.domain import BOUNDS, constraint_values, sample_feasible
from nearsub.common.surrogate.warping import Warping

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "LFInLoopModel",
    "LoadedModel",
    "ModelFileError",
    "load_model",
    "save_model",
]

FORMAT_NAME = "nearsub.gp-surrogate"
FORMAT_VERSION = 1


class ModelFileError(Exception):
    """A model file cannot be used: unreadable, corrupt, foreign or of an unknown version."""


class MultiFidelitySurrogate:
    """A trained multi-fidelity model for prediction: y_MF = rho y_LF + y_delta (2.11) and
    sigma_MF = sigma_delta (2.14), with the prediction methods of `MultiOutputGP`."""

    def __init__(self, lf: MultiOutputGP, delta: MultiOutputGP, rho: np.ndarray):
        self.lf, self.delta, self.rho = lf, delta, np.asarray(rho, dtype=float)

    @property
    def gps(self):
        """The discrepancy GPs: they carry the high-fidelity information and the std."""
        return self.delta.gps

    @property
    def all_gps(self):
        return self.lf.gps + self.delta.gps

    def predict(self, X: Any, return_std: bool = False):
        return self._combine(self.lf.predict(X), self.delta.predict(X, return_std=return_std), return_std)

    def predict_rows(self, X: Any, return_std: bool = False):
        return self._combine(self.lf.predict_rows(X), self.delta.predict_rows(X, return_std=return_std), return_std)

    def predict_point(self, x: Any) -> tuple[np.ndarray, np.ndarray]:
        lf_mean, _ = self.lf.predict_point(x)
        delta_mean, delta_std = self.delta.predict_point(x)
        return self.rho * lf_mean + delta_mean, delta_std

    def _combine(self, y_lf, delta, return_std):
        if return_std:
            mean, std = delta
            return self.rho * y_lf + mean, std
        return self.rho * y_lf + delta


LF_MODULE = hydro_lf.__name__
_LF_PROBES = 8  # feasible points whose LF values a model file keeps to detect a changed LF
_LF_PROBE_SEED = 20261201
_LF_PROBE_RTOL = 1e-9


def lf_identity() -> dict[str, Any]:
    """This nearsub's low fidelity: module, function, version and discretisation settings."""
    return {
        "module": LF_MODULE,
        "function": "lf_coefficients",
        "version": hydro_lf.LF_VERSION,
        "n_strips": hydro_lf.N_STRIPS,
        "n_frusta": hydro_lf.N_FRUSTA,
    }


def lf_hash(identity: Mapping[str, Any]) -> str:
    """Short sha256 of an LF identity (canonical JSON)."""
    return hashlib.sha256(json.dumps(dict(identity), sort_keys=True).encode()).hexdigest()[:16]


def lf_probe_points() -> np.ndarray:
    return sample_feasible(_LF_PROBES, seed=_LF_PROBE_SEED)


class LFInLoopModel:
    """y = LF(x) + delta(x), sigma = sigma_delta: the exact LF plus a residual GP `delta` fitted
    on `warping`-ed inputs. X, Y: the HF samples (raw inputs, HF values) it was fitted to."""

    kind = "lf_in_loop"

    def __init__(self, delta: MultiOutputGP, warping: Warping, X: Any, Y: Any):
        self.delta, self.warping = delta, warping
        self.X, self.Y = np.asarray(X, dtype=float), np.asarray(Y, dtype=float)

    @classmethod
    def fit(cls, X: Any, Y: Any, warping: Warping, *, n_restarts: int, seed: int) -> LFInLoopModel:
        """Fit the residual GP to HF samples X (n, 6), Y (n, 3): targets Y - LF(X)."""
        X, Y = np.asarray(X, dtype=float), np.asarray(Y, dtype=float)
        residual = Y - hydro_lf.lf_coefficients(X)
        delta = MultiOutputGP(bounds=warping.bounds, n_restarts=n_restarts, seed=seed)
        return cls(delta.fit(warping.forward(X), residual), warping, X, Y)

    @property
    def gps(self):
        """The discrepancy GPs: they carry the HF information and the std."""
        return self.delta.gps

    @property
    def all_gps(self):
        return self.delta.gps

    @property
    def log_marginal_likelihoods(self) -> list[float]:
        return [float(gp.log_marginal_likelihood_value_) for gp in self.delta.gps]

    def low_fidelity(self, X: Any) -> np.ndarray:
        """The exact LF [X', Y', N'] (n, 3) at inputs X (n, 6)."""
        return hydro_lf.lf_coefficients(np.atleast_2d(np.asarray(X, dtype=float)))

    def discrepancy(self, X: Any, return_std: bool = False):
        """The residual GP alone at X (n, 6): mean (n, 3) and, if asked, std (n, 3)."""
        W = self.warping.forward(np.atleast_2d(np.asarray(X, dtype=float)))
        return self.delta.predict_rows(W, return_std=return_std)

    def predict_rows(self, X: Any, return_std: bool = False):
        """LF + delta with row-wise arithmetic (see `MultiOutputGP.predict_rows`). Where the LF is
        undefined at finite inputs (the UUV within 1 cm of the hull, or beyond the LF's field)
        the LF term is taken at `lf_defined_pose(x)`, so the answer stays finite; such rows are
        always outside the bounds or (4.4), hence flagged by `Surrogate.predict`."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        lf = self.low_fidelity(X)
        undefined = ~np.all(np.isfinite(lf), axis=1) & np.all(np.isfinite(X), axis=1)
        if undefined.any():
            lf[undefined] = self.low_fidelity(lf_defined_pose(X[undefined]))
        if return_std:
            mean, std = self.discrepancy(X, return_std=True)
            return lf + mean, std
        return lf + self.discrepancy(X)

    predict = predict_rows

    def predict_point(self, x: Any) -> tuple[np.ndarray, np.ndarray]:
        mean, std = self.predict_rows(np.asarray(x, dtype=float)[None, :], return_std=True)
        return mean[0], std[0]


def lf_defined_pose(X: np.ndarray) -> np.ndarray:
    """The nearest pose of the trained domain: inputs clamped into table 4.2's bounds, then R_lat
    raised until (4.4) holds (its left side rises by L_sub/D_sub = 8.575 per unit R_lat)."""
    X = np.clip(X, BOUNDS[:, 0], BOUNDS[:, 1])
    shortfall = np.maximum(-constraint_values(X)[:, 0], 0.0)
    X[:, 1] += shortfall / (L_SUB / D_SUB)
    return X


@dataclass(frozen=True)
class LoadedModel:
    """A surrogate read from a model file, with everything needed to use it responsibly."""

    path: Path
    model: MultiOutputGP | MultiFidelitySurrogate | LFInLoopModel
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    units: dict[str, str]
    bounds: np.ndarray
    constraints: dict[str, Any]
    provenance: dict[str, Any]
    format_version: int
    saved_utc: str


def _utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def save_model(
    path: str | os.PathLike,
    model: MultiOutputGP,
    *,
    input_names: Sequence[str],
    output_names: Sequence[str],
    units: Mapping[str, str],
    bounds: Any,
    constraints: Mapping[str, Any],
    provenance: Mapping[str, Any],
) -> Path:
    """Write `model` and its metadata to `path` (atomically: a crash never leaves half a file).

    units maps input/output names to unit strings; constraints and provenance must be
    JSON-serialisable. Raises ValueError if the metadata does not fit the model.
    """
    path = Path(path)
    in_loop = isinstance(model, LFInLoopModel)
    multi = not in_loop and hasattr(model, "delta")  # a MultiFidelityGP (common/mfgp.py) or MultiFidelitySurrogate
    if in_loop:
        parts = {"delta": model.delta.get_state()}
        X, Y = model.X, model.Y
    else:
        parts = {"lf": model.lf.get_state(), "delta": model.delta.get_state()} if multi else {"": model.get_state()}
        state = parts["delta"] if multi else parts[""]
        X, Y = state["X"], state["Y"]
    if multi:
        rho = np.asarray(getattr(model, "rho_", getattr(model, "rho", 1.0)), dtype=float) * np.ones(Y.shape[1])
    d, m = X.shape[1], Y.shape[1]
    input_names, output_names = [str(s) for s in input_names], [str(s) for s in output_names]
    if len(input_names) != d or len(output_names) != m:
        raise ValueError(
            f"model has {d} inputs and {m} outputs, got {len(input_names)} input names "
            f"and {len(output_names)} output names"
        )
    if len(set(input_names + output_names)) != d + m:
        raise ValueError("input and output names must be unique")
    unknown = set(units) - set(input_names + output_names)
    if unknown:
        raise ValueError(f"units given for unknown names: {sorted(unknown)}")
    bounds = np.array(bounds, dtype=float)
    if bounds.shape != (d, 2) or np.any(bounds[:, 1] <= bounds[:, 0]):
        raise ValueError(f"bounds must have shape ({d}, 2) with upper > lower")
    saved_utc = _utc_now()
    provenance = dict(provenance)
    provenance.setdefault("created_utc", saved_utc)
    meta = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "saved_utc": saved_utc,
        "input_names": input_names,
        "output_names": output_names,
        "units": {str(k): str(v) for k, v in units.items()},
        "constraints": dict(constraints),
        "provenance": provenance,
        "software": {
            "nearsub": nearsub_version,
            "numpy": np.__version__,
            "scipy": scipy.__version__,
        },
        "n_outputs": m,
        "kind": "lf-in-loop" if in_loop else "multi-fidelity" if multi else "gp",
    }
    if in_loop:
        identity = lf_identity()
        meta["warping"] = list(model.warping.names)
        meta["low_fidelity"] = identity
        meta["lf_hash"] = lf_hash(identity)
    if in_loop or multi:
        delta_gps = model.delta.gps
        meta["fit"] = {
            "log_marginal_likelihood": [float(gp.log_marginal_likelihood_value_) for gp in delta_gps],
            "n_restarts": [int(gp.n_restarts) for gp in delta_gps],
        }
    try:
        meta_json = json.dumps(meta, allow_nan=False, sort_keys=True)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"constraints and provenance must be JSON-serialisable: {exc}") from exc

    arrays = {
        "metadata": np.frombuffer(meta_json.encode("utf-8"), dtype=np.uint8),
        "bounds": bounds,
        "X": X,
        "Y": Y,
    }
    for prefix, part in parts.items():
        base = f"{prefix}/" if prefix else ""
        if prefix:
            arrays[f"{base}X"], arrays[f"{base}Y"] = part["X"], part["Y"]
        arrays[f"{base}model/seed"] = np.asarray(part["seed"])
        for j, gp_state in enumerate(part["outputs"]):
            for key, value in gp_state.items():
                arrays[f"{base}model/gp{j}/{key}"] = np.asarray(value)
    if multi:
        arrays["rho"] = rho
    if in_loop:
        probes = lf_probe_points()
        arrays["lf_probe/X"], arrays["lf_probe/Y"] = probes, hydro_lf.lf_coefficients(probes)

    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def _scalar_or_array(a: np.ndarray) -> Any:
    """0-d arrays back to Python scalars (exact: float64 -> float), others as arrays."""
    return a.item() if a.ndim == 0 else a


def load_model(path: str | os.PathLike) -> LoadedModel:
    """Read a model file written by `save_model`; raises ModelFileError naming path and problem."""
    path = Path(path)

    def fail(problem: str) -> ModelFileError:
        return ModelFileError(f"{path}: {problem}")

    # Any failure while reading the bytes means a corrupt file, whatever numpy/zipfile raise.
    try:
        npz = np.load(path, allow_pickle=False)
    except FileNotFoundError as exc:
        raise fail("no such file") from exc
    except Exception as exc:
        raise fail(f"corrupt or unreadable model file ({type(exc).__name__}: {exc})") from exc
    if not isinstance(npz, NpzFile):
        raise fail("not a nearsub model file (a single .npy array, not an .npz archive)")
    try:
        with npz:
            entries = {name: npz[name] for name in npz.files}  # reading checks each CRC-32
    except Exception as exc:
        raise fail(f"corrupt or unreadable model file ({type(exc).__name__}: {exc})") from exc

    if "metadata" not in entries:
        raise fail("not a nearsub model file (no 'metadata' entry)")
    try:
        meta = json.loads(entries["metadata"].tobytes().decode("utf-8"))
    except ValueError as exc:
        raise fail(f"corrupt metadata ({exc})") from exc
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        found = meta.get("format") if isinstance(meta, dict) else None
        raise fail(f"not a nearsub model file (format {found!r}, expected {FORMAT_NAME!r})")
    if meta.get("version") != FORMAT_VERSION:
        raise fail(f"unsupported format version {meta.get('version')!r} (this nearsub reads version {FORMAT_VERSION})")

    try:
        m = int(meta["n_outputs"])

        def gp_set(prefix: str) -> MultiOutputGP:
            outputs: list[dict[str, Any]] = [{} for _ in range(m)]
            for name, value in entries.items():
                if name.startswith(f"{prefix}model/gp"):
                    j, key = name[len(f"{prefix}model/gp") :].split("/", 1)
                    outputs[int(j)][key] = _scalar_or_array(value)
            seed = _scalar_or_array(entries[f"{prefix}model/seed"])
            data = {"X": entries[f"{prefix}X"], "Y": entries[f"{prefix}Y"], "seed": seed, "outputs": outputs}
            return MultiOutputGP.from_state(data)

        kind = meta.get("kind", "gp")
        if kind == "lf-in-loop":
            _check_lf(meta, entries, fail)
            model = LFInLoopModel(gp_set("delta/"), Warping(meta["warping"]), entries["X"], entries["Y"])
        elif kind == "multi-fidelity":
            model = MultiFidelitySurrogate(gp_set("lf/"), gp_set("delta/"), entries["rho"])
        elif kind == "gp":
            model = gp_set("")
        else:
            raise ValueError(f"unknown model kind {kind!r}")
        loaded = LoadedModel(
            path=path,
            model=model,
            input_names=tuple(meta["input_names"]),
            output_names=tuple(meta["output_names"]),
            units=dict(meta["units"]),
            bounds=entries["bounds"],
            constraints=dict(meta["constraints"]),
            provenance=dict(meta["provenance"]),
            format_version=int(meta["version"]),
            saved_utc=str(meta["saved_utc"]),
        )
    except ModelFileError:
        raise
    except (KeyError, ValueError, TypeError, IndexError) as exc:
        raise fail(f"inconsistent model file ({type(exc).__name__}: {exc})") from exc
    d = entries["X"].shape[1]
    if len(loaded.input_names) != d or len(loaded.output_names) != m or loaded.bounds.shape != (d, 2):
        raise fail("metadata does not match the model (names or bounds vs. data shapes)")
    return loaded


def _check_lf(meta: dict[str, Any], entries: dict[str, np.ndarray], fail) -> None:
    """Refuse an LF-in-the-loop file made with another LF than this nearsub's, naming both."""
    stored, current = dict(meta["low_fidelity"]), lf_identity()
    here = f"this nearsub's LF is {current} (hash {lf_hash(current)})"
    if stored != current or meta.get("lf_hash") != lf_hash(current):
        raise fail(
            f"trained with a different low fidelity: the file's LF is {stored} (hash {meta.get('lf_hash')}), "
            f"{here}; retrain with `nearsub train`"
        )
    probe_y = hydro_lf.lf_coefficients(entries["lf_probe/X"])
    if not np.allclose(probe_y, entries["lf_probe/Y"], rtol=_LF_PROBE_RTOL, atol=0.0):
        worst = float(np.max(np.abs(probe_y - entries["lf_probe/Y"])))
        raise fail(
            f"trained with a different low fidelity: the file's LF {stored} (hash {meta['lf_hash']}) gave other "
            f"values at its probe points than {here} (largest difference {worst:.3g}): the LF changed without a "
            "new LF_VERSION; retrain with `nearsub train`"
        )
