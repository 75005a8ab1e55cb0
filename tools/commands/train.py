"""`nearsub train`: train the interaction surrogate, LF in the loop (common/surrogate/training.py).

    nearsub train [--design sobol|residual-us|nmmf] [--budget 300] [--workers 2 | --scheduler ADDRESS]
    nearsub train --design envelope --envelope vehicle=sdv [--envelope vehicle=remus100] [--samples 8]
    nearsub train --design D --pool A.csv [B.csv]        # pick among HF values that exist; no HF runs
    nearsub train --compare DIR --pool A.csv B.csv --envelope CONDITIONS [--envelope CONDITIONS]   # designs.md table

The model is the exact low fidelity (the one-way slender-body model, `common/hydro/low_fidelity.py`)
plus a residual GP on HF - LF at the HF samples (the two-way panel model,
`common/hydro/high_fidelity.py`). `--design` chooses where the HF runs (docs/hydro/designs.md).
HF runs go in parallel on a local Dask cluster (`--workers N`, on 127.0.0.1) or a running one
(`--scheduler tcp://HOST:8786`), and are appended to the `--state` CSV as they finish, so a killed
run continues where it stopped (the designs replay the stored runs; `--restart` discards them).
At the end the model is written with its provenance, its HF samples as CSV beside it
(<stem>-hf-samples.csv) and the HF's free-stream table for the increment mode
(<stem>-free-stream.npz, `common/surrogate/free_stream.py`).

`--design envelope` aims the HF runs at the outcome boundary of one or two envelopes
(`--envelope KEY=VALUE,...` with the keys of `nearsub envelope`: vehicle, behaviour, d_lead,
gamma, sea_state, depth, u_sub, u_ot, grid (20x10 unless given), r_long and r_lat as LO:HI,
duration, dt); docs/hydro/envelope-design.md. `--pool` runs any design on HF values that already
exist (CSVs with the samples CSV's columns, or the held-out file's `_hf` ones): the candidates are
the pool's rows and no HF runs. `--compare DIR` runs every design on the pool and scores each
design's envelopes against those of a reference fitted to the whole pool.

`nearsub train --data FILE.csv --out MODEL.npz` instead fits a single-fidelity GP to a user's own
table (columns as the samples CSV), after checking every value: a missing column, a value that is
not a plain number (a unit written into it), or a row outside table 4.2 or (4.4)-(4.7) is an error
naming the file, row, column and value (exit 2).
"""

from __future__ import annotations

import hashlib
import os
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from nearsub.common.learning.gp import FINAL_FIT_RESTARTS, MultiOutputGP
from nearsub.common.surrogate import domain
from nearsub.common.surrogate import free_stream as fs
from nearsub.common.surrogate import model as sg
from nearsub.common.surrogate import training as tr
from nearsub.common.surrogate.validation import read_number_table

from ..support.arguments import integer
from ..support.outputs import output_file
from ..support.schedulers import scheduler_address

DEFAULT_STATE = Path("training") / "hf-samples.csv"


def _shown(word: str) -> str:
    """An absolute path in a command line as a model records it: relative to the working directory
    when below it, else its name (a shipped model carries no temporary folder's path)."""
    key, sep, value = word.rpartition("=") if word.startswith("--") else ("", "", word)
    if not os.path.isabs(value):
        return word
    return key + sep + tr.file_reference(Path(value))["file"]


def command_line(default: str) -> str:
    return "nearsub " + " ".join(map(_shown, sys.argv[1:])) if sys.argv and "nearsub" in sys.argv[0] else default


def read_pool(paths) -> tuple[np.ndarray, np.ndarray]:
    """HF inputs and values of the --pool CSVs in file order: the samples CSV's columns (checked
    as --data is) or the held-out file's `_hf` columns; rows whose HF failed (NaN) are left out."""
    from nearsub.common.surrogate.validation import PointsFileError, read_points_file

    parts = []
    for path in map(Path, paths):
        try:
            parts.append(read_training_table(path))
        except DataFileError as first:
            try:
                parts.append(read_points_file(path))
            except PointsFileError:
                raise first from None
    X, Y = np.vstack([p[0] for p in parts]), np.vstack([p[1] for p in parts])
    keep = np.all(np.isfinite(Y), axis=1)
    return X[keep], Y[keep]


def envelope_specs(args) -> list:
    """The --envelope specs as EnvelopeConfig (ValueError naming the bad one)."""
    from nearsub.common.analysis import envelope_design as ed

    specs = args.envelope or []
    if len(specs) > ed.MAX_SPECS:
        raise ValueError(f"--envelope given {len(specs)} times: at most {ed.MAX_SPECS} envelopes")
    if args.samples < 1:
        raise ValueError(f"--samples {args.samples}: need at least 1")
    return [ed.parse_spec(spec) for spec in specs]


def train_command(args) -> int:
    if getattr(args, "data", None):
        return data_command(args)
    try:
        specs = envelope_specs(args)
        if args.compare:
            return compare_command(args, specs)
        # sobol has no seed points: the adaptive designs' default must not refuse its small budgets
        n_seed = args.n_seed or (min(tr.DEFAULT_N_SEED, args.budget) if args.design == "sobol" else tr.DEFAULT_N_SEED)
        settings = tr.DesignSettings(
            design=args.design, budget=args.budget, seed=args.seed, n_seed=n_seed, batch=args.batch
        )
        if settings.design == "envelope" and not specs:
            raise ValueError("--design envelope: name the envelope(s) to aim at with --envelope KEY=VALUE,...")
        pool = read_pool(args.pool) if args.pool else None
    except (ValueError, LookupError) as exc:
        print(f"nearsub train: {exc}", file=sys.stderr)
        return 2
    out = output_file(args.out or "surrogate.npz", "--out", parents=True)  # never over the shipped model unless asked
    state = output_file(args.state, "--state", parents=True) if pool is None else Path(args.state)
    if args.restart and pool is None:
        state.unlink(missing_ok=True)
    try:
        store = tr.HFStore(state) if pool is None else tr.pool_store(*pool)
    except ValueError as exc:
        print(f"nearsub train: --state {state}: {exc}", file=sys.stderr)
        return 2
    acquire = None
    if settings.design == "envelope":
        from nearsub.common.analysis.envelope_design import acquisition

        acquire = acquisition(specs, args.samples)
    started = time.perf_counter()
    columns = (TextColumn("[bold]HF runs"), BarColumn(), TextColumn("{task.completed}"), TimeRemainingColumn())
    with Progress(*columns, disable=not sys.stderr.isatty() and not args.progress) as progress:
        task = progress.add_task("train", total=None)
        if pool is not None:  # the pool's values stand in for the HF runs
            try:
                X, Y = tr.run_design(
                    settings, store, tr.pool_runner, candidates=tr.pool_candidates(pool[0]), acquire=acquire
                )
            except tr.NotInPoolError as exc:
                print(f"nearsub train: --pool: {exc}", file=sys.stderr)
                return 2
        else:
            with tr.hf_runner(args.workers, args.scheduler) as run:
                X, Y = tr.run_design(settings, store, run, on_row=lambda: progress.advance(task), acquire=acquire)
    design_seconds = time.perf_counter() - started
    overlap = tr.held_out_overlap(X)
    if overlap and pool is None:  # a pool may hold the held-out points on purpose (the comparison's)
        print(f"nearsub train: {overlap} sample(s) coincide with held-out validation points", file=sys.stderr)
        return 2
    began = time.perf_counter()
    model = tr.fit_model(X, Y, seed=args.seed)
    fit_seconds = time.perf_counter() - began
    out.parent.mkdir(parents=True, exist_ok=True)
    hf_seconds = sum(store.rows[store._key(x)][1] for x in X)
    where = {"hf_store": tr.file_reference(state)} if pool is None else {}
    if pool is not None:
        where["pool"] = [tr.file_reference(Path(p)) for p in args.pool]
    if specs:
        where["envelopes"] = [spec.model_dump(mode="json", exclude={"model"}) for spec in specs]
        where["posterior_samples"] = args.samples
    provenance = tr.provenance(
        settings.design,
        model,
        command_line("nearsub train"),
        created_utc=datetime.now(UTC).isoformat(timespec="seconds"),
        settings=settings.__dict__,
        **where,
        hf_seconds=round(hf_seconds, 1),
        design_wall_seconds=round(design_seconds, 1),
        fit_wall_seconds=round(fit_seconds, 1),
        dropped_samples=int(len(X) - len(model.X)),
        workers=args.scheduler or args.workers or 1,
    )
    sg.save_surrogate(out, model, provenance)
    tr.write_samples(out.with_name(out.stem + "-hf-samples.csv"), X, Y)
    # The increment mode takes delta's free-stream part out with the HF's free stream (interaction.py).
    table = fs.build_table(
        surrogate_model_id=sg.load_surrogate(out).model_id,
        surrogate_model=out.name,
        command=command_line("nearsub train"),
    )
    fs.save_table(fs.table_path_for(out), table)
    elapsed = time.perf_counter() - started
    lml = ", ".join(f"{v:.1f}" for v in model.log_marginal_likelihoods)
    print(
        f"wrote {out} ({settings.design}, {len(model.X)} HF samples) in {elapsed / 60:.1f} min: design "
        f"{design_seconds / 60:.1f} min (HF runs {hf_seconds:.0f} s), fit {fit_seconds:.0f} s; LML {lml}"
    )
    return 0


# ------------------------------------------------------------------ --compare: the pool comparison
def compare_command(args, specs: list) -> int:
    """Every design on the pool, scored by the misclassified cells of its envelopes against the
    reference's (docs/hydro/envelope-design.md). Each design's result is written as it finishes
    (DIR/designs/<design>.json); the table is made of every design result in DIR."""
    import json

    from nearsub.common.analysis import envelope_design as ed

    if not args.pool or not specs:
        raise ValueError("--compare needs --pool CSV... and at least one --envelope CONDITIONS")
    budgets = sorted(set(args.budgets))
    if budgets[0] <= ed.COMPARE_N_SEED:
        raise ValueError(f"--budgets {budgets[0]}: each budget must exceed the {ed.COMPARE_N_SEED} seed points")
    X, Y = read_pool(args.pool)
    if budgets[-1] > len(X):
        raise ValueError(f"--budgets {budgets[-1]}: the pool holds {len(X)} HF values")
    out = Path(args.compare)
    (out / "designs").mkdir(parents=True, exist_ok=True)
    setup = {
        "pool": [tr.file_reference(Path(p)) for p in args.pool],
        "envelopes": [spec.model_dump(mode="json", exclude={"model"}) for spec in specs],
        "budgets": budgets,
        "samples": args.samples,
        "seed": args.seed,
        "n_seed": ed.COMPARE_N_SEED,
    }
    # what steers each design's picks (the posterior samples only the envelope design's)
    setup_of = {d: setup if d == "envelope" else {k: v for k, v in setup.items() if k != "samples"} for d in tr.DESIGNS}
    scored = {"reference": [tr.file_reference(Path(p)) for p in args.reference or args.pool]}  # and its scores
    runs = []
    for design in args.designs or ed.COMPARE_DESIGNS:
        kept = out / "designs" / f"{design}-picks.json"
        if kept.exists() and (old := json.loads(kept.read_text()))["setup"] == setup_of[design]:  # resume
            picks = old["picks"]
            runs.append(ed.DesignRun(design, X[picks], Y[picks], old["seconds"], old["rounds"]))
            continue
        run = ed.run_pool_design(design, X, Y, specs, budgets, args.samples, args.seed)
        picks = [int(np.flatnonzero(np.all(X == x, axis=1))[0]) for x in run.X]
        record = {
            "setup": setup_of[design],
            "design": design,
            "picks": picks,
            "seconds": run.seconds,
            "rounds": run.rounds,
        }
        kept.write_text(json.dumps(record, indent=1) + "\n")
        print(f"{design}: picked {len(picks)} in {run.seconds:.0f} s", flush=True)
        runs.append(run)
    began = time.perf_counter()
    reference = ed.reference_model(*(read_pool(args.reference) if args.reference else (X, Y)), out / "reference.npz")
    references = ed.mean_outcomes(reference, specs)
    print(f"reference: {len(reference.X)} pool points, fitted or read in {time.perf_counter() - began:.0f} s")
    for run in runs:
        rows = ed.score_design(run, specs, references, budgets)
        result = {"setup": setup_of[run.design] | scored, "design": run.design, "rows": rows}
        (out / "designs" / f"{run.design}.json").write_text(json.dumps(result, indent=1) + "\n")
        print(f"{run.design}: " + ", ".join(f"{r['vehicle']} {r['budget']}: {r['misclassified']}" for r in rows))
    results = [json.loads(p.read_text()) for p in sorted((out / "designs").glob("*.json")) if "picks" not in p.stem]
    table = ed.comparison_table([r for r in results if r["setup"] == setup_of.get(r["design"], {}) | scored], specs)
    (out / "comparison.md").write_text(table + "\n")
    print(table)
    return 0


# ------------------------------------------------------------------------ --data: a user's table
# Column names that carry another unit or convention than the samples CSV, and what to give instead.
_COLUMN_HINTS = {
    "u": "u_kn (speed in knots)",
    "u_ms": "u_kn (speed in knots, not m/s)",
    "u_m_s": "u_kn (speed in knots, not m/s)",
    "psi": "psi_deg (heading in degrees)",
    "psi_rad": "psi_deg (heading in degrees, not radians)",
    "X": "X_p (the coefficient X' = X/(0.5 rho u^2 L_uuv^2), not newtons)",
    "Y": "Y_p (the coefficient Y' = Y/(0.5 rho u^2 L_uuv^2), not newtons)",
    "N": "N_p (the coefficient N' = N/(0.5 rho u^2 L_uuv^3), not N m)",
    "X'": "X_p",
    "Y'": "Y_p",
    "N'": "N_p",
}
MIN_DATA_ROWS = 2  # a GP needs two points to estimate a length scale at all


class DataFileError(ValueError):
    """A user's table cannot be fitted; the message names the file, row, column and value."""


def read_training_table(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Inputs (n, 6) and outputs (n, 3) from a CSV with the columns of the samples CSV
    (INPUT_NAMES and OUTPUT_NAMES, in any order; other columns are ignored), every row a finite
    number inside table 4.2's bounds and constraints (4.4)-(4.7). Raises DataFileError naming the
    file, row (data rows from 1, with the file's line), column and value of the first problem."""
    names = (*domain.INPUT_NAMES, *domain.OUTPUT_NAMES)

    def hints(header: list[str]) -> str:
        found = [f"found {name!r}: give {_COLUMN_HINTS[name]}" for name in header if name in _COLUMN_HINTS]
        return f"; {'; '.join(found)}" if found else ""

    values = read_number_table(path, names, DataFileError, missing_hint=hints)
    if len(values) < MIN_DATA_ROWS:
        raise DataFileError(f"{path}: {len(values)} data row(s); a surrogate needs at least {MIN_DATA_ROWS}")
    X, Y = values[:, : len(domain.INPUT_NAMES)], values[:, len(domain.INPUT_NAMES) :]
    for r, x in enumerate(X):
        for name, value, (low, high) in zip(domain.INPUT_NAMES, x, domain.BOUNDS, strict=True):
            if not low <= value <= high:
                raise DataFileError(
                    f"{path}: row {r + 1} (line {r + 2}), column {name}: {value:g} is outside table 4.2's "
                    f"[{low:g}, {high:g}] {domain.UNITS[name]}"
                )
        g = domain.constraint_values(x)[0]
        if not np.all(g >= 0.0):
            violated = "; ".join(
                f"{name} {domain.CONSTRAINTS[name]} (left side {value:.4g})"
                for name, value in zip(domain.CONSTRAINT_NAMES, g, strict=True)
                if not value >= 0.0
            )
            raise DataFileError(
                f"{path}: row {r + 1} (line {r + 2}) with R_lat {x[1]:g}, d_ratio {x[4]:g}, ld_ratio {x[5]:g} "
                f"violates {violated}"
            )
    return X, Y


def fit_from_data(path: Path, out: Path, seed: int = 0, n_restarts: int = FINAL_FIT_RESTARTS) -> int:
    """Fit a single-fidelity GP surrogate to a user's table and save it with its provenance;
    returns the number of rows. Raises DataFileError for a bad table."""
    X, Y = read_training_table(path)
    model = MultiOutputGP(bounds=domain.BOUNDS, n_restarts=n_restarts, seed=seed).fit(X, Y)
    provenance = {
        "method": "single-fidelity GP regression (thesis section 2.2.1) fitted to a user's table",
        "high_fidelity": f"user-supplied data: {path.name} (nearsub did not compute it)",
        "data": tr.file_reference(path)["file"],  # relative to the working directory, or the name alone
        "data_sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
        "rows": int(len(X)),
        "command": command_line(f"nearsub train --data {path}"),
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "seed": seed,
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    sg.save_surrogate(out, model, provenance)
    return len(X)


def data_command(args) -> int:
    if args.out is None:
        print("nearsub train: --data needs --out MODEL.npz", file=sys.stderr)
        return 2
    out = output_file(args.out, "--out", parents=True)
    try:
        rows = fit_from_data(Path(args.data), out, seed=args.seed)
    except DataFileError as exc:
        print(f"nearsub train: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}: a GP surrogate fitted to {rows} rows of {args.data}")
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("train", help="train the interaction surrogate (exact LF + residual GP on HF runs)")
    p.add_argument("--design", choices=tr.DESIGNS, default="sobol", help="where the HF runs (default sobol)")
    p.add_argument("--budget", type=int, default=300, help="HF samples (default 300)")
    p.add_argument("--seed", type=int, default=tr.DEFAULT_SEED, help="design seed (0 is the held-out set's)")
    p.add_argument(
        "--n-seed",
        type=integer(minimum=2),
        help=f"space-filling seed points of the adaptive designs (default {tr.DEFAULT_N_SEED})",
    )
    p.add_argument("--batch", type=int, default=10, help="residual-us picks per round")
    p.add_argument(
        "--workers", type=integer(minimum=1), metavar="N", help="run the HF on a local Dask cluster of N processes"
    )
    p.add_argument(
        "--scheduler",
        type=scheduler_address,
        metavar="ADDRESS",
        help="run the HF on this Dask scheduler (tcp://host:8786)",
    )
    p.add_argument("--state", default=str(DEFAULT_STATE), help="HF runs CSV, appended as each run finishes")
    p.add_argument("--restart", action="store_true", help="discard the HF runs in --state")
    p.add_argument("--out", help="model file to write (default: ./surrogate.npz; required with --data)")
    p.add_argument(
        "--data",
        metavar="FILE.csv",
        help="fit a GP to your own table instead of training: columns as the shipped samples CSV "
        f"({', '.join((*domain.INPUT_NAMES, *domain.OUTPUT_NAMES))})",
    )
    p.add_argument(
        "--envelope",
        action="append",
        metavar="CONDITIONS",
        help="with --design envelope: an envelope to aim at, KEY=VALUE,... with the keys of nearsub envelope "
        "(vehicle=sdv,behaviour=waypoints,grid=20x10; ranges as LO:HI); at most twice",
    )
    p.add_argument(
        "--samples", type=int, default=8, metavar="K", help="posterior samples per envelope round (default 8)"
    )
    p.add_argument(
        "--pool", nargs="+", metavar="CSV", help="pick among these HF values instead of running the HF (pool mode)"
    )
    p.add_argument(
        "--compare",
        metavar="DIR",
        help="with --pool and --envelope: run every design on the pool at --budgets and score its envelopes "
        "against a reference fitted to the whole pool; tables into DIR",
    )
    p.add_argument(
        "--reference", nargs="+", metavar="CSV", help="with --compare: fit the reference to these (default: the pool)"
    )
    p.add_argument("--budgets", nargs="+", type=int, default=[25, 50, 100], help="with --compare (default 25 50 100)")
    p.add_argument("--designs", nargs="+", choices=tr.DESIGNS, help="with --compare: these designs only (default all)")
    p.add_argument("--progress", action="store_true", help="show the progress bar even when not on a terminal")
    p.set_defaults(func=train_command)
