"""`nearsub train`: train the interaction surrogate with NMMF active learning (thesis ch. 2 and 4).

The two fidelities are nearsub's own physics (SPEC section 7): the low fidelity is the one-way
slender-body model (`common/hydro_lf.py`), the high fidelity the two-way panel model
(`common/hydro_hf.py`). NMMF (`common/active.py`) picks every sample, with maximum-variance
selection over the three outputs (2.31). The campaign saves itself after every sample, so a killed
run resumes with `--resume` without repeating or losing one. At the end the multi-fidelity model
is written as a model file with its provenance, and the samples as CSV.

`nearsub train --data FILE.csv --out MODEL.npz` instead fits a single-fidelity GP to a user's own
table (columns as the samples CSV), after checking every value: a missing column, a value that is
not a plain number (a unit written into it), or a row outside table 4.2 or (4.4)-(4.7) is an error
naming the file, row, column and value (exit 2).
"""

from __future__ import annotations

import csv
import hashlib
import json
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from nearsub.common.learning.active import Campaign, CampaignSettings
from nearsub.common.learning.gp import MultiOutputGP
from nearsub.common.surrogate import domain
from nearsub.common.surrogate import model as sg
from nearsub.common.surrogate.training import interaction_problem, write_samples

DEFAULT_STATE = Path("training") / "campaign.json"


def nmmf_settings(args) -> CampaignSettings:
    """The thesis's training settings (NMMF, maximum-variance selection (2.31)) with the design
    options of `add_design_arguments`. Raises ValueError for inconsistent sizes."""
    return CampaignSettings(
        method="nmmf",
        hf_budget=args.budget,
        selection="max-variance",
        seed=args.seed,
        n_lf0=args.n_lf0,
        n_hf0=args.n_hf0,
    )


def add_design_arguments(p) -> None:
    """--budget, --seed, --n-lf0, --n-hf0: the options `nmmf_settings` reads."""
    p.add_argument("--budget", type=int, default=100, help="high-fidelity samples (default 100, as the thesis)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-lf0", type=int, default=30, help="initial low-fidelity design")
    p.add_argument("--n-hf0", type=int, default=10, help="initial high-fidelity design (nested in the LF one)")


def train_command(args) -> int:
    if getattr(args, "data", None):
        return data_command(args)
    problem = interaction_problem()
    state = Path(args.state)
    if args.resume:
        if not state.exists():
            print(f"nearsub train: no campaign to resume at {state}", file=sys.stderr)
            return 2
        try:
            campaign = Campaign.resume(state, problem)
        except (ValueError, KeyError) as exc:  # another problem's campaign (nearsub campaign), or not one
            print(f"nearsub train: cannot resume {state}: {exc}", file=sys.stderr)
            return 2
    else:
        if state.exists() and not args.restart:
            print(f"nearsub train: {state} exists; pass --resume to continue it or --restart", file=sys.stderr)
            return 2
        state.parent.mkdir(parents=True, exist_ok=True)
        campaign = Campaign(problem, nmmf_settings(args), path=state)
    started = time.perf_counter()
    hf_seconds = 0.0
    columns = (
        TextColumn("[bold]HF samples"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TextColumn("{task.fields[error]}"),
        TimeRemainingColumn(),
    )
    with Progress(*columns, disable=not sys.stderr.isatty() and not args.progress) as progress:
        task = progress.add_task("train", total=campaign.settings.hf_budget, completed=campaign.n_hf, error="")
        while (request := campaign.ask()) is not None:
            began = time.perf_counter()
            Y = (problem.lf if request.fidelity == "lf" else problem.hf)(request.X)
            if request.fidelity == "hf":
                hf_seconds += time.perf_counter() - began
            campaign.tell(request.X, Y)
            if campaign.model is not None:
                probe = domain.sample_feasible(200, seed=1)
                _, std = campaign.model.predict(probe, return_std=True)
                progress.update(task, completed=campaign.n_hf, error=f"mean predicted std {np.mean(std):.2e}")
    out = Path(args.out or sg.default_model_path())
    high_fidelity = (
        "nearsub two-way Hess-Smith panel method with viscous corrections (common/hydro_hf.py); "
        "NOT RANS CFD (docs/hydro/README.md)"
    )
    n_hf, n_lf = write_campaign_model(out, campaign, state, high_fidelity)
    elapsed = time.perf_counter() - started
    print(f"wrote {out} ({n_hf} HF and {n_lf} LF samples) in {elapsed / 3600:.2f} h; HF runs {hf_seconds:.0f} s")
    return 0


def _command_line(default: str) -> str:
    return "nearsub " + " ".join(sys.argv[1:]) if sys.argv and "nearsub" in sys.argv[0] else default


def write_campaign_model(out: Path, campaign: Campaign, state: Path, high_fidelity: str) -> tuple[int, int]:
    """Write a campaign's multi-fidelity model with its provenance, and its samples as CSV beside it
    (<stem>-hf-samples.csv, <stem>-lf-samples.csv); returns the HF and LF sample counts."""
    out.parent.mkdir(parents=True, exist_ok=True)
    X_hf, Y_hf = campaign.data("hf")
    X_lf, Y_lf = campaign.data("lf")
    provenance = {
        "method": "NMMF active learning (thesis Algorithm 1), maximum-variance multi-output selection (2.31); "
        "Kennedy-O'Hagan multi-fidelity GP with rho = 1",
        "high_fidelity": high_fidelity,
        "low_fidelity": "nearsub one-way slender-body model with ITTC-57 friction (common/hydro_lf.py)",
        "command": _command_line("nearsub train"),
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "hf_samples": int(len(X_hf)),
        "lf_samples": int(len(X_lf)),
        "campaign": str(state),
        "settings": json.loads(json.dumps(campaign.settings.__dict__)),
    }
    sg.save_surrogate(out, campaign.model, provenance)
    write_samples(out.with_name(out.stem + "-hf-samples.csv"), X_hf, Y_hf)
    write_samples(out.with_name(out.stem + "-lf-samples.csv"), X_lf, Y_lf)
    return len(X_hf), len(X_lf)


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
    try:
        with open(path, newline="") as fh:
            reader = csv.reader(fh)
            header = [name.strip() for name in next(reader, [])]
            rows = list(reader)
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFileError(f"{path}: cannot read: {exc}") from None
    missing = [name for name in names if name not in header]
    if missing:
        hints = [f"found {found!r}: give {_COLUMN_HINTS[found]}" for found in header if found in _COLUMN_HINTS]
        raise DataFileError(
            f"{path}: missing column(s) {', '.join(missing)} (expected {', '.join(names)}"
            + (f"; {'; '.join(hints)}" if hints else "")
            + ")"
        )
    index = [header.index(name) for name in names]
    values = np.empty((len(rows), len(names)))
    for r, row in enumerate(rows):
        for c, (name, k) in enumerate(zip(names, index, strict=True)):
            text = row[k].strip() if k < len(row) else ""
            try:
                values[r, c] = float(text)
            except ValueError:
                unit = domain.UNITS[name]
                raise DataFileError(
                    f"{path}: row {r + 1} (line {r + 2}), column {name}: {text!r} is not a number "
                    f"(give a plain number in the column's unit, {unit})"
                ) from None
            if not np.isfinite(values[r, c]):
                raise DataFileError(f"{path}: row {r + 1} (line {r + 2}), column {name}: {text!r} is not finite")
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


def fit_from_data(path: Path, out: Path, seed: int = 0, n_restarts: int = 5) -> int:
    """Fit a single-fidelity GP surrogate to a user's table and save it with its provenance;
    returns the number of rows. Raises DataFileError for a bad table."""
    X, Y = read_training_table(path)
    model = MultiOutputGP(bounds=domain.BOUNDS, n_restarts=n_restarts, seed=seed).fit(X, Y)
    provenance = {
        "method": "single-fidelity GP regression (thesis section 2.2.1) fitted to a user's table",
        "high_fidelity": f"user-supplied data: {path.name} (nearsub did not compute it)",
        "data": str(path),
        "data_sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
        "rows": int(len(X)),
        "command": _command_line(f"nearsub train --data {path}"),
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "seed": seed,
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    sg.save_surrogate(out, model, provenance)
    return len(X)


def data_command(args) -> int:
    if args.out is None:
        print(
            "nearsub train: --data needs --out MODEL.npz (the default would replace the shipped model)", file=sys.stderr
        )
        return 2
    try:
        rows = fit_from_data(Path(args.data), Path(args.out), seed=args.seed)
    except DataFileError as exc:
        print(f"nearsub train: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}: a GP surrogate fitted to {rows} rows of {args.data}")
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("train", help="train the interaction surrogate with NMMF (LF + HF physics)")
    add_design_arguments(p)
    p.add_argument("--state", default=str(DEFAULT_STATE), help="campaign file, saved after every sample")
    p.add_argument("--resume", action="store_true", help="continue the campaign in --state")
    p.add_argument("--restart", action="store_true", help="start over even if --state exists")
    p.add_argument("--out", help="model file to write (default: the shipped one; required with --data)")
    p.add_argument(
        "--data",
        metavar="FILE.csv",
        help="fit a GP to your own table instead of training: columns as the shipped samples CSV "
        f"({', '.join((*domain.INPUT_NAMES, *domain.OUTPUT_NAMES))})",
    )
    p.add_argument("--progress", action="store_true", help="show the progress bar even when not on a terminal")
    p.set_defaults(func=train_command)
