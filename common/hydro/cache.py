"""A disk cache for tables that every process would otherwise compute at start-up.

The LF's submarine field (`low_fidelity.submarine_field`) costs seconds of CPU, and a mission
near a submarine computed it in the surrogate server and again in the sim before step 0. Stored
once as exact float64 arrays and read back, it gives the same bits in every process. The key
hashes everything the values depend on: the inputs given, the source files of the code that
computes them, and the numpy and scipy versions, so a change to any of them computes afresh.
A cache that cannot be read or written is skipped silently: it only saves time.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
import scipy


def cache_dir() -> Path:
    """$NEARSUB_CACHE, else $XDG_CACHE_HOME/nearsub, else ~/.cache/nearsub."""
    if folder := os.environ.get("NEARSUB_CACHE"):
        return Path(folder)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "nearsub"


def cache_key(sources: Iterable[str | os.PathLike], *parts: bytes | str) -> str:
    digest = hashlib.sha256(f"numpy {np.__version__} scipy {scipy.__version__}".encode())
    for source in sources:
        digest.update(Path(source).read_bytes())
    for part in parts:
        digest.update(part.encode() if isinstance(part, str) else part)
    return digest.hexdigest()[:24]


def cached_arrays(name: str, key: str, compute: Callable[[], tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    """`compute()`'s arrays, read from the cache file `name`-`key`.npz when there is one."""
    path = cache_dir() / f"{name}-{key}.npz"
    try:
        with np.load(path) as stored:
            return tuple(stored[f"a{i}"] for i in range(len(stored.files)))
    except (OSError, ValueError, KeyError):
        pass
    arrays = compute()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_name(f"{path.name}.{os.getpid()}.partial.npz")
        np.savez(partial, **{f"a{i}": a for i, a in enumerate(arrays)})
        os.replace(partial, path)  # readers see the whole file or none
    except OSError:
        pass
    return arrays
