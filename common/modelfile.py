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
from nearsub.common.gp import MultiOutputGP

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


@dataclass(frozen=True)
class LoadedModel:
    """A surrogate read from a model file, with everything needed to use it responsibly."""

    path: Path
    model: MultiOutputGP
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
    state = model.get_state()
    X, Y = state["X"], state["Y"]
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
        "model/seed": np.asarray(state["seed"]),
    }
    for j, gp_state in enumerate(state["outputs"]):
        for key, value in gp_state.items():
            arrays[f"model/gp{j}/{key}"] = np.asarray(value)

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
        outputs: list[dict[str, Any]] = [{} for _ in range(m)]
        for name, value in entries.items():
            if name.startswith("model/gp"):
                j, key = name[len("model/gp") :].split("/", 1)
                outputs[int(j)][key] = _scalar_or_array(value)
        model = MultiOutputGP.from_state(
            {
                "X": entries["X"],
                "Y": entries["Y"],
                "seed": _scalar_or_array(entries["model/seed"]),
                "outputs": outputs,
            }
        )
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
