"""Validation of a surrogate against the high fidelity, in the form of thesis table 4.3 (section 4.6).

The thesis tests its ROM on 500 Latin-hypercube points, reports the mean absolute error (MAE) of
X', Y', N', and makes them tangible as REMUS 100 control values: the rudder angle that would make
the same sway force or yaw moment, and the share of the propeller thrust that equals the surge
error. This module holds the pieces as plain functions: the test design (`latin_hypercube_feasible`),
the HF evaluation on a process pool (`evaluate_rows`), the MAE and the error equivalents.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

import numpy as np
from scipy.stats import qmc

from nearsub.common.physics.vehicles import REMUS100, Vehicle
from nearsub.common.surrogate.domain import BOUNDS, INPUT_NAMES, OUTPUT_NAMES, UNITS, constraints_ok

# Thesis table 4.3: MAE of X', Y', N' on 500 test points, and its error equivalents
# (% X_prop for X', equivalent rudder angle in degrees for Y' and N').
THESIS_MAE = np.array([7.492e-4, 7.220e-4, 7.629e-4])
THESIS_EQUIVALENTS = np.array([10.26, 1.78, 3.95])
EQUIVALENT_UNITS = ("% X_prop", "deg rudder", "deg rudder")
THESIS_TEST_POINTS = 500  # section 4.6
# The held-out set (docs/hydro/validation-points.csv): THESIS_TEST_POINTS Latin-hypercube points of
# `latin_hypercube_feasible` with this seed. No training design uses the seed or the points.
HELD_OUT_SEED = 0
HELD_OUT_POINTS = THESIS_TEST_POINTS
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def latin_hypercube_feasible(n: int, seed: int = 0) -> np.ndarray:
    """n test points (n, 6) of a Latin hypercube over table 4.2's box that satisfy (4.4)-(4.7).

    The thesis's 500 Latin-hypercube points lie within the constraints (section 4.6). Here: a
    scipy Latin hypercube of m points, grown until at least n of its rows are feasible, and its
    first n feasible rows (the hypercube's rows are in random order, so they are a random
    subset). Every one-dimensional stratum of the hypercube holds at most one point, so the test
    set stays stratified; only the strata the constraints forbid are empty.
    """
    if n < 1:
        raise ValueError(f"points: need at least 1, got {n}")
    lower, width = BOUNDS[:, 0], BOUNDS[:, 1] - BOUNDS[:, 0]
    m = 6 * n  # about 1 point in 6 of the box is feasible (surrogate.sample_feasible)
    while True:
        X = lower + width * qmc.LatinHypercube(d=len(INPUT_NAMES), seed=np.random.default_rng(seed)).random(m)
        X = X[constraints_ok(X)]
        if len(X) >= n:
            return X[:n]
        m = math.ceil(1.25 * m)


def _timed_rows(function: Callable[[np.ndarray], np.ndarray], X: np.ndarray) -> tuple[np.ndarray, float]:
    """function(X) and the wall seconds it took (runs in a worker process)."""
    start = time.perf_counter()
    Y = np.asarray(function(X), dtype=float)
    return Y, time.perf_counter() - start


def evaluate_rows(
    function: Callable[[np.ndarray], np.ndarray],
    X: np.ndarray,
    jobs: int = 1,
    on_row: Callable[[int], None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """function (rows (k, d) -> (k, m)) at every row of X, one row per call: returns Y (n, m) and the
    wall seconds of each row (n,). jobs > 1 uses a pool of spawned processes with one BLAS thread
    each (a second BLAS thread slows the HF's dense solve on a shared machine, docs/hydro). `function`
    must be picklable (a module-level function or a functools.partial of one). on_row(i) is called
    as row i finishes, in completion order."""
    X = np.atleast_2d(np.asarray(X, dtype=float))
    results: list[tuple[np.ndarray, float] | None] = [None] * len(X)
    if jobs <= 1:
        for i, row in enumerate(X):
            results[i] = _timed_rows(function, row[None, :])
            if on_row is not None:
                on_row(i)
    else:
        for var in THREAD_VARS:  # inherited by the spawned workers
            os.environ.setdefault(var, "1")
        with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = {pool.submit(_timed_rows, function, row[None, :]): i for i, row in enumerate(X)}
            for future in as_completed(futures):
                results[futures[future]] = future.result()
                if on_row is not None:
                    on_row(futures[future])
    Y = np.vstack([y.reshape(1, -1) for y, _ in results])
    return Y, np.array([seconds for _, seconds in results])


class PointsFileError(ValueError):
    """A points file cannot be used; the message names the file, row, column and value."""


def read_number_table(
    path: Any,
    names: tuple[str, ...],
    error: type[ValueError],
    nan_ok: tuple[str, ...] = (),
    missing_hint: Callable[[list[str]], str] = lambda header: "",
) -> np.ndarray:
    """The columns `names` (in any order; others ignored) of a CSV as floats (n, len(names)): every
    value a plain finite number in its column's unit (UNITS), or 'nan' in the `nan_ok` columns.
    Raises `error` naming the file, row (data rows from 1, with the file's line), column and value
    of the first problem; a missing column's message ends with missing_hint(header)."""
    import csv

    try:
        with open(path, newline="") as fh:
            reader = csv.reader(fh)
            header = [name.strip() for name in next(reader, [])]
            rows = list(reader)
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{path}: cannot read: {exc}") from None
    missing = [name for name in names if name not in header]
    if missing:
        raise error(
            f"{path}: missing column(s) {', '.join(missing)} (expected {', '.join(names)}{missing_hint(header)})"
        )
    index = [header.index(name) for name in names]
    values = np.empty((len(rows), len(names)))
    for r, row in enumerate(rows):
        for c, (name, k) in enumerate(zip(names, index, strict=True)):
            text = row[k].strip() if k < len(row) else ""
            try:
                values[r, c] = float(text)
            except ValueError:
                unit = UNITS[name.removesuffix("_hf")]
                raise error(
                    f"{path}: row {r + 1} (line {r + 2}), column {name}: {text!r} is not a number "
                    f"(give a plain number in the column's unit, {unit})"
                ) from None
            if not np.isfinite(values[r, c]) and not (name in nan_ok and np.isnan(values[r, c])):
                raise error(f"{path}: row {r + 1} (line {r + 2}), column {name}: {text!r} is not finite")
    return values


def read_points_file(path: Any) -> tuple[np.ndarray, np.ndarray]:
    """Test inputs (n, 6) and their HF values (n, 3) from a CSV with the columns INPUT_NAMES and
    <output>_hf for each output (as docs/hydro/validation-points.csv; other columns ignored). An
    HF value may be 'nan' (the HF failed there: left out). Raises PointsFileError naming the file,
    row, column and value (`read_number_table`)."""
    hf_names = tuple(f"{n}_hf" for n in OUTPUT_NAMES)
    values = read_number_table(path, (*INPUT_NAMES, *hf_names), PointsFileError, nan_ok=hf_names)
    if not len(values):
        raise PointsFileError(f"{path}: no data rows")
    return values[:, : len(INPUT_NAMES)], values[:, len(INPUT_NAMES) :]


def mean_absolute_error(predicted: Any, actual: Any) -> np.ndarray:
    """MAE per output column over the rows where both are finite (thesis section 4.6)."""
    predicted, actual = np.atleast_2d(predicted), np.atleast_2d(actual)
    finite = np.all(np.isfinite(predicted) & np.isfinite(actual), axis=1)
    return np.mean(np.abs(predicted[finite] - actual[finite]), axis=0)


def error_equivalents(mae: Any, vehicle: Vehicle = REMUS100) -> np.ndarray:
    """Table 4.3's error equivalents of an MAE [X', Y', N']: [% X_prop, rudder deg for Y', rudder deg
    for N'], from the vehicle's coefficients (the thesis uses the REMUS 100's, section 4.6).

    The thesis does not print the conversion; this is the one its definitions give. A coefficient
    error becomes a force with the non-dimensionalisation of section 5.2, X = X' 0.5 rho u^2 L^2
    (Y likewise, N with L^3). The rudder makes Y_uu_dr u^2 delta and N_uu_dr u^2 delta (5.11), and
    the thrust that holds speed u in steady surge is X_prop = -X_u|u| u^2 ((5.11) with v = r = 0).
    So u cancels:
        % X_prop  = 100 X'_MAE 0.5 rho L^2 / |X_u|u||
        delta_Y   = Y'_MAE 0.5 rho L^2 / |Y_uu_dr|
        delta_N   = N'_MAE 0.5 rho L^3 / |N_uu_dr|
    With Prestero's REMUS 100 (common/vehicles.py) the thesis's own MAEs give 41.9 %, 3.89 deg and
    8.57 deg, not its printed 10.26 %, 1.78 deg and 3.95 deg: the thesis used some other, unstated
    scaling (the two rudder angles are both about 0.46 of ours, so the length and the rudder
    coefficients agree and only a common factor differs). docs/hydro/validation.md discusses it.
    """
    mae = np.asarray(mae, dtype=float)
    q = 0.5 * vehicle.rho
    length = vehicle.length
    return np.array(
        [
            100.0 * mae[0] * q * length**2 / abs(vehicle.X_uu),
            math.degrees(mae[1] * q * length**2 / abs(vehicle.Y_uudr)),
            math.degrees(mae[2] * q * length**3 / abs(vehicle.N_uudr)),
        ]
    )


def validation_summary(
    X: np.ndarray, actual: np.ndarray, predicted: np.ndarray, std: np.ndarray, lf: np.ndarray | None = None
) -> dict[str, Any]:
    """MAE, relative MAE (over the mean |HF|), 2-sigma coverage, error equivalents and context for a
    test set, next to the LF alone (`lf`, the exact LF at X; default: computed) and thesis table
    4.3, as JSON-ready data.

    actual: the HF values (n, 3), NaN where the HF could not evaluate a row (excluded, as are rows
    where the LF is undefined); predicted, std: the surrogate's mean and std there."""
    if lf is None:
        from nearsub.common.hydro.low_fidelity import lf_coefficients

        lf = lf_coefficients(X)
    finite = np.all(np.isfinite(actual), axis=1) & np.all(np.isfinite(lf), axis=1)
    mae = mean_absolute_error(predicted[finite], actual[finite])
    lf_mae = mean_absolute_error(lf[finite], actual[finite])
    mean_abs_hf = np.mean(np.abs(actual[finite]), axis=0)
    errors = np.abs(predicted[finite] - actual[finite])
    within_2_std = np.mean(errors <= 2.0 * std[finite], axis=0)
    return {
        "points": int(len(X)),
        "evaluated": int(finite.sum()),
        "outputs": list(OUTPUT_NAMES),
        "mae": mae.tolist(),
        "relative_mae": (mae / mean_abs_hf).tolist(),
        "lf_mae": lf_mae.tolist(),
        "lf_relative_mae": (lf_mae / mean_abs_hf).tolist(),
        "lf_over_model": (lf_mae / mae).tolist(),
        "max_abs_error": errors.max(axis=0).tolist(),
        "mean_abs_hf": mean_abs_hf.tolist(),
        "fraction_within_2_std": within_2_std.tolist(),
        "equivalents": error_equivalents(mae).tolist(),
        "equivalent_units": list(EQUIVALENT_UNITS),
        "thesis_mae": THESIS_MAE.tolist(),
        "thesis_equivalents": THESIS_EQUIVALENTS.tolist(),
        "thesis_mae_through_this_conversion": error_equivalents(THESIS_MAE).tolist(),
    }
