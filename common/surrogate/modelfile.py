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
* A multi-fidelity model (metadata ``kind = "multi-fidelity"``, thesis (2.10)-(2.15)) stores two
  such GP sets with their own data, ``lf/...`` and ``delta/...``, and ``rho``; ``X``/``Y`` are then
  the high-fidelity sample points and the discrepancy targets y_HF - rho y_LF (2.15). It loads
  as a `MultiFidelitySurrogate`: y = rho y_LF + y_delta, sigma = sigma_delta.

The zip CRC-32 of every entry is checked on reading, so truncation and bit rot are detected.
"""

from __future__ import annotations

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
from nearsub.common.learning.gp import MultiOutputGP

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
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


@dataclass(frozen=True)
class LoadedModel:
    """A surrogate read from a model file, with everything needed to use it responsibly."""

    path: Path
    model: MultiOutputGP | MultiFidelitySurrogate
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
    multi = hasattr(model, "delta")  # a MultiFidelityGP (common/mfgp.py) or MultiFidelitySurrogate
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
        "kind": "multi-fidelity" if multi else "gp",
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
        if kind == "multi-fidelity":
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
    except (KeyError, ValueError, TypeError, IndexError) as exc:
        raise fail(f"inconsistent model file ({type(exc).__name__}: {exc})") from exc
    d = entries["X"].shape[1]
    if len(loaded.input_names) != d or len(loaded.output_names) != m or loaded.bounds.shape != (d, 2):
        raise fail("metadata does not match the model (names or bounds vs. data shapes)")
    return loaded
